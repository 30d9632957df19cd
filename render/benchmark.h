#pragma once
// `flarekit bench render`: times the three rendering methods on one lens (median of repeated
// renders of the ghosts only — no light source — at one light angle, each method rendering its
// frames with one FlareRenderer into one reused FlareImage, as a capture sequence does).

#include <string>

#include <nlohmann/json.hpp>

#include "render/flare_renderer.h"

namespace flarekit::render {

struct RenderBenchmarkOptions {
  int width_px = 1280;        // image size
  int height_px = 720;
  int grid_size = 64;         // rays per side per ghost and wavelength
  int spectral_samples = 0;   // 0 = RGB
  double angle_deg = 10.0;    // light angle
  int repetitions = 5;        // renders per method; the median is reported
  bool IsValid(std::string* error) const;
};

struct RenderBenchmarkResult {
  std::string lens;
  int ghosts = 0;
  int width_px = 0, height_px = 0, grid_size = 0, wavelengths = 0, threads = 0;
  double ms_tiled = 0, ms_per_ghost = 0, ms_matrix = 0;  // median total render times
  double ms_trace = 0;           // median ray-tracing part of the tiled render
  double ms_tiled_raster = 0, ms_per_ghost_raster = 0;   // median rasterization parts
  double rays_per_s = 0;         // rays traced per second in the tracing part
  nlohmann::json toJson() const;
};

RenderBenchmarkResult benchmarkRender(const Lens& lens, const RenderBenchmarkOptions& options);

}  // namespace flarekit::render
