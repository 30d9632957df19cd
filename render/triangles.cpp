// The triangles of a traced ray grid (render/raster.h buildTriangles): each cell's quad on the
// sensor split along a fixed diagonal, its values set up for the rasterizers in raster.cpp, and
// the cells that fold or cross the rim handed back for refinement.
#include "render/raster.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace flarekit::render {
namespace {

struct RasterVertex {
  float x, y, u, v, r, t;
  float e;  // irradiance at the ray (see buildTriangles), 0 where no cell beside it shows the ghost
};

// Whether points spanning [min_x, max_x] × [min_y, max_y] (pixel coordinates) lie wholly off
// one side of the image: a triangle there has no pixel, splatted or sampled (see makeTriangle).
bool offImage(float min_x, float max_x, float min_y, float max_y, const SensorMapping& m) {
  return max_x < 0 || max_y < 0 || min_x >= m.width_px || min_y >= m.height_px;
}

// Margin of RasterTriangle::rim_clear and aperture_clear beyond a whole footprint (in r_rel and
// aperture units): far above the rounding of the interpolated values (~1e-7), so 0.5 + d/footprint
// stays above 1 at every pixel inside the triangle.
constexpr float kClearMargin = 1e-5f;

// A triangle Gouraud-shaded (see the end) sets *smooth_flux to the integral of its corners'
// irradiance over it, in the units of cell_flux / pitch², and leaves it 0 otherwise.
bool makeTriangle(RasterVertex p0, RasterVertex p1, RasterVertex p2, const SensorMapping& m,
                  const Aperture& aperture, double cell_flux, const cv::Vec3f& weight, int batch,
                  RasterTriangle* out, double* smooth_flux) {
  *smooth_flux = 0;
  const float min_x = std::min({p0.x, p1.x, p2.x}), max_x = std::max({p0.x, p1.x, p2.x});
  const float min_y = std::min({p0.y, p1.y, p2.y}), max_y = std::max({p0.y, p1.y, p2.y});
  // Off the image first, the cheapest test and the commonest end: at 10° four in five of the
  // Heliar's triangles. (A sampled triangle there gets an empty pixel box below, a splatted one
  // would be rejected like this.)
  if (offImage(min_x, max_x, min_y, max_y, m)) return false;
  double area2 = (static_cast<double>(p1.x) - p0.x) * (static_cast<double>(p2.y) - p0.y) -
                 (static_cast<double>(p2.x) - p0.x) * (static_cast<double>(p1.y) - p0.y);
  if (area2 < 0) {
    std::swap(p1, p2);
    area2 = -area2;
  }
  if (!(area2 > 1e-6)) return false;  // degenerate: covers no pixel centre reliably
  RasterTriangle& t = *out;
  // Triangles smaller than kSplatArea pixels are splatted (see rasterizeInto): their box is the
  // pixels they touch. Larger ones are sampled at pixel centres (i + 0.5) inside [min, max].
  t.splat = area2 < 2.0 * kSplatArea;
  if (!(max_x - min_x < 1e5f && max_y - min_y < 1e5f)) return false;
  if (t.splat) {
    t.x0 = std::max(0, static_cast<int>(std::floor(min_x)));
    t.x1 = std::min(m.width_px - 1, static_cast<int>(std::floor(max_x)));
    t.y0 = std::max(0, static_cast<int>(std::floor(min_y)));
    t.y1 = std::min(m.height_px - 1, static_cast<int>(std::floor(max_y)));
  } else {
    t.x0 = std::max(0, static_cast<int>(std::ceil(std::max(min_x, -1.0f) - 0.5f)));
    t.x1 = std::min(m.width_px - 1, static_cast<int>(std::floor(std::min(max_x, m.width_px + 1.0f) - 0.5f)));
    t.y0 = std::max(0, static_cast<int>(std::ceil(std::max(min_y, -1.0f) - 0.5f)));
    t.y1 = std::min(m.height_px - 1, static_cast<int>(std::floor(std::min(max_y, m.height_px + 1.0f) - 0.5f)));
  }
  if (t.x0 > t.x1 || t.y0 > t.y1) return false;
  t.px[0] = p0.x;
  t.px[1] = p1.x;
  t.px[2] = p2.x;
  t.py[0] = p0.y;
  t.py[1] = p1.y;
  t.py[2] = p2.y;
  t.area_px = static_cast<float>(0.5 * area2);
  t.ox = p0.x;
  t.oy = p0.y;
  const RasterVertex* p[3] = {&p0, &p1, &p2};
  for (int k = 0; k < 3; ++k) {
    const RasterVertex& a = *p[k];
    const RasterVertex& b = *p[(k + 1) % 3];
    const float dx = b.x - a.x, dy = b.y - a.y;
    t.ea[k] = -dy;
    t.eb[k] = dx;
    t.ec[k] = dx * (t.oy - a.y) - dy * (t.ox - a.x);
    t.top_left[k] = dy < 0 || (dy == 0 && dx > 0);
  }
  const float d1x = p1.x - p0.x, d1y = p1.y - p0.y, d2x = p2.x - p0.x, d2y = p2.y - p0.y;
  const float inv = static_cast<float>(1.0 / area2);
  auto plane = [&](float a0, float a1, float a2, float* c0, float* cx, float* cy) {
    *c0 = a0;
    *cx = ((a1 - a0) * d2y - (a2 - a0) * d1y) * inv;
    *cy = ((a2 - a0) * d1x - (a1 - a0) * d2x) * inv;
  };
  plane(p0.u, p1.u, p2.u, &t.u0, &t.ux, &t.uy);
  plane(p0.v, p1.v, p2.v, &t.v0, &t.vx, &t.vy);
  plane(p0.r, p1.r, p2.r, &t.r0, &t.rx, &t.ry);
  plane(p0.t, p1.t, p2.t, &t.t0, &t.tx, &t.ty);
  t.aperture_footprint =
      std::max(1e-6f, std::sqrt(0.5f * (t.ux * t.ux + t.uy * t.uy + t.vx * t.vx + t.vy * t.vy)));
  t.rim_footprint = std::max(1e-6f, std::sqrt(t.rx * t.rx + t.ry * t.ry));
  // Culling and the interior fast path. r_rel is linear over the triangle: past 1 + half a
  // footprint at every corner means dark everywhere.
  const float rim_out = 1.0f + 0.5f * t.rim_footprint, rim_in = 1.0f - 0.5f * t.rim_footprint;
  if (p0.r >= rim_out && p1.r >= rim_out && p2.r >= rim_out) return false;
  bool interior = p0.r <= rim_in && p1.r <= rim_in && p2.r <= rim_in;
  if (aperture.hasDistance()) {
    const float half = 0.5f * t.aperture_footprint;
    // Beyond one straight blade edge at every corner: outside the (convex) iris everywhere.
    if (aperture.shape().kind == ApertureKind::kPolygon && aperture.rounding() == 0.0f)
      for (int k = 0; k < aperture.edgeCount(); ++k) {
        const float nx = aperture.edgeNormalX(k), ny = aperture.edgeNormalY(k);
        const float limit = aperture.apothem() + half;
        if (p0.u * nx + p0.v * ny >= limit && p1.u * nx + p1.v * ny >= limit &&
            p2.u * nx + p2.v * ny >= limit)
          return false;
      }
    const float d_min = std::min({aperture.signedDistance(p0.u, p0.v), aperture.signedDistance(p1.u, p1.v),
                                  aperture.signedDistance(p2.u, p2.v)});
    interior = interior && d_min >= half;
    t.aperture_clear = d_min >= t.aperture_footprint + kClearMargin;
  } else {
    interior = false;
    t.aperture_clear = false;
  }
  t.interior = interior;
  t.rim_clear = std::max({p0.r, p1.r, p2.r}) <= 1.0f - t.rim_footprint - kClearMargin;
  // Irradiance from the area ratio of the ray-grid cells (Hullin 2011 §3.2), Gouraud-shaded
  // (their §5, "smooth shading"): each corner's irradiance, interpolated with T, so that a ghost's
  // light varies continuously over the grid's cells, as a real ghost's does, instead of stepping
  // at every cell's edge. A splatted triangle (a caustic's) and one with a corner beside no
  // cell showing the ghost carry their own half cell's flux over their area instead.
  if (!t.splat && p0.e > 0 && p1.e > 0 && p2.e > 0) {
    plane(p0.t * p0.e, p1.t * p1.e, p2.t * p2.e, &t.t0, &t.tx, &t.ty);
    t.weight = weight;
    *smooth_flux = 0.5 * area2 * (static_cast<double>(p0.e) + p1.e + p2.e) / 3.0;
  } else {
    const double scale = cell_flux / (area2 * m.pixel_pitch_mm * m.pixel_pitch_mm);
    t.weight = weight * static_cast<float>(scale);
  }
  t.batch = batch;
  return true;
}

}  // namespace

void buildTriangles(const TracedRays& rays, const SensorMapping& mapping, const Aperture& aperture,
                    double cell_flux, const cv::Vec3f& weight, int batch,
                    std::vector<RasterTriangle>* out, std::vector<int>* refine,
                    size_t first_ray) {
  const int n = rays.n;
  const size_t count = static_cast<size_t>(n) * static_cast<size_t>(n);
  // Every ray's sensor position in pixels, converted once per grid (a ray is a corner of up to
  // four quads, and the conversion divides). (Kept per thread, as `orientation` below.)
  thread_local std::vector<float> pixel_x, pixel_y;
  pixel_x.resize(count);
  pixel_y.resize(count);
  for (size_t k = 0; k < count; ++k) {
    pixel_x[k] = static_cast<float>(mapping.toPixelX(rays.x_mm[first_ray + k]));
    pixel_y[k] = static_cast<float>(mapping.toPixelY(rays.y_mm[first_ray + k]));
  }
  // Each ray's irradiance: the flux of the cells beside it that show part of the ghost over their
  // sensor area (an average of their irradiances weighed by area, bounded by the largest, also at
  // a fold). Only those cells, so that traceGridCorners' grids give the same values.
  auto valid = [&](size_t k) {
    return rays.r_rel[k] <= 1.0f && rays.u[k] * rays.u[k] + rays.v[k] * rays.v[k] <= 1.0f;
  };
  thread_local std::vector<float> irradiance;
  irradiance.assign(count, 0.0f);
  {
    thread_local std::vector<double> area_sum;
    thread_local std::vector<int> cells;
    area_sum.assign(count, 0.0);
    cells.assign(count, 0);
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        const size_t g00 = static_cast<size_t>(j * n + i), g10 = g00 + 1;
        const size_t g01 = g00 + static_cast<size_t>(n), g11 = g01 + 1;
        const size_t f = first_ray;
        if (!rays.alive[f + g00] || !rays.alive[f + g10] || !rays.alive[f + g01] || !rays.alive[f + g11])
          continue;
        if (!valid(f + g00) && !valid(f + g10) && !valid(f + g01) && !valid(f + g11)) continue;
        // A quad's area from its diagonals, pixels².
        const double area = 0.5 * std::abs((static_cast<double>(pixel_x[g11]) - pixel_x[g00]) *
                                               (static_cast<double>(pixel_y[g01]) - pixel_y[g10]) -
                                           (static_cast<double>(pixel_y[g11]) - pixel_y[g00]) *
                                               (static_cast<double>(pixel_x[g01]) - pixel_x[g10]));
        for (size_t g : {g00, g10, g01, g11}) {
          area_sum[g] += area;
          ++cells[g];
        }
      }
    const double pitch2 = mapping.pixel_pitch_mm * mapping.pixel_pitch_mm;
    for (size_t g = 0; g < count; ++g)
      if (cells[g] > 0 && area_sum[g] > 1e-12)
        irradiance[g] = static_cast<float>(cells[g] * cell_flux / (area_sum[g] * pitch2));
  }
  auto vertex = [&](int i, int j) {
    const size_t g = static_cast<size_t>(j * n + i);
    const size_t k = first_ray + g;
    return RasterVertex{pixel_x[g], pixel_y[g], rays.u[k], rays.v[k], rays.r_rel[k],
                        rays.transmission[k], irradiance[g]};
  };
  // Orientation of each quad's two triangles on the sensor (+1, −1, 0 = mixed or degenerate):
  // where the pupil-to-sensor map folds (a caustic), linear interpolation across the fold is
  // wrong, so those quads and their neighbours are refined too.
  // (Kept per thread: refined cells call this thousands of times per frame.)
  thread_local std::vector<int8_t> orientation;
  if (refine) {
    orientation.assign(static_cast<size_t>(n) * static_cast<size_t>(n), 0);
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        const size_t k00 = first_ray + static_cast<size_t>(j * n + i), k10 = k00 + 1;
        const size_t k01 = k00 + static_cast<size_t>(n), k11 = k01 + 1;
        if (!rays.alive[k00] || !rays.alive[k10] || !rays.alive[k01] || !rays.alive[k11]) continue;
        auto cross = [&](size_t a, size_t b, size_t c) {
          return (rays.x_mm[b] - rays.x_mm[a]) * (rays.y_mm[c] - rays.y_mm[a]) -
                 (rays.x_mm[c] - rays.x_mm[a]) * (rays.y_mm[b] - rays.y_mm[a]);
        };
        // Only quads that show part of the ghost count: outside it rays may fold freely.
        if (!valid(k00) && !valid(k10) && !valid(k01) && !valid(k11)) {
          orientation[k00 - first_ray] = 2;
          continue;
        }
        const float s1 = cross(k00, k10, k11), s2 = cross(k00, k11, k01);
        orientation[k00 - first_ray] = (s1 > 0 && s2 > 0) ? 1 : (s1 < 0 && s2 < 0) ? -1 : 0;
      }
  }
  auto folded = [&](int i, int j) {
    const int8_t o = orientation[static_cast<size_t>(j * n + i)];
    if (o == 0) return true;
    const int di[4] = {1, -1, 0, 0}, dj[4] = {0, 0, 1, -1};
    for (int d = 0; d < 4; ++d) {
      const int a = i + di[d], b = j + dj[d];
      if (a < 0 || b < 0 || a + 1 >= n || b + 1 >= n) continue;
      const int8_t q = orientation[static_cast<size_t>(b * n + a)];
      if (q != 0 && q != 2 && q != o) return true;
    }
    return false;
  };
  // Interpolated corner values do not carry each cell's flux exactly (the flat values do): the
  // smooth triangles' irradiance is scaled so that together they carry their cells' flux.
  thread_local std::vector<size_t> smooth_triangles;
  smooth_triangles.clear();
  double cells_flux = 0, interpolated_flux = 0;
  auto keep = [&](const RasterTriangle& t, double smooth) {
    out->push_back(t);
    if (smooth <= 0) return;
    smooth_triangles.push_back(out->size() - 1);
    cells_flux += 0.5 * cell_flux / (mapping.pixel_pitch_mm * mapping.pixel_pitch_mm);
    interpolated_flux += smooth;
  };
  RasterTriangle t;
  double smooth = 0;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const size_t k00 = first_ray + static_cast<size_t>(j * n + i), k10 = k00 + 1;
      const size_t k01 = k00 + static_cast<size_t>(n), k11 = k01 + 1;
      const size_t corner[4] = {k00, k10, k01, k11};
      bool any_valid = false, all_alive = true;
      float r_min = 1e30f, r_max = -1e30f;
      for (size_t c : corner) {
        all_alive = all_alive && rays.alive[c];
        any_valid = any_valid || (rays.alive[c] && valid(c));
        r_min = std::min(r_min, rays.r_rel[c]);
        r_max = std::max(r_max, rays.r_rel[c]);
      }
      if (!any_valid) continue;
      if (refine && (!all_alive || (r_min <= 1.0f && r_max > 1.0f && r_max - r_min > kRefineJump) ||
                     folded(i, j))) {
        refine->push_back(j * n + i);
        continue;
      }
      if (!all_alive) {
        // Not refined further (the last level): of a quad with one dead corner, the triangle of
        // its three live corners still carries its half of the cell's pupil area to the sensor.
        int dead = -1, count = 0;
        for (int c = 0; c < 4; ++c)
          if (!rays.alive[corner[c]]) {
            dead = c;
            ++count;
          }
        if (count != 1) continue;
        RasterVertex v[4] = {vertex(i, j), vertex(i + 1, j), vertex(i, j + 1), vertex(i + 1, j + 1)};
        // The other three in the order around the quad (00, 10, 11, 01), skipping the dead one.
        const int ring[4] = {0, 1, 3, 2};
        RasterVertex tri[3];
        int m = 0;
        for (int r : ring)
          if (r != dead) tri[m++] = v[r];
        if (makeTriangle(tri[0], tri[1], tri[2], mapping, aperture, cell_flux, weight, batch, &t, &smooth))
          keep(t, smooth);
        continue;
      }
      const RasterVertex v00 = vertex(i, j), v10 = vertex(i + 1, j);
      const RasterVertex v01 = vertex(i, j + 1), v11 = vertex(i + 1, j + 1);
      if (offImage(std::min({v00.x, v10.x, v01.x, v11.x}), std::max({v00.x, v10.x, v01.x, v11.x}),
                   std::min({v00.y, v10.y, v01.y, v11.y}), std::max({v00.y, v10.y, v01.y, v11.y}),
                   mapping))
        continue;  // both triangles would be
      if (makeTriangle(v00, v10, v11, mapping, aperture, cell_flux, weight, batch, &t, &smooth)) keep(t, smooth);
      if (makeTriangle(v00, v11, v01, mapping, aperture, cell_flux, weight, batch, &t, &smooth)) keep(t, smooth);
    }
  if (interpolated_flux > 0) {
    const float scale = static_cast<float>(cells_flux / interpolated_flux);
    for (size_t k : smooth_triangles) {
      RasterTriangle& s = (*out)[k];
      s.t0 *= scale;
      s.tx *= scale;
      s.ty *= scale;
    }
  }
}

}  // namespace flarekit::render
