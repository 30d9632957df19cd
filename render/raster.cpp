#include "render/raster.h"

#include <algorithm>
#include <cmath>
#include <mutex>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace flarekit::render {
namespace {

struct RasterVertex {
  float x, y, u, v, r, t;
};

bool makeTriangle(RasterVertex p0, RasterVertex p1, RasterVertex p2, const SensorMapping& m,
                  double cell_flux, const cv::Vec3f& weight, int batch, RasterTriangle* out) {
  double area2 = (static_cast<double>(p1.x) - p0.x) * (static_cast<double>(p2.y) - p0.y) -
                 (static_cast<double>(p2.x) - p0.x) * (static_cast<double>(p1.y) - p0.y);
  if (area2 < 0) {
    std::swap(p1, p2);
    area2 = -area2;
  }
  if (!(area2 > 1e-6)) return false;  // degenerate: covers no pixel centre reliably
  const float min_x = std::min({p0.x, p1.x, p2.x}), max_x = std::max({p0.x, p1.x, p2.x});
  const float min_y = std::min({p0.y, p1.y, p2.y}), max_y = std::max({p0.y, p1.y, p2.y});
  RasterTriangle& t = *out;
  // Pixel centres (i + 0.5) inside [min, max].
  t.x0 = std::max(0, static_cast<int>(std::ceil(min_x - 0.5f)));
  t.x1 = std::min(m.width_px - 1, static_cast<int>(std::floor(max_x - 0.5f)));
  t.y0 = std::max(0, static_cast<int>(std::ceil(min_y - 0.5f)));
  t.y1 = std::min(m.height_px - 1, static_cast<int>(std::floor(max_y - 0.5f)));
  if (t.x0 > t.x1 || t.y0 > t.y1) return false;
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
  // Flux of the triangle's pupil area spread over its sensor area (Hullin 2011 §3.2: intensity
  // from the area ratio of the ray-grid cells), in relative irradiance.
  const double scale = cell_flux / (area2 * m.pixel_pitch_mm * m.pixel_pitch_mm);
  t.weight = weight * static_cast<float>(scale);
  t.batch = batch;
  return true;
}

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

// Adds triangle `t` to `buffer` (CV_32FC3 covering pixels [bx, bx + cols) × [by, by + rows)),
// restricted to pixel columns [x0, x1] and rows [y0, y1].
inline void rasterizeInto(const RasterTriangle& t, const Aperture& aperture, int x0, int x1,
                          int y0, int y1, cv::Mat& buffer, int bx, int by) {
  for (int y = y0; y <= y1; ++y) {
    const float dy = (y + 0.5f) - t.oy;
    auto* row = buffer.ptr<cv::Vec3f>(y - by);
    for (int x = x0; x <= x1; ++x) {
      const float dx = (x + 0.5f) - t.ox;
      if (!inside(t, dx, dy)) continue;
      const float s = shade(t, aperture, dx, dy);
      if (s > 0.0f) row[x - bx] += t.weight * s;
    }
  }
}

}  // namespace

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

void buildTriangles(const TracedRays& rays, const SensorMapping& mapping, double cell_flux,
                    const cv::Vec3f& weight, int batch, std::vector<RasterTriangle>* out,
                    std::vector<int>* refine) {
  const int n = rays.n;
  auto vertex = [&](int i, int j) {
    const size_t k = static_cast<size_t>(j * n + i);
    return RasterVertex{static_cast<float>(mapping.toPixelX(rays.x_mm[k])),
                        static_cast<float>(mapping.toPixelY(rays.y_mm[k])),
                        rays.u[k], rays.v[k], rays.r_rel[k], rays.transmission[k]};
  };
  auto valid = [&](size_t k) {
    return rays.r_rel[k] <= 1.0f && rays.u[k] * rays.u[k] + rays.v[k] * rays.v[k] <= 1.0f;
  };
  RasterTriangle t;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const size_t k00 = static_cast<size_t>(j * n + i), k10 = k00 + 1;
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
      if (refine && (!all_alive || (r_min <= 1.0f && r_max > 1.0f && r_max - r_min > kRefineJump))) {
        refine->push_back(j * n + i);
        continue;
      }
      if (!all_alive) continue;
      const RasterVertex v00 = vertex(i, j), v10 = vertex(i + 1, j);
      const RasterVertex v01 = vertex(i, j + 1), v11 = vertex(i + 1, j + 1);
      if (makeTriangle(v00, v10, v11, mapping, cell_flux, weight, batch, &t)) out->push_back(t);
      if (makeTriangle(v00, v11, v01, mapping, cell_flux, weight, batch, &t)) out->push_back(t);
    }
}

void rasterizeBatches(const std::vector<std::vector<RasterTriangle>>& batches,
                      const std::vector<bool>* keep, const Aperture& aperture, cv::Mat* image) {
  for (size_t b = 0; b < batches.size(); ++b) {
    if (keep && !(*keep)[b]) continue;
    for (const RasterTriangle& t : batches[b])
      rasterizeInto(t, aperture, t.x0, t.x1, t.y0, t.y1, *image, 0, 0);
  }
}

void rasterizePerGhost(const std::vector<std::vector<RasterTriangle>>& batches,
                       const Aperture& aperture, cv::Mat* image) {
  std::mutex mutex;
  tbb::parallel_for(size_t{0}, batches.size(), [&](size_t b) {
    const auto& tris = batches[b];
    if (tris.empty()) return;
    int x0 = image->cols, y0 = image->rows, x1 = -1, y1 = -1;
    for (const RasterTriangle& t : tris) {
      x0 = std::min(x0, t.x0);
      y0 = std::min(y0, t.y0);
      x1 = std::max(x1, t.x1);
      y1 = std::max(y1, t.y1);
    }
    // The ghost's own buffer over its bounding box (Hullin's one-ghost-at-a-time pass), then
    // blended additively into the frame.
    cv::Mat buffer(y1 - y0 + 1, x1 - x0 + 1, CV_32FC3, cv::Scalar::all(0));
    for (const RasterTriangle& t : tris) rasterizeInto(t, aperture, t.x0, t.x1, t.y0, t.y1, buffer, x0, y0);
    std::lock_guard<std::mutex> lock(mutex);
    cv::Mat roi = (*image)(cv::Rect(x0, y0, buffer.cols, buffer.rows));
    roi += buffer;
  });
}

void rasterizeTiled(const std::vector<std::vector<RasterTriangle>>& batches,
                    const Aperture& aperture, const TileOptions& options, cv::Mat* image) {
  const int W = image->cols, H = image->rows;
  const int C = options.coarse_tile_px, F = options.fine_tile_px;
  const int ncx = (W + C - 1) / C, ncy = (H + C - 1) / C;
  const int tiles = ncx * ncy;
  struct Ref {
    uint32_t batch, index;
  };
  // Level 1: every triangle into the coarse tiles its bounding box overlaps, counted per batch in
  // parallel, then laid out tile by tile in batch order (deterministic).
  std::vector<std::vector<int>> counts(batches.size(), std::vector<int>(static_cast<size_t>(tiles), 0));
  tbb::parallel_for(size_t{0}, batches.size(), [&](size_t b) {
    auto& c = counts[b];
    for (const RasterTriangle& t : batches[b])
      for (int ty = t.y0 / C; ty <= t.y1 / C; ++ty)
        for (int tx = t.x0 / C; tx <= t.x1 / C; ++tx) ++c[static_cast<size_t>(ty * ncx + tx)];
  });
  std::vector<size_t> start(static_cast<size_t>(tiles) + 1, 0);
  std::vector<std::vector<size_t>> batch_offset(batches.size(), std::vector<size_t>(static_cast<size_t>(tiles)));
  for (int tile = 0; tile < tiles; ++tile) {
    size_t s = start[static_cast<size_t>(tile)];
    for (size_t b = 0; b < batches.size(); ++b) {
      batch_offset[b][static_cast<size_t>(tile)] = s;
      s += static_cast<size_t>(counts[b][static_cast<size_t>(tile)]);
    }
    start[static_cast<size_t>(tile) + 1] = s;
  }
  std::vector<Ref> refs(start.back());
  tbb::parallel_for(size_t{0}, batches.size(), [&](size_t b) {
    auto offset = batch_offset[b];
    for (size_t i = 0; i < batches[b].size(); ++i) {
      const RasterTriangle& t = batches[b][i];
      for (int ty = t.y0 / C; ty <= t.y1 / C; ++ty)
        for (int tx = t.x0 / C; tx <= t.x1 / C; ++tx)
          refs[offset[static_cast<size_t>(ty * ncx + tx)]++] = {static_cast<uint32_t>(b), static_cast<uint32_t>(i)};
    }
  });
  // Level 2 and accumulation, one coarse tile per task: each fine tile keeps the triangles that
  // overlap it and sums them pixel by pixel in a tile-local buffer written once.
  tbb::parallel_for(0, tiles, [&](int tile) {
    const int cx = tile % ncx, cy = tile / ncx;
    const size_t begin = start[static_cast<size_t>(tile)], end = start[static_cast<size_t>(tile) + 1];
    if (begin == end) return;
    std::vector<const RasterTriangle*> fine;
    cv::Mat acc(F, F, CV_32FC3);
    for (int fy = cy * C; fy < std::min(H, (cy + 1) * C); fy += F)
      for (int fx = cx * C; fx < std::min(W, (cx + 1) * C); fx += F) {
        const int fx1 = std::min(W, fx + F) - 1, fy1 = std::min(H, fy + F) - 1;
        fine.clear();
        for (size_t r = begin; r < end; ++r) {
          const RasterTriangle& t = batches[refs[r].batch][refs[r].index];
          if (t.x1 < fx || t.x0 > fx1 || t.y1 < fy || t.y0 > fy1) continue;
          fine.push_back(&t);
        }
        if (fine.empty()) continue;
        acc.setTo(cv::Scalar::all(0));
        for (const RasterTriangle* t : fine)
          rasterizeInto(*t, aperture, std::max(t->x0, fx), std::min(t->x1, fx1),
                        std::max(t->y0, fy), std::min(t->y1, fy1), acc, fx, fy);
        for (int y = fy; y <= fy1; ++y) {
          auto* dst = image->ptr<cv::Vec3f>(y);
          const auto* src = acc.ptr<cv::Vec3f>(y - fy);
          for (int x = fx; x <= fx1; ++x) dst[x] += src[x - fx];
        }
      }
  });
}

}  // namespace flarekit::render
