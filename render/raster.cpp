#include "render/raster.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

namespace flarekit::render {
namespace {

inline float shade(const RasterTriangle& t, const Aperture& aperture, float dx, float dy) {
  const float r = t.r0 + t.rx * dx + t.ry * dy;
  const float rim = std::clamp(0.5f + (1.0f - r) / t.rim_footprint, 0.0f, 1.0f);
  if (rim <= 0.0f) return 0.0f;
  const float u = t.u0 + t.ux * dx + t.uy * dy;
  const float v = t.v0 + t.vx * dx + t.vy * dy;
  const float a = aperture.coverage(u, v, t.aperture_footprint);
  if (a <= 0.0f) return 0.0f;
  const float tr = std::max(0.0f, t.t0 + t.tx * dx + t.ty * dy);
  return tr * a * rim;
}

inline bool inside(const RasterTriangle& t, float dx, float dy) {
  for (int k = 0; k < 3; ++k) {
    const float e = t.ea[k] * dx + t.eb[k] * dy + t.ec[k];
    if (e < 0.0f || (e == 0.0f && !t.top_left[k])) return false;
  }
  return true;
}

// Whether no pixel centre of columns [x0, x1] and rows [y0, y1] can be inside triangle `t`
// (sampled, not splatted): one edge is negative at all four corner centres. The edge functions
// are evaluated as rasterizeInto evaluates them, and each rounded operation is monotonic, so
// over the rectangle they peak at a corner: when this says no, rasterizeInto adds nothing there.
// Long thin triangles (caustics, grazing cells) cross the boxes of many tiles they never touch.
bool missesPixels(const RasterTriangle& t, int x0, int x1, int y0, int y1) {
  const float dx0 = (static_cast<float>(x0) + 0.5f) - t.ox, dx1 = (static_cast<float>(x1) + 0.5f) - t.ox;
  const float dy0 = (static_cast<float>(y0) + 0.5f) - t.oy, dy1 = (static_cast<float>(y1) + 0.5f) - t.oy;
  for (int k = 0; k < 3; ++k) {
    const float base0 = t.eb[k] * dy0 + t.ec[k], base1 = t.eb[k] * dy1 + t.ec[k];
    if (t.ea[k] * dx0 + base0 < 0.0f && t.ea[k] * dx1 + base0 < 0.0f &&
        t.ea[k] * dx0 + base1 < 0.0f && t.ea[k] * dx1 + base1 < 0.0f)
      return true;
  }
  return false;
}

// Interior spans are accumulated in aligned chunks of this many pixels (one AVX2 vector).
constexpr int kChunk = 8;
typedef float Vec8 __attribute__((vector_size(4 * kChunk)));
typedef float Vec8U __attribute__((vector_size(4 * kChunk), aligned(4), may_alias));  // in a buffer
typedef int Int8 __attribute__((vector_size(4 * kChunk)));
constexpr Vec8 kLaneCentre = {0.5f, 1.5f, 2.5f, 3.5f, 4.5f, 5.5f, 6.5f, 7.5f};  // pixel centres
constexpr Int8 kLaneIndex = {0, 1, 2, 3, 4, 5, 6, 7};
constexpr Vec8 kOnes = {1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f, 1.0f};

// Planar RGB accumulation buffer covering pixels [bx, bx + stride) × [by, by + rows); the stride
// is a multiple of kChunk.
struct Planes {
  float* r;
  float* g;
  float* b;
  int stride, bx, by;
};

// Adds triangle `t` to `p`, restricted to pixel columns [x0, x1] and rows [y0, y1]. Per row, the
// span where the edge functions can be ≥ 0 is solved for (one pixel wider than exact); the exact
// top-left test then decides each pixel, the same way in every caller.
// Also built for AVX2 (8 floats a vector instead of SSE2's 4), chosen at load time by the CPU;
// without FMA it performs the same IEEE operations, so images do not depend on the machine.
__attribute__((target_clones("avx2", "default")))
void rasterizeInto(const RasterTriangle& t, const Aperture& aperture, int x0, int x1,
                          int y0, int y1, const Planes& p) {
  const float wr = t.weight[0], wg = t.weight[1], wb = t.weight[2];
  if (t.splat) {
    // A triangle below kSplatArea pixels may cover no pixel centre at all, or one by chance, so
    // point sampling would lose or multiply its flux (caustics are made of such triangles).
    // Instead its flux goes to the pixels under k² points spread evenly over it, each carrying
    // its share with the transmission, iris and rims at that point — as a dense ray grid would.
    const float edge = std::max({std::abs(t.px[1] - t.px[0]) + std::abs(t.py[1] - t.py[0]),
                                 std::abs(t.px[2] - t.px[1]) + std::abs(t.py[2] - t.py[1]),
                                 std::abs(t.px[0] - t.px[2]) + std::abs(t.py[0] - t.py[2])});
    const int k = std::clamp(static_cast<int>(std::ceil(2.0f * edge)), 1, 16);
    const float share = t.area_px / static_cast<float>(k * k);
    for (int a = 0; a < k; ++a)
      for (int b = 0; b < k; ++b) {
        // The unit square folded onto the triangle: uniform points.
        float s1 = (a + 0.5f) / k, s2 = (b + 0.5f) / k;
        if (s1 + s2 > 1.0f) {
          s1 = 1.0f - s1;
          s2 = 1.0f - s2;
        }
        const float x = t.px[0] + s1 * (t.px[1] - t.px[0]) + s2 * (t.px[2] - t.px[0]);
        const float y = t.py[0] + s1 * (t.py[1] - t.py[0]) + s2 * (t.py[2] - t.py[0]);
        const int ix = static_cast<int>(std::floor(x)), iy = static_cast<int>(std::floor(y));
        if (ix < x0 || ix > x1 || iy < y0 || iy > y1) continue;
        const float dx = x - t.ox, dy = y - t.oy;
        if (t.r0 + t.rx * dx + t.ry * dy > 1.0f) continue;
        const float ap = aperture.transmission(t.u0 + t.ux * dx + t.uy * dy, t.v0 + t.vx * dx + t.vy * dy);
        const float tr = std::max(0.0f, t.t0 + t.tx * dx + t.ty * dy);
        const float v = share * ap * tr;
        const size_t i = static_cast<size_t>(iy - p.by) * static_cast<size_t>(p.stride) +
                         static_cast<size_t>(ix - p.bx);
        p.r[i] += wr * v;
        p.g[i] += wg * v;
        p.b[i] += wb * v;
      }
    return;
  }
  // The span's ends by multiplication: they only bound the exact test (a pixel of slack on each
  // side), so a reciprocal's rounding cannot change which pixels are inside. (Edges too steep for
  // a finite reciprocal keep the division.)
  float inv_a[3];
  for (int k = 0; k < 3; ++k) inv_a[k] = std::abs(t.ea[k]) > 1e-30f ? 1.0f / t.ea[k] : 0.0f;
  // In RGB mode each wavelength's colour weight is one primary: the other two planes would only
  // get +0 added (which changes nothing), so only the planes with a non-zero weight are touched.
  float* plane[3];
  float w[3];
  int planes = 0;
  for (int c = 0; c < 3; ++c) {
    if (t.weight[c] == 0.0f) continue;
    plane[planes] = c == 0 ? p.r : c == 1 ? p.g : p.b;
    w[planes++] = t.weight[c];
  }
  if (planes == 0) return;
  // The rows' spans are set up kRows rows at a time, each step one loop over the rows that
  // vectorises (which edges bound the span on which side, and by reciprocal or division, is the
  // triangle's, decided once): a row's span is computed by the same IEEE operations as one row at
  // a time, so it is the same. One row at a time, the set-up was 40 % of this function's
  // instructions on a 1280×720 frame, where a ghost's triangles are some 25 pixels wide.
  constexpr int kRows = 32;
  static_assert(kRows % 8 == 0, "the set-up loops run over whole vectors of 8 rows");
  const float inf = std::numeric_limits<float>::infinity();
  const float ox_half = t.ox - 0.5f;
  const float fx0 = static_cast<float>(x0), fx1 = static_cast<float>(x1);
  alignas(32) float dys[kRows], bases[3][kRows], lo_edges[kRows], hi_edges[kRows];
  alignas(32) int empties[kRows], xss[kRows], xes[kRows], c0s[kRows], chunkss[kRows];
  alignas(32) int fast_begins[kRows], fast_ends[kRows];
  alignas(32) float trows[kRows];
  // The triangle's constants in locals: the compiler must otherwise reload them after every store
  // to a plane (a float store may alias the triangle's floats).
  const bool tl0 = t.top_left[0], tl1 = t.top_left[1], tl2 = t.top_left[2];
  const float a0 = t.ea[0], a1 = t.ea[1], a2 = t.ea[2];
  const float t0 = t.t0, ty = t.ty, tx = t.tx, ox = t.ox;
  const bool interior = t.interior, rim_clear = t.rim_clear, aperture_clear = t.aperture_clear;
  // Interior triangles: the top-left test is folded into one threshold per edge (e > 0 is
  // e ≥ the smallest denormal) so the loop is branch-free and vectorises.
  const float th0 = tl0 ? 0.0f : std::numeric_limits<float>::denorm_min();
  const float th1 = tl1 ? 0.0f : std::numeric_limits<float>::denorm_min();
  const float th2 = tl2 ? 0.0f : std::numeric_limits<float>::denorm_min();
  // The rim band of a circular or polygonal iris goes by vectors too (a mask's bilinear lookup
  // stays one pixel at a time): the aperture's constants, as Aperture::coverage uses them.
  const bool lanes = !interior && aperture.hasDistance();
  const bool circle = aperture.shape().kind == ApertureKind::kCircle;
  const int edges = circle ? 0 : aperture.edgeCount();
  float edge_nx[32], edge_ny[32];
  for (int k = 0; k < edges; ++k) {
    edge_nx[k] = aperture.edgeNormalX(k);
    edge_ny[k] = aperture.edgeNormalY(k);
  }
  const float apothem = aperture.apothem(), rounding = aperture.rounding();
  const float rim_footprint = t.rim_footprint;
  const float aperture_footprint = std::max(t.aperture_footprint, 1e-6f);
  for (int yb = y0; yb <= y1; yb += kRows) {
    const int nr = std::min(kRows, y1 - yb + 1);
    // The set-up loops run over whole vectors of 8 rows (the rows past nr are computed and never
    // read): without remainder loops, which cost more than the rows they saved.
    const int nv = (nr + 7) & ~7;
    for (int i = 0; i < nv; ++i) {
      dys[i] = (static_cast<float>(yb + i) + 0.5f) - t.oy;
      trows[i] = t0 + ty * dys[i];
      lo_edges[i] = -inf;  // the span's ends from the edges alone (not clipped to [x0, x1])
      hi_edges[i] = inf;
      empties[i] = 0;
    }
    for (int k = 0; k < 3; ++k) {
      float* base = bases[k];
      const float a = t.ea[k], eb = t.eb[k], ec = t.ec[k], inv = inv_a[k];
      for (int i = 0; i < nv; ++i) base[i] = eb * dys[i] + ec;
      if (a > 0.0f) {
        if (inv != 0.0f)
          for (int i = 0; i < nv; ++i) lo_edges[i] = std::max(lo_edges[i], ox_half - base[i] * inv);
        else
          for (int i = 0; i < nv; ++i) lo_edges[i] = std::max(lo_edges[i], ox_half - base[i] / a);
      } else if (a < 0.0f) {
        if (inv != 0.0f)
          for (int i = 0; i < nv; ++i) hi_edges[i] = std::min(hi_edges[i], ox_half - base[i] * inv);
        else
          for (int i = 0; i < nv; ++i) hi_edges[i] = std::min(hi_edges[i], ox_half - base[i] / a);
      } else {
        const int tl = t.top_left[k] ? 1 : 0;
        for (int i = 0; i < nv; ++i)
          empties[i] |= (base[i] < 0.0f) | ((base[i] == 0.0f) & (tl == 0));
      }
    }
    // Rows with pixels to visit get xs ≤ xe, the others xe < xs (rows whose span was empty only
    // after clipping added nothing but +0 before). Values are clamped before the conversions to
    // int, where that changes nothing for a row with pixels (lo ≤ hi + 2 ≤ x1 + 2 and
    // hi ≥ lo − 2 ≥ x0 − 2) but keeps an empty row's infinite ends finite.
    for (int i = 0; i < nv; ++i) {
      const float lo_edge = lo_edges[i], hi_edge = hi_edges[i];
      const float lo = std::max(fx0, lo_edge);
      const float hi = std::min(fx1, hi_edge);
      const bool skip = (empties[i] != 0) | !(lo <= hi + 2.0f);
      const int xs = std::max(x0, static_cast<int>(std::floor(std::min(lo, fx1 + 4.0f))) - 1);
      const int xe = std::min(x1, static_cast<int>(std::ceil(std::max(hi, fx0 - 4.0f))) + 1);
      xss[i] = xs;
      xes[i] = skip || xe < xs ? xs - 1 : xe;
      // Interior triangles: whole chunks of kChunk pixels, aligned to the buffer (its stride is
      // a multiple of kChunk), c0 the first one's pixel. Pixels a whole pixel inside the edges'
      // span are inside every edge: the span's ends and the edge functions are both rounded far
      // below a pixel (|x − ox| < 1e5 px, float), so the exact test could only say yes there.
      // Chunks wholly in that run, [fast_begin, fast_end), skip it (the bulk of a large ghost's
      // pixels); the chunks at the ends take it, so ties are decided as before and the result is
      // the same. (Clamped to [xs − 1, xe + 1] before the conversion, as if unclamped.)
      const int c0 = p.bx + ((xs - p.bx) & ~(kChunk - 1));
      const int chunks = (xe - c0) / kChunk + 1;
      const float lim_lo = static_cast<float>(xs - 1), lim_hi = static_cast<float>(xe + 1);
      const int ms = std::max(xs, static_cast<int>(std::ceil(std::min(lim_hi, std::max(lim_lo, lo_edge + 1.0f)))));
      const int me = std::min(xe, static_cast<int>(std::floor(std::min(lim_hi, std::max(lim_lo, hi_edge - 1.0f)))));
      const bool fast = (lo_edge + 1.0f <= hi_edge - 1.0f) & (ms <= me);
      const int fb = (ms - c0 + kChunk - 1) / kChunk;
      c0s[i] = c0;
      chunkss[i] = chunks;
      fast_begins[i] = fast ? fb : chunks;
      fast_ends[i] = fast ? std::max(fb, (me + 1 - c0) / kChunk) : chunks;
    }
    for (int i = 0; i < nr; ++i) {
      const int xs = xss[i], xe = xes[i];
      if (xe < xs) continue;
      const int y = yb + i;
      const float dy = dys[i];
      const size_t row = static_cast<size_t>(y - p.by) * static_cast<size_t>(p.stride);
      const float b0 = bases[0][i], b1 = bases[1][i], b2 = bases[2][i];
      const float trow = trows[i];
      if (interior) {
        // A = C = 1: only the interpolated transmission. Pixels of a chunk outside the span [xs, xe] add exactly +0.
        const int c0 = c0s[i], chunks = chunkss[i];
        const int fast_begin = fast_begins[i], fast_end = fast_ends[i];
        // The chunks as explicit 8-float vectors (GCC vector extensions: one AVX2 vector, two
        // SSE2 ones), the same IEEE operations a lane as the scalar expressions they replace.
        for (int q = 0; q < planes; ++q) {
          float* P = plane[q] + row - p.bx;
          const float wp = w[q];
          for (int c = 0; c < chunks; ++c) {
            const int xb = c0 + c * kChunk;
            const Vec8 dx = (static_cast<float>(xb) + kLaneCentre) - ox;  // x + 0.5 exact: x < 2²²
            const Vec8 tr = trow + tx * dx;
            Vec8 v = tr > 0.0f ? tr : Vec8{};
            if (c < fast_begin || c >= fast_end) {
              // The exact test, the same expression as everywhere else so that every caller
              // decides ties alike.
              const Vec8 e0 = a0 * dx + b0, e1 = a1 * dx + b1, e2 = a2 * dx + b2;
              const Int8 x = xb + kLaneIndex;
              const Int8 in = (e0 >= th0) & (e1 >= th1) & (e2 >= th2) & (x >= xs) & (x <= xe);
              v = in ? v : Vec8{};
            }
            Vec8U* out = reinterpret_cast<Vec8U*>(P + xb);
            *out = *out + wp * v;
          }
        }
        continue;
      }
      if (lanes) {
        // The rim band, a chunk of kChunk pixels a vector as the interior: shade() lane by lane
        // (the same IEEE operations, the clamps and maxima written as the selects std::clamp and
        // std::max are), pixels outside the triangle or the span adding exactly +0. On the Nikon
        // 28-75 these pixels were a third of the work, one at a time.
        const int c0 = c0s[i], chunks = chunkss[i];
        const float r_row = t.ry * dy, u_row = t.uy * dy, v_row = t.vy * dy, t_row = t.ty * dy;
        for (int c = 0; c < chunks; ++c) {
          const int xb = c0 + c * kChunk;
          const Vec8 dx = (static_cast<float>(xb) + kLaneCentre) - ox;
          const Vec8 e0 = a0 * dx + b0, e1 = a1 * dx + b1, e2 = a2 * dx + b2;
          const Int8 x = xb + kLaneIndex;
          const Int8 in = (e0 >= th0) & (e1 >= th1) & (e2 >= th2) & (x >= xs) & (x <= xe);
          // C or A of a triangle clear of the rims or of the iris is 1 at every pixel (what the
          // clamps below give there, exactly): most rim band triangles lie along one edge only.
          Vec8 rim = kOnes;
          if (!rim_clear) {
            const Vec8 r = (t.r0 + t.rx * dx) + r_row;
            rim = 0.5f + (1.0f - r) / rim_footprint;
            rim = rim < 0.0f ? Vec8{} : (1.0f < rim ? kOnes : rim);
          }
          Vec8 a = kOnes;
          if (!aperture_clear) {
            const Vec8 u = (t.u0 + t.ux * dx) + u_row;
            const Vec8 v = (t.v0 + t.vx * dx) + v_row;
            Vec8 d = Vec8{};
            if (circle || rounding != 0.0f) {
              const Vec8 q = u * u + v * v;
              Vec8 root;
              for (int k = 0; k < kChunk; ++k) root[k] = std::sqrt(q[k]);
              d = 1.0f - root;
            }
            if (!circle) {
              Vec8 m = Vec8{} - 1e30f;
              for (int k = 0; k < edges; ++k) {
                const Vec8 e = u * edge_nx[k] + v * edge_ny[k];
                m = m < e ? e : m;
              }
              const Vec8 polygon = apothem - m;
              d = rounding == 0.0f ? polygon : (1.0f - rounding) * polygon + rounding * d;
            }
            a = 0.5f + d / aperture_footprint;
            a = a < 0.0f ? Vec8{} : (1.0f < a ? kOnes : a);
          }
          Vec8 tr = (t.t0 + t.tx * dx) + t_row;
          tr = 0.0f < tr ? tr : Vec8{};
          Vec8 shade = (tr * a) * rim;
          shade = rim <= 0.0f ? Vec8{} : shade;
          shade = a <= 0.0f ? Vec8{} : shade;
          shade = in ? shade : Vec8{};
          for (int q = 0; q < planes; ++q) {
            Vec8U* out = reinterpret_cast<Vec8U*>(plane[q] + row - p.bx + xb);
            *out = *out + w[q] * shade;
          }
        }
        continue;
      }
      float* rows[3];
      for (int q = 0; q < planes; ++q) rows[q] = plane[q] + row - p.bx;
      for (int x = xs; x <= xe; ++x) {
        const float dx = (x + 0.5f) - t.ox;
        const float e0 = a0 * dx + b0, e1 = a1 * dx + b1, e2 = a2 * dx + b2;
        const bool in = (e0 > 0.0f || (tl0 && e0 == 0.0f)) && (e1 > 0.0f || (tl1 && e1 == 0.0f)) &&
                        (e2 > 0.0f || (tl2 && e2 == 0.0f));
        if (!in) continue;
        const float s = shade(t, aperture, dx, dy);
        for (int q = 0; q < planes; ++q) rows[q][x] += w[q] * s;
      }
    }
  }
}

// Adds planar buffers into an interleaved CV_32FC3 image region.
void addPlanes(const float* r, const float* g, const float* b, int stride, int x0, int y0, int w,
               int h, cv::Mat* image) {
  for (int y = 0; y < h; ++y) {
    auto* dst = image->ptr<cv::Vec3f>(y0 + y) + x0;
    const size_t o = static_cast<size_t>(y) * static_cast<size_t>(stride);
    for (int x = 0; x < w; ++x) {
      dst[x][0] += r[o + static_cast<size_t>(x)];
      dst[x][1] += g[o + static_cast<size_t>(x)];
      dst[x][2] += b[o + static_cast<size_t>(x)];
    }
  }
}

// One batch into its own planar buffer over its bounding box: the box and three planes of
// `stride` floats a row, in `*storage` (zeroed and grown as needed). w = 0 when the batch is empty.
struct BatchPlanes {
  int x0 = 0, y0 = 0, w = 0, h = 0, stride = 0;
  const float* r = nullptr;
  const float* g = nullptr;
  const float* b = nullptr;
};

BatchPlanes rasterizeBatch(const std::vector<RasterTriangle>& tris, const Aperture& aperture,
                           cv::Size image, std::vector<float>* storage) {
  BatchPlanes out;
  if (tris.empty()) return out;
  int x0 = image.width, y0 = image.height, x1 = -1, y1 = -1;
  for (const RasterTriangle& t : tris) {
    x0 = std::min(x0, t.x0);
    y0 = std::min(y0, t.y0);
    x1 = std::max(x1, t.x1);
    y1 = std::max(y1, t.y1);
  }
  const int w = x1 - x0 + 1, h = y1 - y0 + 1;
  const int stride = (w + kChunk - 1) / kChunk * kChunk;
  const size_t size = static_cast<size_t>(stride) * static_cast<size_t>(h);
  if (storage->size() < 3 * size) storage->resize(3 * size);
  std::fill(storage->begin(), storage->begin() + static_cast<std::ptrdiff_t>(3 * size), 0.0f);
  float* r = storage->data();
  float* g = r + size;
  float* b = g + size;
  const Planes p{r, g, b, stride, x0, y0};
  for (const RasterTriangle& t : tris) rasterizeInto(t, aperture, t.x0, t.x1, t.y0, t.y1, p);
  out = {x0, y0, w, h, stride, r, g, b};
  return out;
}

void addBatch(const BatchPlanes& p, cv::Mat* image) {
  if (p.w > 0) addPlanes(p.r, p.g, p.b, p.stride, p.x0, p.y0, p.w, p.h, image);
}

}  // namespace

std::vector<float>& RasterScratch::buffer(size_t slot) {
  if (buffers_.size() <= slot) buffers_.resize(slot + 1);
  return buffers_[slot];
}

bool TileOptions::IsValid(std::string* error) const {
  if (fine_tile_px < 1 || coarse_tile_px < fine_tile_px || coarse_tile_px % fine_tile_px != 0) {
    if (error) *error = "tile sizes: coarse must be a positive multiple of fine";
    return false;
  }
  return true;
}

float shadeTriangle(const RasterTriangle& t, const Aperture& aperture, float x, float y) {
  const float dx = x - t.ox, dy = y - t.oy;
  if (!inside(t, dx, dy)) return 0.0f;
  return shade(t, aperture, dx, dy);
}

void rasterizeBatches(const std::vector<std::vector<RasterTriangle>>& batches,
                      const std::vector<bool>* keep, const Aperture& aperture, cv::Mat* image) {
  std::vector<float> storage;
  for (size_t b = 0; b < batches.size(); ++b) {
    if (keep && !(*keep)[b]) continue;
    addBatch(rasterizeBatch(batches[b], aperture, image->size(), &storage), image);
  }
}

void rasterizePerGhost(const std::vector<std::vector<RasterTriangle>>& batches,
                       const Aperture& aperture, cv::Mat* image, RasterScratch* scratch) {
  // Hullin's one-ghost-at-a-time pass: each batch into its own buffer over its bounding box, in
  // parallel, added to the frame in batch order. (Added as the threads finished, under a mutex,
  // the same frame differed in its last bits from run to run.) A pipeline of `tokens` batches in
  // flight: the adding stage takes them in order, so the batch of sequence number n + tokens
  // starts only after batch n was added, and slot n mod tokens is free for it. Batches finished
  // behind a large one wait for it, holding their tokens: with 2 tokens a thread the Nikon 28-75's
  // per-ghost rasterization (1280×720, 2 threads) took 1130–1160 ms, with 8 1020–1100 ms, about
  // as long as the mutex took (980–1070 ms). 8 a thread, as long as their buffers (a whole frame
  // at most) stay within 256 MB, and at least 2 a thread.
  const size_t threads = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  const size_t frame_bytes = 3 * sizeof(float) * image->total();
  const size_t tokens = std::clamp((size_t{256} << 20) / std::max<size_t>(frame_bytes, 1), 2 * threads, 8 * threads);
  RasterScratch own;
  RasterScratch& buffers = scratch ? *scratch : own;
  for (size_t slot = 0; slot < tokens; ++slot) buffers.buffer(slot);  // grown here, not in the stages
  struct Item {
    size_t batch = 0, sequence = 0;
    BatchPlanes planes;
  };
  size_t next = 0, sequence = 0;
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, Item>(tbb::filter_mode::serial_in_order,
                                   [&](tbb::flow_control& control) {
                                     while (next < batches.size() && batches[next].empty()) ++next;
                                     if (next == batches.size()) {
                                       control.stop();
                                       return Item{};
                                     }
                                     return Item{next++, sequence++, {}};
                                   }) &
          tbb::make_filter<Item, Item>(tbb::filter_mode::parallel,
                                       [&](Item item) {
                                         item.planes = rasterizeBatch(batches[item.batch], aperture, image->size(),
                                                                      &buffers.buffer(item.sequence % tokens));
                                         return item;
                                       }) &
          tbb::make_filter<Item, void>(tbb::filter_mode::serial_in_order,
                                       [&](const Item& item) { addBatch(item.planes, image); }));
}

void rasterizeTiled(const std::vector<std::vector<RasterTriangle>>& batches,
                    const Aperture& aperture, const TileOptions& options, cv::Mat* image,
                    bool overwrite) {
  // Overwriting: a tile without triangles writes zeros, the others their sums (0 + sum = sum).
  auto zeroPixels = [&](int x0, int y0, int x1, int y1) {
    if (!overwrite) return;
    for (int y = y0; y <= y1; ++y)
      std::fill_n(image->ptr<float>(y) + 3 * static_cast<size_t>(x0), 3 * static_cast<size_t>(x1 - x0 + 1), 0.0f);
  };
  const int W = image->cols, H = image->rows;
  const int C = options.coarse_tile_px, F = options.fine_tile_px;
  const int ncx = (W + C - 1) / C, ncy = (H + C - 1) / C;
  const int tiles = ncx * ncy;
  // Level 1: every triangle into the coarse tiles its bounding box overlaps (less those whose
  // pixels it misses, when the box spans several). One pass over each batch (in parallel) lists
  // its triangles' indices tile by tile, in order: a tile's triangles are then every batch's list
  // for it in batch order (deterministic). (Counting first and laying the references out in a
  // second pass read every triangle twice, 1.9 M of 168 bytes on the Nikon 28-75: the two passes
  // were 8 % of the tiled rasterization on one thread.)
  auto missesCoarseTile = [&](const RasterTriangle& t, int tx, int ty) {
    if (t.splat || (t.x0 / C == t.x1 / C && t.y0 / C == t.y1 / C)) return false;
    return missesPixels(t, std::max(t.x0, tx * C), std::min(t.x1, tx * C + C - 1),
                        std::max(t.y0, ty * C), std::min(t.y1, ty * C + C - 1));
  };
  // Batch b's triangles in tile `tile`: order[b][first[b][tile] .. first[b][tile + 1]).
  std::vector<std::vector<uint32_t>> order(batches.size());
  std::vector<std::vector<uint32_t>> first(batches.size());
  tbb::parallel_for(size_t{0}, batches.size(), [&](size_t b) {
    // (tile, index) pairs in triangle order, then a counting sort by tile (stable).
    thread_local std::vector<uint32_t> pair_tile, pair_index;
    pair_tile.clear();
    pair_index.clear();
    const auto& tris = batches[b];
    std::vector<uint32_t>& f = first[b];
    f.assign(static_cast<size_t>(tiles) + 1, 0);
    for (size_t i = 0; i < tris.size(); ++i) {
      const RasterTriangle& t = tris[i];
      const int tx0 = t.x0 / C, tx1 = t.x1 / C, ty0 = t.y0 / C, ty1 = t.y1 / C;
      if (tx0 == tx1 && ty0 == ty1) {  // the common case: inside one tile
        const auto tile = static_cast<uint32_t>(ty0 * ncx + tx0);
        pair_tile.push_back(tile);
        pair_index.push_back(static_cast<uint32_t>(i));
        ++f[tile + 1];
        continue;
      }
      for (int ty = ty0; ty <= ty1; ++ty)
        for (int tx = tx0; tx <= tx1; ++tx)
          if (!missesCoarseTile(t, tx, ty)) {
            const auto tile = static_cast<uint32_t>(ty * ncx + tx);
            pair_tile.push_back(tile);
            pair_index.push_back(static_cast<uint32_t>(i));
            ++f[tile + 1];
          }
    }
    for (int tile = 0; tile < tiles; ++tile) f[static_cast<size_t>(tile) + 1] += f[static_cast<size_t>(tile)];
    std::vector<uint32_t>& o = order[b];
    o.resize(pair_index.size());
    thread_local std::vector<uint32_t> fill;
    fill.assign(f.begin(), f.end() - 1);
    for (size_t k = 0; k < pair_index.size(); ++k) o[fill[pair_tile[k]]++] = pair_index[k];
  });
  // Level 2 and accumulation, one coarse tile per task: the coarse tile's triangles are dealt to
  // the fine tiles their boxes overlap (one pass over the list, §4.3 Algorithm 2), then each fine
  // tile sums its triangles in a tile-local planar buffer (in cache), written to the frame once.
  tbb::parallel_for(0, tiles, [&](int tile) {
    const int cx = tile % ncx, cy = tile / ncx;
    const auto ut = static_cast<size_t>(tile);
    // Calls `f` on the tile's triangles in order: batch by batch, each batch's in index order.
    auto forEach = [&](auto&& fn) {
      for (size_t b = 0; b < batches.size(); ++b) {
        const uint32_t* o = order[b].data();
        const RasterTriangle* tris = batches[b].data();
        for (uint32_t k = first[b][ut], e = first[b][ut + 1]; k < e; ++k) fn(tris[o[k]]);
      }
    };
    bool empty = true;
    for (size_t b = 0; b < batches.size() && empty; ++b) empty = first[b][ut] == first[b][ut + 1];
    const int tx0 = cx * C, ty0 = cy * C;
    const int tw = std::min(W, tx0 + C) - tx0, th = std::min(H, ty0 + C) - ty0;
    if (empty) {
      zeroPixels(tx0, ty0, tx0 + tw - 1, ty0 + th - 1);
      return;
    }
    const int nfx = (tw + F - 1) / F, nfy = (th + F - 1) / F;
    // A coarse tile of one fine tile (as with the default sizes) keeps its triangles as they are:
    // dealing them out would only copy its list, in a pass over the triangles themselves (from
    // memory, for the Nikon 28-75's 1.9 M).
    const bool single = nfx * nfy == 1;
    std::vector<std::vector<const RasterTriangle*>> fine(single ? 0 : static_cast<size_t>(nfx) * static_cast<size_t>(nfy));
    if (!single) forEach([&](const RasterTriangle& t) {
      const int fx0 = (std::max(t.x0, tx0) - tx0) / F, fx1 = (std::min(t.x1, tx0 + tw - 1) - tx0) / F;
      const int fy0 = (std::max(t.y0, ty0) - ty0) / F, fy1 = (std::min(t.y1, ty0 + th - 1) - ty0) / F;
      const bool one = fx0 == fx1 && fy0 == fy1;
      for (int fy = fy0; fy <= fy1; ++fy)
        for (int fx = fx0; fx <= fx1; ++fx) {
          const int px0 = tx0 + fx * F, py0 = ty0 + fy * F;
          if (!one && !t.splat &&
              missesPixels(t, std::max(t.x0, px0), std::min(t.x1, px0 + F - 1), std::max(t.y0, py0),
                           std::min(t.y1, py0 + F - 1)))
            continue;
          fine[static_cast<size_t>(fy * nfx + fx)].push_back(&t);
        }
    });
    // The fine tiles are tasks too (nested in the coarse tile's task), so that the two cores
    // share the work of a crowded coarse tile (where the light's ghosts pile up) instead of one
    // of them finishing it alone. Each writes only its own pixels.
    const int stride = (F + kChunk - 1) / kChunk * kChunk;
    const size_t area = static_cast<size_t>(stride) * static_cast<size_t>(F);
    tbb::parallel_for(0, nfx * nfy, [&](int f) {
      const int i = f % nfx, j = f / nfx;
      const int fx = tx0 + i * F, fy = ty0 + j * F;
      const int fx1 = std::min(tx0 + tw, fx + F) - 1, fy1 = std::min(ty0 + th, fy + F) - 1;
      if (!single && fine[static_cast<size_t>(f)].empty()) {
        zeroPixels(fx, fy, fx1, fy1);
        return;
      }
      // The tile's planes, kept per thread: allocated afresh per tile (768 KB), their pages were
      // faulted in again and again (1.2 k page faults a frame fewer on the Nikon 28-75 at
      // 1280×720). Nothing in a tile's task waits on other tasks, so no other tile takes the
      // thread's planes meanwhile.
      thread_local std::vector<float> planes;
      planes.assign(3 * area, 0.0f);
      float* r = planes.data();
      float* g = r + area;
      float* b = g + area;
      const Planes p{r, g, b, stride, fx, fy};
      auto draw = [&](const RasterTriangle& t) {
        rasterizeInto(t, aperture, std::max(t.x0, fx), std::min(t.x1, fx1), std::max(t.y0, fy),
                      std::min(t.y1, fy1), p);
      };
      if (single) {
        forEach(draw);
      } else {
        for (const RasterTriangle* t : fine[static_cast<size_t>(f)]) draw(*t);
      }
      for (int y = fy; y <= fy1; ++y) {
        auto* dst = image->ptr<cv::Vec3f>(y);
        const size_t o = static_cast<size_t>(y - fy) * static_cast<size_t>(stride);
        if (overwrite) {
          for (int x = fx; x <= fx1; ++x) {
            const size_t q = o + static_cast<size_t>(x - fx);
            dst[x] = cv::Vec3f(r[q], g[q], b[q]);
          }
          continue;
        }
        for (int x = fx; x <= fx1; ++x) {
          const size_t q = o + static_cast<size_t>(x - fx);
          dst[x][0] += r[q];
          dst[x][1] += g[q];
          dst[x][2] += b[q];
        }
      }
    });
  });
}

}  // namespace flarekit::render
