#include "render/flare_renderer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <sstream>

#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include "common/error.h"
#include "render/ghost_render.h"
#include "render/starburst.h"

namespace flarekit::render {
namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

const char* methodName(RenderMethod m) {
  switch (m) {
    case RenderMethod::kTiled: return "tiled";
    case RenderMethod::kPerGhost: return "per-ghost";
    case RenderMethod::kMatrix: return "matrix";
  }
  return "?";
}

// Luminance-weighted statistics of one ghost's image.
void measureGhost(const cv::Mat& image, GhostRecord* g) {
  double sum = 0, sx = 0, sy = 0, peak = 0;
  for (int y = 0; y < image.rows; ++y) {
    const auto* row = image.ptr<cv::Vec3f>(y);
    for (int x = 0; x < image.cols; ++x) {
      const double l = 0.2126 * row[x][0] + 0.7152 * row[x][1] + 0.0722 * row[x][2];
      if (l <= 0) continue;
      sum += l;
      sx += l * (x + 0.5);
      sy += l * (y + 0.5);
      peak = std::max(peak, l);
    }
  }
  g->energy = sum;
  if (sum <= 0) return;
  g->centroid_px = {sx / sum, sy / sum};
  int x0 = image.cols, y0 = image.rows, x1 = -1, y1 = -1;
  const double threshold = 1e-4 * peak;
  for (int y = 0; y < image.rows; ++y) {
    const auto* row = image.ptr<cv::Vec3f>(y);
    for (int x = 0; x < image.cols; ++x) {
      const double l = 0.2126 * row[x][0] + 0.7152 * row[x][1] + 0.0722 * row[x][2];
      if (l <= threshold) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
  }
  if (x1 >= 0) g->bbox_px = cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1);
}

// Makes *image a CV_32FC3 image of rows × cols, in its own pixels when it already has that shape
// and no other cv::Mat shares them (a reused frame costs no page faults: 11 MB at 1280×720), else
// in new ones. Zeroed unless `zero` is false (then for a renderer that writes every pixel).
void reuseImage(int rows, int cols, bool zero, cv::Mat* image) {
  const bool reusable = image->rows == rows && image->cols == cols && image->type() == CV_32FC3 &&
                        image->isContinuous() && image->u != nullptr && image->u->refcount == 1;
  if (!reusable) *image = cv::Mat(rows, cols, CV_32FC3);
  if (zero) image->setTo(cv::Scalar::all(0));
}

}  // namespace

bool FlareRenderOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (width_px < 1 || height_px < 1 || width_px > 16384 || height_px > 16384)
    return fail("image size must be 1..16384 pixels per side");
  if (!(sensor_width_mm > 0 && sensor_height_mm > 0 && std::isfinite(sensor_width_mm) &&
        std::isfinite(sensor_height_mm)))
    return fail("sensor size must be positive");
  if (!(std::abs(optical_axis_offset_px.x) <= width_px &&
        std::abs(optical_axis_offset_px.y) <= height_px))
    return fail("optical axis offset must be finite and at most the image size per axis");
  if (!(f_number >= 0 && std::isfinite(f_number))) return fail("f-number must be ≥ 0 (0 = the lens's own)");
  if (spectral_samples != 0 && (spectral_samples < 3 || spectral_samples > 200))
    return fail("wavelengths must be rgb (0) or 3..200 spectral samples");
  if (grid_size < 2 || grid_size > 4096) return fail("grid size must be 2..4096 rays per side");
  if (max_ghosts < 0) return fail("max ghosts must be ≥ 0 (0 = all)");
  if (!(min_relative_intensity >= 0 && min_relative_intensity <= 1))
    return fail("minimum relative intensity must be in [0, 1]");
  if (!(coating_ior == 0 || (coating_ior >= 1 && std::isfinite(coating_ior))))
    return fail("coating index must be 0 (file's) or ≥ 1");
  if (!(default_coating_nm > 0 && default_coating_nm < 10000)) return fail("default coating wavelength must be in (0, 10000) nm");
  if (!(coating_override_nm >= 0 && coating_override_nm < 10000)) return fail("coating override must be in [0, 10000) nm");
  if (!(starburst_radius_px >= 0 && std::isfinite(starburst_radius_px))) return fail("starburst radius must be ≥ 0");
  if (!(halo_fraction >= 0 && halo_fraction <= 1)) return fail("halo fraction must be in [0, 1]");
  if (!(light_irradiance >= 0 && std::isfinite(light_irradiance))) return fail("light irradiance must be ≥ 0");
  std::string aperture_error;
  if (!aperture.IsValid(&aperture_error)) return fail(aperture_error);
  return true;
}

std::string RenderSummary::BriefReport() const {
  std::ostringstream out;
  out.precision(3);
  out << "Rendered " << ghosts_rendered << " of " << ghosts_enumerated << " ghosts at "
      << wavelengths << " wavelengths (" << rays_traced << " rays) on " << threads
      << " threads in " << total_ms << " ms (trace " << trace_ms << " ms, raster " << raster_ms
      << " ms, light source " << source_ms << " ms).";
  return out.str();
}

// What a FlareRenderer keeps between renders.
struct FlareRenderer::Scratch {
  // Triangles of each (ghost, wavelength): cleared, not freed, so their capacity carries over.
  std::vector<std::vector<RasterTriangle>> batches;
  RasterScratch raster;  // the per-ghost rasterizer's buffers
  // The last render's lens, options and setup: its lens, coatings, wavelengths and reflectance
  // tables serve the next render of the same lens with the same lens options (prepareLensSetup).
  std::optional<Lens> lens;
  FlareRenderOptions lens_options;
  RenderSetup setup;
  // Each wavelength's starburst (starburstBand), kept while the iris and the wavelengths stay the
  // same: the bands' 5 nm copies took 76 ms of a 640×427 RGB render, on every frame of a capture.
  struct Starburst {
    ApertureShape shape;
    int spectral_samples = -1;
    std::vector<cv::Mat> bands;
    std::vector<double> scale_nm;
  } starburst;

  // The starburst bands of every wavelength sample, built when the kept ones do not fit (mask
  // irises always: a mask is compared by nothing cheaper than its pixels).
  const Starburst& starburstBands(const Aperture& aperture, int spectral_samples, int samples) {
    const ApertureShape& a = aperture.shape();
    const ApertureShape& b = starburst.shape;
    if (starburst.spectral_samples == spectral_samples && a.kind != ApertureKind::kMask &&
        a.kind == b.kind && a.blades == b.blades && a.rounding == b.rounding &&
        a.rotation_deg == b.rotation_deg)
      return starburst;
    const cv::Mat pattern = starburstPattern(aperture, 256);
    starburst.bands.assign(static_cast<size_t>(samples), cv::Mat());
    starburst.scale_nm.assign(static_cast<size_t>(samples), 0.0);
    tbb::parallel_for(0, samples, [&](int s) {
      const auto i = static_cast<size_t>(s);
      starburst.bands[i] = starburstBand(pattern, sampleBand(spectral_samples, s), &starburst.scale_nm[i]);
    });
    starburst.shape = a;
    starburst.spectral_samples = spectral_samples;
    return starburst;
  }
};

FlareRenderer::FlareRenderer() : scratch_(std::make_unique<Scratch>()) {}
FlareRenderer::~FlareRenderer() = default;
FlareRenderer::FlareRenderer(FlareRenderer&&) noexcept = default;
FlareRenderer& FlareRenderer::operator=(FlareRenderer&&) noexcept = default;

FlareImage renderFlare(const Lens& lens, const LightDirection& light,
                       const FlareRenderOptions& options) {
  FlareImage out;
  FlareRenderer().render(lens, light, options, &out);
  return out;
}

void FlareRenderer::render(const Lens& lens, const LightDirection& light,
                           const FlareRenderOptions& options, FlareImage* image) {
  const auto t_start = Clock::now();
  if (!std::isfinite(light.angle_deg) || !std::isfinite(light.roll_deg) ||
      std::abs(light.angle_deg) >= 89.0)
    throw InputError("light angle must be finite and below 89 degrees");
  if (!(scratch_->lens && *scratch_->lens == lens && sameLensOptions(scratch_->lens_options, options))) {
    scratch_->setup = prepareLensSetup(lens, options);
    scratch_->lens = lens;
    scratch_->lens_options = options;
  }
  aimSetup(scratch_->setup, light, options);
  const RenderSetup& setup = scratch_->setup;
  FlareImage& out = *image;
  // The matrix sprites and the tiled rasterizer write every pixel themselves (in parallel, in
  // cache); only the per-ghost rasterizer adds to a zeroed frame.
  const bool writes_all = options.method != RenderMethod::kPerGhost;
  reuseImage(options.height_px, options.width_px, /*zero=*/!writes_all, &out.radiance);
  out.light_image_px = {0, 0};
  out.attributes.clear();
  out.summary = RenderSummary{};
  RenderSummary& summary = out.summary;
  summary.threads = tbb::this_task_arena::max_concurrency();
  summary.wavelengths = static_cast<int>(setup.samples.size());

  // Ghosts: enumerate, cull by side of the stop, rank by the paraxial estimate, cut.
  std::vector<Ghost> ghosts = enumerateGhosts(setup.lens);
  summary.ghosts_enumerated = static_cast<int>(ghosts.size());
  if (options.same_side_of_stop_only)
    ghosts.erase(std::remove_if(ghosts.begin(), ghosts.end(), [](const Ghost& g) { return !g.same_side_of_stop; }),
                 ghosts.end());
  tbb::parallel_for(size_t{0}, ghosts.size(),
                    [&](size_t i) { ghosts[i].intensity_estimate = ghostIntensityEstimate(setup, ghosts[i]); });
  std::stable_sort(ghosts.begin(), ghosts.end(),
                   [](const Ghost& a, const Ghost& b) { return a.intensity_estimate > b.intensity_estimate; });
  if (!ghosts.empty() && options.min_relative_intensity > 0) {
    const double limit = options.min_relative_intensity * ghosts.front().intensity_estimate;
    ghosts.erase(std::remove_if(ghosts.begin(), ghosts.end(), [&](const Ghost& g) { return g.intensity_estimate < limit; }),
                 ghosts.end());
  }
  if (options.max_ghosts > 0 && static_cast<int>(ghosts.size()) > options.max_ghosts)
    ghosts.resize(static_cast<size_t>(options.max_ghosts));
  summary.ghosts_rendered = static_cast<int>(ghosts.size());
  const int ns = static_cast<int>(setup.samples.size());

  // The wavelengths' direct light (the light's own image and where it lands: a bound and a 48²
  // grid each, as long as the whole matrix render otherwise) is traced beside the ghosts, as tasks
  // that idle threads take up; it is used in wavelength order below.
  std::vector<DirectLight> direct(static_cast<size_t>(ns));
  tbb::task_group direct_tasks;
  for (int s = 0; s < ns; ++s)
    direct_tasks.run([&, s] { direct[static_cast<size_t>(s)] = traceDirectLight(setup, s); });

  std::vector<std::vector<RasterTriangle>>& batches = scratch_->batches;
  for (auto& b : batches) b.clear();
  if (options.method == RenderMethod::kMatrix) {
    const auto t0 = Clock::now();
    addMatrixSprites(setup, ghosts, &out.radiance, /*zero_first=*/true);
    summary.raster_ms = msSince(t0);
  } else {
    // Bundle tracing, one task per (ghost, wavelength); batch index = ghost · ns + sample.
    const auto t0 = Clock::now();
    batches.resize(ghosts.size() * static_cast<size_t>(ns));
    std::vector<long long> rays(batches.size(), 0);
    tbb::parallel_for(size_t{0}, batches.size(), [&](size_t b) {
      const Ghost& g = ghosts[b / static_cast<size_t>(ns)];
      const int sample = static_cast<int>(b % static_cast<size_t>(ns));
      rays[b] = traceGhostTriangles(setup, g, sample, options.grid_size, static_cast<int>(b), &batches[b]);
    });
    for (long long r : rays) summary.rays_traced += r;
    summary.trace_ms = msSince(t0);
    const auto t1 = Clock::now();
    if (options.method == RenderMethod::kTiled)
      rasterizeTiled(batches, setup.aperture, TileOptions{}, &out.radiance, /*overwrite=*/true);
    else
      rasterizePerGhost(batches, setup.aperture, &out.radiance, &scratch_->raster);
    summary.raster_ms = msSince(t1);
  }

  // Ghost records (and layers: each ghost's batches rasterized on their own). A record's layer is
  // kept for reuse; the rest starts afresh.
  out.ghosts.resize(ghosts.size());
  tbb::parallel_for(size_t{0}, ghosts.size(), [&](size_t i) {
    GhostRecord& r = out.ghosts[i];
    cv::Mat layer = std::move(r.image);
    r = GhostRecord{};
    r.id = ghosts[i].id;
    r.surface_a = ghosts[i].surface_a;
    r.surface_b = ghosts[i].surface_b;
    r.intensity_estimate = ghosts[i].intensity_estimate;
    if (!options.ghost_layers) return;
    r.image = std::move(layer);
    reuseImage(options.height_px, options.width_px, /*zero=*/true, &r.image);
    if (options.method == RenderMethod::kMatrix) {
      addMatrixSprite(setup, ghosts[i], &r.image);
    } else {
      std::vector<bool> keep(batches.size(), false);
      for (int s = 0; s < ns; ++s) keep[i * static_cast<size_t>(ns) + static_cast<size_t>(s)] = true;
      rasterizeBatches(batches, &keep, setup.aperture, &r.image);
    }
    measureGhost(r.image, &r);
  });

  // The light's own image: direct flux through the iris, spread by the starburst.
  const auto t2 = Clock::now();
  double cx = 0, cy = 0, wsum = 0;
  const double radius = options.starburst_radius_px > 0
                            ? options.starburst_radius_px
                            : std::hypot(options.width_px, options.height_px) / 8.0;
  const Scratch::Starburst* starburst =
      options.light_source && options.starburst
          ? &scratch_->starburstBands(setup.aperture, options.spectral_samples, ns)
          : nullptr;
  direct_tasks.wait();
  for (int s = 0; s < ns; ++s) {
    const DirectLight& d = direct[static_cast<size_t>(s)];
    if (!d.valid) continue;
    const double lum = std::max(1e-6, static_cast<double>(setup.samples[static_cast<size_t>(s)].rgb_weight[1]) + 1e-3);
    cx += lum * d.center_px.x;
    cy += lum * d.center_px.y;
    wsum += lum;
    if (!options.light_source) continue;
    const double pitch = setup.mapping.pixel_pitch_mm;
    const double flux_px = d.flux / (pitch * pitch);  // relative irradiance × pixels
    const cv::Vec3f& w = setup.samples[static_cast<size_t>(s)].rgb_weight;
    const double spot = flux_px * (1.0 - options.halo_fraction);
    const double lambda_scale = setup.samples[static_cast<size_t>(s)].wavelength_nm / 550.0;
    if (starburst) {
      addStarburst(starburst->bands[static_cast<size_t>(s)], d.center_px,
                   radius * starburst->scale_nm[static_cast<size_t>(s)] / 550.0, spot, w, &out.radiance);
    } else {
      const int x = static_cast<int>(std::floor(d.center_px.x)), y = static_cast<int>(std::floor(d.center_px.y));
      if (x >= 0 && y >= 0 && x < options.width_px && y < options.height_px)
        out.radiance.at<cv::Vec3f>(y, x) += w * static_cast<float>(spot);
    }
    if (options.halo_fraction > 0)
      addHalo(d.center_px, radius * 0.25 * lambda_scale, flux_px * options.halo_fraction, w, &out.radiance);
  }
  if (wsum > 0) {
    out.light_image_px = {cx / wsum, cy / wsum};
  } else {
    // No direct light reaches the sensor: place the light by the paraxial chief ray.
    const double f = paraxialProperties(setup.lens).efl_mm;
    out.light_image_px = {setup.mapping.toPixelX(f * setup.direction[0] / setup.direction[2]),
                          setup.mapping.toPixelY(f * setup.direction[1] / setup.direction[2])};
  }
  summary.source_ms = msSince(t2);

  // Metadata.
  const ParaxialProperties p = paraxialProperties(setup.lens);
  auto& a = out.attributes;
  a["flarekit.lens"] = lens.name;
  if (!lens.file.empty()) a["flarekit.lens_file"] = lens.file.string();
  a["flarekit.angle_deg"] = light.angle_deg;
  a["flarekit.roll_deg"] = light.roll_deg;
  a["flarekit.f_number"] = p.f_number;
  a["flarekit.focal_length_mm"] = p.efl_mm;
  a["flarekit.sensor_distance_mm"] = setup.lens.sensor_distance_mm;
  a["flarekit.method"] = std::string(methodName(options.method));
  std::vector<float> wl;
  for (const auto& s : setup.samples) wl.push_back(static_cast<float>(s.wavelength_nm));
  a["flarekit.wavelengths_nm"] = wl;
  a["flarekit.grid"] = options.grid_size;
  a["flarekit.pixel_pitch_mm"] = setup.mapping.pixel_pitch_mm;
  a["flarekit.sensor_mm"] = cv::Vec2d(options.sensor_width_mm, options.sensor_height_mm);
  if (options.optical_axis_offset_px != cv::Point2d(0, 0))
    a["flarekit.optical_axis_offset_px"] =
        cv::Vec2d(options.optical_axis_offset_px.x, options.optical_axis_offset_px.y);
  a["flarekit.light_image_px"] = cv::Vec2d(out.light_image_px.x, out.light_image_px.y);
  a["flarekit.ghosts"] = summary.ghosts_rendered;
  a["flarekit.radiometric_unit"] =
      std::string("relative sensor irradiance: E_sensor / E_in (incident irradiance at the entrance pupil)");
  summary.total_ms = msSince(t_start);
}

ExrImage toExrImage(const FlareImage& image) {
  ExrImage exr;
  exr.layers.push_back({"", image.radiance});
  exr.attributes = image.attributes;
  for (const GhostRecord& g : image.ghosts) {
    if (g.image.empty()) continue;
    const std::string name = "ghost." + std::to_string(g.id);
    exr.layers.push_back({name, g.image});
    const std::string key = "flarekit." + name + ".";
    exr.attributes[key + "surfaces"] = cv::Vec2i(g.surface_a, g.surface_b);
    exr.attributes[key + "centroid_px"] = cv::Vec2d(g.centroid_px.x, g.centroid_px.y);
    exr.attributes[key + "bbox_px"] = std::vector<float>{
        static_cast<float>(g.bbox_px.x), static_cast<float>(g.bbox_px.y),
        static_cast<float>(g.bbox_px.width), static_cast<float>(g.bbox_px.height)};
    exr.attributes[key + "energy"] = g.energy;
    exr.attributes[key + "intensity_estimate"] = g.intensity_estimate;
  }
  return exr;
}

}  // namespace flarekit::render
