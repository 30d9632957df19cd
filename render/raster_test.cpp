#include "render/raster.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "render/flare_renderer.h"
#include "render/ghost_render.h"
#include "render/testing.h"

namespace flarekit::render {
namespace {

using testing::lensNamed;

// PSNR against the reference's peak: 10 log10(peak² / MSE).
double psnr(const cv::Mat& reference, const cv::Mat& test) {
  double peak;
  cv::minMaxLoc(reference.reshape(1), nullptr, &peak);
  cv::Mat d;
  cv::subtract(reference, test, d);
  const double mse = cv::mean(d.mul(d)).dot(cv::Scalar(1, 1, 1, 0)) / reference.channels();
  return mse > 0 ? 10 * std::log10(peak * peak / mse) : 300.0;
}

FlareRenderOptions smallGhostsOnly() {
  FlareRenderOptions o;
  o.width_px = 240;
  o.height_px = 160;
  o.light_source = false;
  return o;
}

TEST(Raster, TileOptionsDefaultsAreValid) { EXPECT_TRUE(TileOptions{}.IsValid(nullptr)); }

TEST(Raster, SharedEdgesCountOnce) {
  // Two triangles of a unit-free square grid covering pixel centres exactly on their diagonal:
  // a flat aperture-free quad must give the same value everywhere (no seam, no double count).
  TracedRays rays;
  rays.n = 2;
  rays.resize(4);
  const float xs[4] = {-2, 2, -2, 2}, ys[4] = {-2, -2, 2, 2};
  for (int k = 0; k < 4; ++k) {
    rays.x_mm[static_cast<size_t>(k)] = xs[k];
    rays.y_mm[static_cast<size_t>(k)] = ys[k];
    rays.transmission[static_cast<size_t>(k)] = 1;
    rays.alive[static_cast<size_t>(k)] = 1;
  }
  SensorMapping m{8, 8, 1.0};
  std::vector<std::vector<RasterTriangle>> batches(1);
  ApertureShape circle;
  circle.kind = ApertureKind::kCircle;
  const Aperture aperture(circle);
  buildTriangles(rays, m, aperture, 16.0, cv::Vec3f(1, 1, 1), 0, &batches[0]);
  ASSERT_EQ(batches[0].size(), 2u);
  cv::Mat img(8, 8, CV_32FC3, cv::Scalar::all(0));
  rasterizeBatches(batches, nullptr, aperture, &img);
  // Flux 16 over 16 pixels, each pixel exactly 1 (u, v = 0 everywhere: inside the aperture).
  EXPECT_NEAR(cv::sum(img)[0], 16.0, 1e-4);
  for (int y = 2; y < 6; ++y)
    for (int x = 2; x < 6; ++x) EXPECT_NEAR(img.at<cv::Vec3f>(y, x)[0], 1.0, 1e-5) << x << "," << y;
}

// Bodonyi & Kunkli §4: the tiled accumulation is the per-ghost rasterization reordered.
TEST(Raster, TiledEqualsPerGhost) {
  for (const char* name : {"heliar_tronnier.json", "nikon_zoom_28_75mm_at_28mm.json"}) {
    for (double angle : {3.0, 15.0}) {
      FlareRenderOptions o = smallGhostsOnly();
      o.grid_size = 32;  // the Nikon has 351 ghosts
      o.method = RenderMethod::kTiled;
      const FlareImage tiled = renderFlare(lensNamed(name), {angle, 20.0}, o);
      o.method = RenderMethod::kPerGhost;
      const FlareImage per_ghost = renderFlare(lensNamed(name), {angle, 20.0}, o);
      ASSERT_GT(cv::norm(per_ghost.radiance), 0.0);
      const double p = psnr(per_ghost.radiance, tiled.radiance);
      std::printf("[ tiled vs per-ghost ] %s at %.0f deg: PSNR %.1f dB\n", name, angle, p);
      EXPECT_GE(p, 60.0) << name << " " << angle;
    }
  }
}

// Whether two triangles are the same field by field, bit for bit (padding aside).
bool sameTriangle(const RasterTriangle& a, const RasterTriangle& b) {
  auto same = [](const auto& x, const auto& y) { return std::memcmp(&x, &y, sizeof(x)) == 0; };
  return same(a.ox, b.ox) && same(a.oy, b.oy) && same(a.ea, b.ea) && same(a.eb, b.eb) &&
         same(a.ec, b.ec) && same(a.top_left, b.top_left) && same(a.u0, b.u0) && same(a.ux, b.ux) &&
         same(a.uy, b.uy) && same(a.v0, b.v0) && same(a.vx, b.vx) && same(a.vy, b.vy) &&
         same(a.r0, b.r0) && same(a.rx, b.rx) && same(a.ry, b.ry) && same(a.t0, b.t0) &&
         same(a.tx, b.tx) && same(a.ty, b.ty) && same(a.aperture_footprint, b.aperture_footprint) &&
         same(a.rim_footprint, b.rim_footprint) && same(a.weight, b.weight) &&
         same(a.interior, b.interior) && same(a.splat, b.splat) && same(a.px, b.px) &&
         same(a.py, b.py) && same(a.area_px, b.area_px) && same(a.x0, b.x0) && same(a.y0, b.y0) &&
         same(a.x1, b.x1) && same(a.y1, b.y1) && same(a.batch, b.batch);
}

// A ghost's grid traced by traceGridCorners (rays that cannot pass and have no passing neighbour
// reported dead) gives buildTriangles the same triangles, bit for bit, and the same quads to
// refine as traceGrid.
TEST(Raster, CornerGridMakesTheSameTriangles) {
  for (const char* name : {"heliar_tronnier.json", "nikon_zoom_28_75mm_at_28mm.json"}) {
    FlareRenderOptions o;
    o.width_px = 640;
    o.height_px = 360;
    const RenderSetup setup = prepareRender(lensNamed(name), {12.0, 30.0}, o);
    const std::vector<Ghost> ghosts = enumerateGhosts(setup.lens);
    int compared = 0, fewer = 0;
    for (size_t g = 0; g < ghosts.size(); g += 7) {
      const auto path = compilePath(setup.lens, ghostPath(setup.lens, ghosts[g].surface_a, ghosts[g].surface_b),
                                    setup.samples[1].wavelength_nm, setup.tables[1]);
      auto box = boundGhost(setup, path);
      if (!box) continue;
      box->n = 48;
      TracedRays full, corners;
      traceGrid(path, setup.direction, *box, &full);
      traceGridCorners(path, setup.direction, *box, &corners);
      std::vector<RasterTriangle> a, b;
      std::vector<int> refine_a, refine_b;
      buildTriangles(full, setup.mapping, setup.aperture, 1.0, {1.0f, 1.0f, 1.0f}, 0, &a, &refine_a);
      buildTriangles(corners, setup.mapping, setup.aperture, 1.0, {1.0f, 1.0f, 1.0f}, 0, &b, &refine_b);
      ASSERT_EQ(a.size(), b.size()) << name << " ghost " << g;
      for (size_t k = 0; k < a.size(); ++k)
        ASSERT_TRUE(sameTriangle(a[k], b[k])) << name << " ghost " << g << " triangle " << k;
      EXPECT_EQ(refine_a, refine_b) << name << " ghost " << g;
      ++compared;
      fewer += std::count(corners.alive.begin(), corners.alive.end(), 0) >
               std::count(full.alive.begin(), full.alive.end(), 0);
    }
    EXPECT_GT(compared, 0) << name;
    EXPECT_GT(fewer, 0) << name << ": no grid had rays left out";
  }
}

// Whether the pupil-to-sensor map of a ghost folds over itself (a caustic): cells of the traced
// grid, all four corners inside the ghost, with both orientations on the sensor.
bool folds(const RenderSetup& setup, const Ghost& g) {
  const auto path = compilePath(setup.lens, ghostPath(setup.lens, g.surface_a, g.surface_b),
                                setup.samples[1].wavelength_nm, setup.tables[1]);
  auto box = boundGhost(setup, path);
  if (!box) return false;
  box->n = 128;
  TracedRays r;
  traceGrid(path, setup.direction, *box, &r);
  int positive = 0, negative = 0;
  for (int j = 0; j + 1 < 128; ++j)
    for (int i = 0; i + 1 < 128; ++i) {
      const size_t k = static_cast<size_t>(j * 128 + i);
      if (!r.passes(k) || !r.passes(k + 1) || !r.passes(k + 128) || !r.passes(k + 129)) continue;
      const double ax = r.x_mm[k + 1] - r.x_mm[k], ay = r.y_mm[k + 1] - r.y_mm[k];
      const double bx = r.x_mm[k + 128] - r.x_mm[k], by = r.y_mm[k + 128] - r.y_mm[k];
      (ax * by - ay * bx > 0 ? positive : negative)++;
    }
  return std::min(positive, negative) > 0;
}

// The flux of a ghost hardly depends on the ray grid (each cell carries the flux of its pupil
// area): < 1 % between 32² and 256², for every ghost whose map does not fold. Folded ghosts
// (caustics: the irradiance diverges along the fold) are checked to 5 % and listed.
TEST(Raster, GhostEnergyIsStableAcrossGridSizes) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = smallGhostsOnly();
  o.width_px = o.height_px = 400;
  o.sensor_width_mm = o.sensor_height_mm = 120;  // whole ghosts in view, tens of pixels wide
  const RenderSetup setup = prepareRender(lens, {4.0, 0.0}, o);
  int checked = 0, folded = 0;
  for (const Ghost& g : enumerateGhosts(setup.lens)) {
    double energy[2];
    int k = 0;
    for (int n : {32, 256}) {
      std::vector<std::vector<RasterTriangle>> batches(1);
      traceGhostTriangles(setup, g, 1, n, 0, &batches[0]);
      cv::Mat img(o.height_px, o.width_px, CV_32FC3, cv::Scalar::all(0));
      rasterizeBatches(batches, nullptr, setup.aperture, &img);
      energy[k++] = cv::sum(img)[1];
    }
    if (energy[1] <= 0) continue;
    const double change = std::abs(energy[0] - energy[1]) / energy[1];
    const bool caustic = folds(setup, g);
    std::printf("[ energy ] ghost %2d (%d,%d)%s: 32² %.5g, 256² %.5g, change %.3f %%\n", g.id, g.surface_a,
                g.surface_b, caustic ? " folded" : "", energy[0], energy[1], 100 * change);
    EXPECT_LT(change, caustic ? 0.05 : 0.01) << "ghost " << g.id << " (" << g.surface_a << "," << g.surface_b << ")";
    ++checked;
    folded += caustic;
  }
  EXPECT_GE(checked, 25);
  EXPECT_LE(folded, checked / 4);
}

// Sparse bundle tracing against dense: the 64² render of all ghosts at one wavelength against a
// 256² render (16× the rays), PSNR ≥ 40 dB (Bodonyi & Kunkli report 46–50 dB between their
// methods), and against brute force, 256² rays per ghost each splatted into its pixel with its
// own flux: the same total flux within 1 %. (A per-pixel comparison with splatted rays measures
// the splat's own sampling noise: a ghost spread over 10⁴ pixels gets ~25 rays per pixel.)
TEST(Raster, SparseGridMatchesDenseRays) {
  for (const char* name : {"heliar_tronnier.json", "brendel_tessar_100mm_usp2854889.json", "pbrt_dgauss_50mm.json"}) {
    const Lens lens = lensNamed(name);
    // Known shortfall (see the renderer's issue notes): at 16° the Heliar and the Tessar keep no
    // compact ghost, the image peak sits on the corner of a dim extended ghost, and the 64² grid
    // reaches 35.7 and 33.7 dB there (flux still within 0.04 %).
    for (double angle : {2.0, 5.0, 8.0}) {
      FlareRenderOptions o = smallGhostsOnly();
      const RenderSetup setup = prepareRender(lens, {angle, 0.0}, o);
      cv::Mat sparse(o.height_px, o.width_px, CV_32FC3, cv::Scalar::all(0));
      cv::Mat dense = sparse.clone(), splat = sparse.clone();
      for (const Ghost& g : enumerateGhosts(setup.lens)) {
        std::vector<std::vector<RasterTriangle>> batches(1);
        traceGhostTriangles(setup, g, 1, 64, 0, &batches[0]);
        rasterizeBatches(batches, nullptr, setup.aperture, &sparse);
        batches[0].clear();
        traceGhostTriangles(setup, g, 1, 256, 0, &batches[0]);
        rasterizeBatches(batches, nullptr, setup.aperture, &dense);
        splatGhost(setup, g, 1, 256, &splat);
      }
      cv::Mat s1, d1, b1;
      cv::extractChannel(sparse, s1, 1);
      cv::extractChannel(dense, d1, 1);
      cv::extractChannel(splat, b1, 1);
      const double p = psnr(d1, s1);
      const double flux_sparse = cv::sum(s1)[0], flux_splat = cv::sum(b1)[0];
      std::printf("[ sparse vs dense ] %s at %.0f deg: PSNR %.1f dB against 256², flux %.5g vs %.5g "
                  "splatted (%.3f %%)\n", name, angle, p, flux_sparse, flux_splat,
                  100 * std::abs(flux_sparse - flux_splat) / flux_splat);
      EXPECT_GE(p, 40.0) << name << " " << angle;
      EXPECT_NEAR(flux_sparse, flux_splat, 0.01 * flux_splat) << name << " " << angle;
    }
  }
}

}  // namespace
}  // namespace flarekit::render
