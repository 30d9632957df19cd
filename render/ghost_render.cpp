#include "render/ghost_render.h"

#include <algorithm>
#include <cmath>
#include <mutex>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "common/error.h"
#include "render/paraxial.h"

namespace flarekit::render {

namespace {
// Sub-grid sizes for the cells along discontinuous ghost edges (first level, deeper levels).
// The second level halves its cells (an edge to 1/8 of a grid cell) rather than quartering them
// (1/16): it traced 44 % of a Heliar frame's rays (445 k of 1.01 M at 10°) and yielded 19 % of
// its triangles; halving cuts the frame to 0.74 M rays and hardly changes the image (PSNR
// 81 dB against the 1/16 edges at 0°, 85 dB at 5°, identical at 15°). Two levels of halving
// instead of quartering first cost about as many rays and resolve worse (67 dB).
constexpr int kRefine = 4;
constexpr int kRefineDeeper = 2;
constexpr int kRefineDepth = 2;

// Appends to `subs` the sub-grids of `grid`'s cells `cells` (indices j·n + i), m² cells each.
void appendSubGrids(const RayGrid& grid, const std::vector<int>& cells, int m,
                    std::vector<RayGrid>* subs) {
  const double cell = grid.spacing_mm();
  for (const int c : cells) {
    const int i = c % grid.n, j = c / grid.n;
    RayGrid sub;
    sub.n = m + 1;
    sub.half_size_mm = 0.5 * cell;
    sub.center_x_mm = grid.center_x_mm - grid.half_size_mm + (i + 0.5) * cell;
    sub.center_y_mm = grid.center_y_mm - grid.half_size_mm + (j + 0.5) * cell;
    subs->push_back(sub);
  }
}

// Refinement (see buildRefinedTriangles): appends to `out` the triangles of grids [g0, g1) of
// `grids` (of one size, at refinement level `depth`, traced together in `rays`), each grid's own
// followed by its refined cells', depth first. Their sub-grids are traced together, so a deeper
// level's small grids fill blocks of rays.
void refineGrids(const RenderSetup& setup, const CompiledPath& path, const cv::Vec3f& weight,
                 int batch, const std::vector<RayGrid>& grids, const TracedRays& rays, size_t g0,
                 size_t g1, double cell_flux, int depth, long long* traced,
                 std::vector<RasterTriangle>* out) {
  const size_t rays_per_grid = static_cast<size_t>(rays.n) * static_cast<size_t>(rays.n);
  if (depth == kRefineDepth) {  // the last level: no sub-grids, the triangles go straight out
    for (size_t g = g0; g < g1; ++g)
      buildTriangles(rays, setup.mapping, setup.aperture, cell_flux, weight, batch, out, nullptr,
                     g * rays_per_grid);
    return;
  }
  // Each grid's own triangles [own[g], own[g + 1]) of `own_triangles`, its refined cells the
  // sub-grids [children[g], children[g + 1]).
  const int m = kRefineDeeper;  // (refineGrids starts at the first level below the grid)
  std::vector<RasterTriangle> own_triangles;
  std::vector<size_t> own{0}, children{0};
  std::vector<RayGrid> subs;
  std::vector<int> refine;
  for (size_t g = g0; g < g1; ++g) {
    refine.clear();
    buildTriangles(rays, setup.mapping, setup.aperture, cell_flux, weight, batch, &own_triangles,
                   &refine, g * rays_per_grid);
    appendSubGrids(grids[g], refine, m, &subs);
    own.push_back(own_triangles.size());
    children.push_back(subs.size());
  }
  TracedRays sub_rays;
  if (!subs.empty()) {
    traceGrids(path, setup.direction, subs, &sub_rays);
    *traced += static_cast<long long>((m + 1) * (m + 1)) * static_cast<long long>(subs.size());
  }
  for (size_t k = 0; k + 1 < own.size(); ++k) {
    out->insert(out->end(), own_triangles.begin() + static_cast<std::ptrdiff_t>(own[k]),
                own_triangles.begin() + static_cast<std::ptrdiff_t>(own[k + 1]));
    if (children[k] < children[k + 1])
      refineGrids(setup, path, weight, batch, subs, sub_rays, children[k], children[k + 1],
                  cell_flux / (m * m), depth + 1, traced, out);
  }
}

// Builds the triangles of a ghost's traced grid; cells across a discontinuous edge (rays turning
// grazing or dying) are traced again on a kRefine² sub-grid, recursively up to kRefineDepth
// levels, in the spirit of Bodonyi & Kunkli §4.2 (denser rays only near the ghost's edges). The
// triangles follow in the order of a depth-first walk: a grid's own, then each of its refined
// cells' in turn. The grid's sub-grids are traced together, and theirs kGridsPerTrace sub-grids
// at a time: traced a cell at a time, the second level's 3×3 grids filled a few lanes of a block
// each, and the calls per event dominated their work. (A whole
// level at a time, its triangles would wait in memory to be put in order: on the Nikon 28-75 that
// copy cost more than it saved.)
constexpr size_t kGridsPerTrace = 64;
void buildRefinedTriangles(const RenderSetup& setup, const CompiledPath& path,
                           const cv::Vec3f& weight, int batch, const RayGrid& grid,
                           const TracedRays& rays, double cell_flux, long long* traced,
                           std::vector<RasterTriangle>* out) {
  std::vector<int> refine;
  buildTriangles(rays, setup.mapping, setup.aperture, cell_flux, weight, batch, out,
                 kRefineDepth > 0 ? &refine : nullptr);
  if (refine.empty()) return;
  std::vector<RayGrid> subs;
  appendSubGrids(grid, refine, kRefine, &subs);
  TracedRays sub_rays;
  traceGrids(path, setup.direction, subs, &sub_rays);
  *traced += static_cast<long long>((kRefine + 1) * (kRefine + 1)) * static_cast<long long>(subs.size());
  for (size_t g = 0; g < subs.size(); g += kGridsPerTrace)
    refineGrids(setup, path, weight, batch, subs, sub_rays, g, std::min(subs.size(), g + kGridsPerTrace),
                cell_flux / (kRefine * kRefine), 1, traced, out);
}

}  // namespace

std::vector<SurfaceCoating> surfaceCoatings(const Lens& lens, const FlareRenderOptions& options) {
  const double n_c = options.coating_ior > 0 ? options.coating_ior
                                             : lens.coating_ior.value_or(1.38);
  std::vector<SurfaceCoating> out(lens.surfaces.size());
  for (size_t i = 0; i < lens.surfaces.size(); ++i) {
    const Surface& s = lens.surfaces[i];
    if (s.is_stop || options.uncoated) continue;
    const double design = options.coating_override_nm > 0
                              ? options.coating_override_nm
                              : s.coating_nm.value_or(options.default_coating_nm);
    out[i].coated = true;
    out[i].coating_ior = n_c;
    out[i].thickness_nm = quarterWaveThickness_nm(design, n_c);
  }
  return out;
}

bool sameLensOptions(const FlareRenderOptions& a, const FlareRenderOptions& b) {
  // What prepareLensSetup reads, and surfaceCoatings.
  return a.focus_at_infinity == b.focus_at_infinity && a.f_number == b.f_number &&
         a.spectral_samples == b.spectral_samples && a.coating_ior == b.coating_ior &&
         a.default_coating_nm == b.default_coating_nm &&
         a.coating_override_nm == b.coating_override_nm && a.uncoated == b.uncoated;
}

RenderSetup prepareLensSetup(const Lens& lens, const FlareRenderOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError("render options: " + error);
  RenderSetup s;
  s.lens = options.focus_at_infinity ? focusAtInfinity(lens) : lens;
  if (options.f_number > 0) s.lens = stopDown(s.lens, options.f_number);
  s.coatings = surfaceCoatings(s.lens, options);
  s.samples = spectralSamples(options.spectral_samples);
  // The wavelengths' reflectance tables in parallel: thin-film reflectances of every surface at
  // 129 angles each, most of this function's 0.27 ms (Heliar, one thread), which the matrix
  // renderer waited for on one core.
  s.tables.resize(s.samples.size());
  tbb::parallel_for(size_t{0}, s.samples.size(), [&](size_t i) {
    s.tables[i] = ReflectanceTables(s.lens, s.coatings, s.samples[i].wavelength_nm);
  });
  return s;
}

RenderSetup prepareRender(const Lens& lens, const LightDirection& light,
                          const FlareRenderOptions& options) {
  RenderSetup s = prepareLensSetup(lens, options);
  aimSetup(s, light, options);
  return s;
}

void aimSetup(RenderSetup& s, const LightDirection& light, const FlareRenderOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError("render options: " + error);
  s.mapping.width_px = options.width_px;
  s.mapping.height_px = options.height_px;
  s.mapping.pixel_pitch_mm = std::min(options.sensor_width_mm / options.width_px,
                                      options.sensor_height_mm / options.height_px);
  s.mapping.axis_offset_px = options.optical_axis_offset_px;
  s.direction = lightDirection(light.angle_deg * M_PI / 180.0, light.roll_deg * M_PI / 180.0);
  s.light_irradiance = options.light_irradiance;
  s.aperture = Aperture(options.aperture);
  // Every ray that passes the first surface's rim crosses z = 0 within h0 + |tan θ|·|sag(h0)|.
  const Surface& first = s.lens.surfaces.front();
  const double h0 = first.semi_aperture_mm;
  const double sag = first.isFlat() ? 0.0
                                    : std::abs(first.radius_mm) -
                                          std::sqrt(first.radius_mm * first.radius_mm - h0 * h0);
  const double tan_t = std::hypot(s.direction[0], s.direction[1]) / std::max(1e-9, s.direction[2]);
  s.search_half_mm = 1.02 * (h0 + tan_t * sag);
}

std::optional<RayGrid> boundGhost(const RenderSetup& setup, const CompiledPath& path) {
  constexpr int kCoarse = 33;
  RayGrid coarse;
  coarse.half_size_mm = setup.search_half_mm;
  coarse.n = kCoarse;
  TracedRays rays;
  traceGrid(path, setup.direction, coarse, &rays, /*passing_only=*/true);
  int i0 = kCoarse, i1 = -1, j0 = kCoarse, j1 = -1;
  for (int j = 0; j < kCoarse; ++j)
    for (int i = 0; i < kCoarse; ++i) {
      const size_t k = static_cast<size_t>(j * kCoarse + i);
      if (!rays.alive[k] || rays.r_rel[k] > 1.0f ||
          rays.u[k] * rays.u[k] + rays.v[k] * rays.v[k] > 1.0f)
        continue;
      i0 = std::min(i0, i);
      i1 = std::max(i1, i);
      j0 = std::min(j0, j);
      j1 = std::max(j1, j);
    }
  if (i1 < 0) return std::nullopt;
  const double h = coarse.spacing_mm();
  const double x0 = -coarse.half_size_mm + (i0 - 1) * h, x1 = -coarse.half_size_mm + (i1 + 1) * h;
  const double y0 = -coarse.half_size_mm + (j0 - 1) * h, y1 = -coarse.half_size_mm + (j1 + 1) * h;
  RayGrid box;
  box.center_x_mm = 0.5 * (x0 + x1);
  box.center_y_mm = 0.5 * (y0 + y1);
  box.half_size_mm = 0.5 * std::max(x1 - x0, y1 - y0);
  return box;
}

long long traceGhostTriangles(const RenderSetup& setup, const Ghost& ghost, int sample, int n,
                              int batch, std::vector<RasterTriangle>* out) {
  const SpectralSample& s = setup.samples[static_cast<size_t>(sample)];
  const CompiledPath path = compilePath(setup.lens, ghostPath(setup.lens, ghost.surface_a, ghost.surface_b),
                                        s.wavelength_nm, setup.tables[static_cast<size_t>(sample)]);
  const auto box = boundGhost(setup, path);
  if (!box) return 33LL * 33;
  RayGrid grid = *box;
  grid.n = n;
  TracedRays rays;
  traceGridCorners(path, setup.direction, grid, &rays);
  const double cell = grid.spacing_mm();
  const double cell_flux = cell * cell * std::abs(setup.direction[2]) * setup.light_irradiance;
  long long traced = 33LL * 33 + static_cast<long long>(n) * n;
  buildRefinedTriangles(setup, path, s.rgb_weight, batch, grid, rays, cell_flux, &traced, out);
  return traced;
}

void splatGhost(const RenderSetup& setup, const Ghost& ghost, int sample, int n, cv::Mat* image) {
  const SpectralSample& s = setup.samples[static_cast<size_t>(sample)];
  const CompiledPath path = compilePath(setup.lens, ghostPath(setup.lens, ghost.surface_a, ghost.surface_b),
                                        s.wavelength_nm, setup.tables[static_cast<size_t>(sample)]);
  auto box = boundGhost(setup, path);
  if (!box) return;
  RayGrid grid = *box;
  grid.half_size_mm *= 1.1;
  grid.n = n;
  const double h = grid.spacing_mm();
  const double pitch2 = setup.mapping.pixel_pitch_mm * setup.mapping.pixel_pitch_mm;
  const double cell_flux = h * h * std::abs(setup.direction[2]) * setup.light_irradiance;
  tbb::enumerable_thread_specific<cv::Mat> local([&] {
    return cv::Mat(image->size(), CV_32FC3, cv::Scalar::all(0));
  });
  tbb::parallel_for(0, n, [&](int j) {
    cv::Mat& img = local.local();
    std::vector<double> xs(static_cast<size_t>(n)), ys(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      xs[static_cast<size_t>(i)] = grid.center_x_mm - grid.half_size_mm + i * h;
      ys[static_cast<size_t>(i)] = grid.center_y_mm - grid.half_size_mm + j * h;
    }
    TracedRays rays;
    rays.resize(n);
    traceRays(path, setup.direction, xs.data(), ys.data(), n, &rays);
    for (int i = 0; i < n; ++i) {
      const size_t k = static_cast<size_t>(i);
      if (!rays.alive[k] || rays.r_rel[k] > 1.0f) continue;
      const float a = setup.aperture.transmission(rays.u[k], rays.v[k]);
      if (a <= 0) continue;
      const double px = setup.mapping.toPixelX(rays.x_mm[k]);
      const double py = setup.mapping.toPixelY(rays.y_mm[k]);
      if (!(px >= 0 && py >= 0 && px < img.cols && py < img.rows)) continue;
      const float value = static_cast<float>(cell_flux * rays.transmission[k] * a / pitch2);
      img.at<cv::Vec3f>(static_cast<int>(py), static_cast<int>(px)) += s.rgb_weight * value;
    }
  });
  for (const cv::Mat& m : local) *image += m;
}

DirectLight traceDirectLight(const RenderSetup& setup, int sample, int n) {
  const SpectralSample& s = setup.samples[static_cast<size_t>(sample)];
  const CompiledPath path = compilePath(setup.lens, directPath(setup.lens), s.wavelength_nm,
                                        setup.tables[static_cast<size_t>(sample)]);
  DirectLight out;
  const auto box = boundGhost(setup, path);
  if (!box) return out;
  RayGrid grid = *box;
  grid.n = n;
  TracedRays rays;
  traceGrid(path, setup.direction, grid, &rays);
  const double h = grid.spacing_mm();
  const double cell_flux = h * h * std::abs(setup.direction[2]) * setup.light_irradiance;
  double sx = 0, sy = 0;
  for (size_t k = 0; k < rays.alive.size(); ++k) {
    if (!rays.alive[k] || rays.r_rel[k] > 1.0f) continue;
    const double f = cell_flux * rays.transmission[k] * setup.aperture.transmission(rays.u[k], rays.v[k]);
    out.flux += f;
    sx += f * rays.x_mm[k];
    sy += f * rays.y_mm[k];
  }
  if (out.flux > 0) {
    out.center_px = {setup.mapping.toPixelX(sx / out.flux), setup.mapping.toPixelY(sy / out.flux)};
    out.valid = true;
  }
  return out;
}

double pathTransmissionAtNormal(const RenderSetup& setup, const std::vector<PathEvent>& path,
                                double wavelength_nm) {
  double t = 1.0;
  for (const PathEvent& e : path) {
    if (e.kind == EventKind::kStop) continue;
    const double n1 = setup.lens.refractiveIndex(e.medium_before, wavelength_nm);
    const Surface& s = setup.lens.surfaces[static_cast<size_t>(e.surface)];
    (void)s;
    const int other = e.forward ? e.surface : e.surface - 1;
    const double n2 = setup.lens.refractiveIndex(e.kind == EventKind::kReflect ? other : e.medium_after,
                                                 wavelength_nm);
    const double r = setup.coatings[static_cast<size_t>(e.surface)].reflectance(n1, n2, wavelength_nm, 1.0);
    t *= e.kind == EventKind::kReflect ? r : 1.0 - r;
  }
  return t;
}

double ghostIntensityEstimate(const RenderSetup& setup, const Ghost& ghost) {
  const auto path = ghostPath(setup.lens, ghost.surface_a, ghost.surface_b);
  const ParaxialGhost pg = paraxialGhost(setup.lens, path, 550.0);
  const double t = pathTransmissionAtNormal(setup, path, 550.0);
  if (!pg.valid) return 0.0;
  // A ghost no smaller than one pixel: |A| · pupil radius ≥ pitch.
  const double cap = std::pow(pg.pupil_radius_mm / setup.mapping.pixel_pitch_mm, 2.0);
  return t * std::min(pg.area_gain, cap);
}

namespace {

// One wavelength's paraxial sprite of one ghost.
struct Sprite {
  double cx, cy, m;  // centre (px) and signed pixels per aperture unit
  float value;       // irradiance inside
  cv::Vec3f weight;  // colour weight
};

std::vector<Sprite> ghostSprites(const RenderSetup& setup, const Ghost& ghost) {
  const auto path = ghostPath(setup.lens, ghost.surface_a, ghost.surface_b);
  const double wx = setup.direction[0] / setup.direction[2], wy = setup.direction[1] / setup.direction[2];
  const double pitch = setup.mapping.pixel_pitch_mm;
  const double stop = setup.lens.stopSemiAperture_mm();
  std::vector<Sprite> sprites;
  for (const SpectralSample& s : setup.samples) {
    const ParaxialGhost pg = paraxialGhost(setup.lens, path, s.wavelength_nm);
    if (!pg.valid || pg.magnification == 0.0) continue;
    Sprite sp;
    sp.cx = setup.mapping.toPixelX(pg.center_per_slope_mm * wx);
    sp.cy = setup.mapping.toPixelY(pg.center_per_slope_mm * wy);
    sp.m = pg.magnification * stop / pitch;
    if (std::abs(sp.m) < 0.5) sp.m = sp.m < 0 ? -0.5 : 0.5;  // at least a pixel across
    // Lee & Eisemann §3.2: irradiance = T · cos θ · (pupil area / ghost area) = T cos θ / A²,
    // with A = A1 · magnification, A1 = stop / pupil radius, magnification = m · pitch / stop.
    const double area_gain = std::pow(pg.pupil_radius_mm / (sp.m * pitch), 2.0);
    sp.value = static_cast<float>(pathTransmissionAtNormal(setup, path, s.wavelength_nm) *
                                  std::abs(setup.direction[2]) * setup.light_irradiance * area_gain);
    sp.weight = s.rgb_weight;
    sprites.push_back(sp);
  }
  return sprites;
}

// A step of a row's flat spans at pixel x: RGB and the span count, up at a span's start and down
// past its end.
struct SpanStep {
  int x;
  double delta[4];
};

// Adds the sprites' pixels on row y. Inside the iris's inscribed circle (less half a pixel) the
// sprite is flat: its constant goes into `steps` as a step up at the span's start and down past
// its end, for the caller to integrate once for all sprites (many sprites cover the whole frame,
// which would otherwise cost a pass over it each); only the rim band evaluates the aperture.
// Returns whether it added a step.
bool addSpriteRow(const Sprite& sp, const Aperture& aperture, int y, cv::Mat* image,
                  std::vector<SpanStep>* steps) {
  const double r = std::abs(sp.m);
  const double dy = y + 0.5 - sp.cy;
  if (std::abs(dy) > r + 1.0) return false;
  const double half = std::sqrt(std::max(0.0, (r + 1.0) * (r + 1.0) - dy * dy));
  const int x0 = std::max(0, static_cast<int>(std::floor(sp.cx - half)));
  const int x1 = std::min(image->cols - 1, static_cast<int>(std::ceil(sp.cx + half)));
  if (x0 > x1) return false;
  // Inner flat span: radius (apothem − half a pixel) in aperture units, for polygons and circles.
  double inner = -1.0;
  if (aperture.hasDistance()) {
    const double apothem = aperture.shape().kind == ApertureKind::kCircle ? 1.0 : aperture.apothem();
    const double rin = (apothem - 0.5 / r) * r;  // pixels
    if (rin > 0 && std::abs(dy) < rin) inner = std::sqrt(rin * rin - dy * dy);
  }
  int i0 = x1 + 1, i1 = x1;  // flat span [i0, i1]
  if (inner > 0) {
    i0 = std::max(x0, static_cast<int>(std::ceil(sp.cx - inner - 0.5)));
    i1 = std::min(x1, static_cast<int>(std::floor(sp.cx + inner - 0.5)));
  }
  // A straight-bladed polygon is flat over more than its inscribed circle (a hexagon's corners
  // reach 15 % further): the row's chord of the polygon shrunk by half a pixel, each blade's
  // half-plane solved for u, less a pixel on each side for rounding, where the coverage is 1.
  if (aperture.shape().kind == ApertureKind::kPolygon && aperture.rounding() == 0.0f) {
    const double v = dy / sp.m;
    const double limit = aperture.apothem() - 0.5 / r;
    double u_lo = -1e30, u_hi = 1e30;
    for (int k = 0; k < aperture.edgeCount(); ++k) {
      const double nx = aperture.edgeNormalX(k), ny = aperture.edgeNormalY(k);
      const double bound = limit - v * ny;  // u·nx ≤ bound
      if (nx > 1e-9)
        u_hi = std::min(u_hi, bound / nx);
      else if (nx < -1e-9)
        u_lo = std::max(u_lo, bound / nx);
      else if (bound < 0.0)
        u_hi = -1e30;
    }
    if (u_lo < u_hi) {
      // x + 0.5 = cx + u·m; m < 0 mirrors the interval.
      const double xa = sp.cx + u_lo * sp.m - 0.5, xb = sp.cx + u_hi * sp.m - 0.5;
      const int p0 = std::max(x0, static_cast<int>(std::ceil(std::min(xa, xb))) + 1);
      const int p1 = std::min(x1, static_cast<int>(std::floor(std::max(xa, xb))) - 1);
      if (p0 <= p1 && (i0 > i1 || p1 - p0 > i1 - i0)) {
        i0 = p0;
        i1 = p1;
      }
    }
  }
  // The rim band's pixels worth evaluating, [e0, e1]: for a straight-bladed polygon, the row's
  // chord of the polygon grown by half a pixel (beyond it the coverage is 0: a large hexagonal
  // sprite's circle of radius r + 1 reaches 13 % of r past its sides), a pixel wider on each side
  // for rounding. Pixels outside it would add nothing.
  int e0 = x0, e1 = x1;
  if (aperture.shape().kind == ApertureKind::kPolygon && aperture.rounding() == 0.0f) {
    const double v = dy / sp.m;
    const double limit = aperture.apothem() + 0.5 / r;
    double u_lo = -1e30, u_hi = 1e30;
    for (int k = 0; k < aperture.edgeCount(); ++k) {
      const double nx = aperture.edgeNormalX(k), ny = aperture.edgeNormalY(k);
      const double bound = limit - v * ny;  // u·nx < bound inside
      if (nx > 1e-9)
        u_hi = std::min(u_hi, bound / nx);
      else if (nx < -1e-9)
        u_lo = std::max(u_lo, bound / nx);
      else if (bound < -1e-6)
        u_hi = -1e30;
    }
    if (u_lo < u_hi) {
      const double xa = sp.cx + u_lo * sp.m - 0.5, xb = sp.cx + u_hi * sp.m - 0.5;
      const double lo = std::clamp(std::min(xa, xb), x0 - 2.0, x1 + 2.0);
      const double hi = std::clamp(std::max(xa, xb), x0 - 2.0, x1 + 2.0);
      e0 = std::max(x0, static_cast<int>(std::floor(lo)) - 1);
      e1 = std::min(x1, static_cast<int>(std::ceil(hi)) + 1);
    } else {
      e0 = x1 + 1;  // the row misses the polygon (and its flat span is empty)
    }
  }
  auto* row = image->ptr<cv::Vec3f>(y);
  const cv::Vec3f flat = sp.weight * sp.value;
  const float footprint = static_cast<float>(1.0 / r);
  auto edge = [&](int x) {
    const float u = static_cast<float>((x + 0.5 - sp.cx) / sp.m);
    const float v = static_cast<float>(dy / sp.m);
    const float a = aperture.coverage(u, v, footprint);
    if (a > 0) row[x] += sp.weight * (sp.value * a);
  };
  if (i0 > i1) {
    for (int x = e0; x <= e1; ++x) edge(x);
    return false;
  }
  for (int x = e0; x < std::min(i0, e1 + 1); ++x) edge(x);
  steps->push_back({i0, {flat[0], flat[1], flat[2], 1.0}});
  steps->push_back({i1 + 1, {-static_cast<double>(flat[0]), -static_cast<double>(flat[1]),
                             -static_cast<double>(flat[2]), -1.0}});
  for (int x = std::max(i1 + 1, e0); x <= e1; ++x) edge(x);
  return true;
}

}  // namespace

void addMatrixSprite(const RenderSetup& setup, const Ghost& ghost, cv::Mat* image) {
  addMatrixSprites(setup, {ghost}, image);
}

void addMatrixSprites(const RenderSetup& setup, const std::vector<Ghost>& ghosts, cv::Mat* image,
                      bool zero_first) {
  // Each ghost's sprites in parallel (paraxial matrices and coatings per wavelength: a fifth of
  // the frame on one thread), kept in ghost order.
  std::vector<std::vector<Sprite>> per_ghost(ghosts.size());
  tbb::parallel_for(size_t{0}, ghosts.size(), [&](size_t i) { per_ghost[i] = ghostSprites(setup, ghosts[i]); });
  std::vector<Sprite> sprites;
  for (const auto& list : per_ghost) sprites.insert(sprites.end(), list.begin(), list.end());
  // Rows in parallel: each row sums every sprite that crosses it, the flat spans integrated from
  // their steps in one pass, in double; where no span is open the sum restarts from exactly 0, so
  // rounding leaves nothing behind a bright span. Between two steps the sum is constant: it is
  // added to the run of pixels as it stands (a few hundred steps a row instead of a pass over
  // every pixel in double). The steps at one pixel are combined in the order the sprites made
  // them, then added to the sum, as a per-pixel step array would.
  const int cols = image->cols;
  tbb::parallel_for(tbb::blocked_range<int>(0, image->rows, 8), [&](const tbb::blocked_range<int>& rows) {
    std::vector<SpanStep> steps;
    // The steps in order of x, those at one x in the order they were made: a counting sort by x
    // (0 ≤ x ≤ cols). std::stable_sort of the 40-byte steps, with its buffer allocated per row,
    // was 12 % of a Heliar matrix frame.
    std::vector<int> first(static_cast<size_t>(cols) + 2);
    std::vector<SpanStep> sorted;
    for (int y = rows.begin(); y < rows.end(); ++y) {
      if (zero_first) std::fill_n(image->ptr<float>(y), 3 * static_cast<size_t>(cols), 0.0f);
      steps.clear();
      for (const Sprite& s : sprites) addSpriteRow(s, setup.aperture, y, image, &steps);
      if (steps.empty()) continue;
      std::fill(first.begin(), first.end(), 0);
      for (const SpanStep& st : steps) ++first[static_cast<size_t>(st.x) + 1];
      for (size_t x = 1; x < first.size(); ++x) first[x] += first[x - 1];
      sorted.resize(steps.size());
      for (const SpanStep& st : steps) sorted[static_cast<size_t>(first[static_cast<size_t>(st.x)]++)] = st;
      float* row = image->ptr<float>(y);
      double sum[4] = {0.0, 0.0, 0.0, 0.0};
      for (size_t k = 0; k < steps.size();) {
        const int x = sorted[k].x;
        double combined[4] = {0.0, 0.0, 0.0, 0.0};
        for (; k < steps.size() && sorted[k].x == x; ++k)
          for (int c = 0; c < 4; ++c) combined[c] += sorted[k].delta[c];
        for (int c = 0; c < 4; ++c) sum[c] += combined[c];
        if (sum[3] < 0.5) {  // no span open (the count is an exact small integer)
          sum[0] = sum[1] = sum[2] = 0.0;
          continue;
        }
        const int end = std::min(cols, k < steps.size() ? sorted[k].x : cols);
        const float r = static_cast<float>(sum[0]), g = static_cast<float>(sum[1]),
                    b = static_cast<float>(sum[2]);
        for (int p = x; p < end; ++p) {
          row[3 * p] += r;
          row[3 * p + 1] += g;
          row[3 * p + 2] += b;
        }
      }
    }
  });
}

}  // namespace flarekit::render
