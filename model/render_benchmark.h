#pragma once
// The measurement behind `flarekit bench model` (issue 4's performance targets): a reproducible set
// of random ghosts rendered over a full frame, with and without derivative images.

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "model/ghost_shape.h"
#include "model/model_renderer.h"

namespace flarekit::model {

struct RenderBenchmarkOptions {
  int ghosts = 100;        // number of ghosts
  int width = 1280;        // frame width, pixels
  int height = 720;        // frame height, pixels
  int channels = 1;        // 1 (grey) or 3 (RGB)
  double min_radius = 20;  // ghost radius range, pixels (L, R, h vary ±15 % around it)
  double max_radius = 80;
  int repeats = 7;         // timed runs per measurement; the median is reported (≥ 1)
  int threads = 0;         // TBB threads; 0 = TBB's default (all cores)
  unsigned seed = 1;       // random ghost set

  bool IsValid(std::string* error) const;
};

// The ghost set the benchmark renders: centres uniform over the frame, radius r uniform in
// [min_radius, max_radius] with L, R, h = r·U(0.85, 1.15), Cl, Cr = U(0.35, 0.75),
// Fi = r·U(0.1, 0.35), Fo = U(1.5, 6) px, Ei, Eo = U(0.7, 2.5), Ib = U(0.5, 2), Ii = U(0, 0.5).
std::vector<GhostParameters> benchmarkGhosts(const RenderBenchmarkOptions& options);

struct RenderBenchmarkResult {
  int ghosts = 0, width = 0, height = 0, channels = 0, threads = 0, repeats = 0;
  double ms_render = 0;                    // all ghosts, full frame (median wall-clock time)
  double ms_render_with_derivatives = 0;   // all ghosts, full frame, every derivative image
  // CPU time of the whole process per run (all threads; mean over the timed runs): what the work
  // costs regardless of other load on the machine. On an idle machine with N cores the wall-clock
  // time approaches cpu_ms / N.
  double cpu_ms_render = 0;
  double cpu_ms_render_with_derivatives = 0;
  double pixels_per_s = 0;                 // frame pixels per second of ms_render
  double ghost_pixels = 0;                 // Σ pixels within the ghosts' reach, clipped to the frame
  double ghost_pixels_per_s = 0;           // ghost_pixels per second of ms_render
  double ms_one_ghost = 0;                 // Σ over ghosts of rendering each alone, per ghost
  double ms_one_ghost_with_derivatives = 0;
  double derivative_cost_ratio = 0;        // ms_one_ghost_with_derivatives / ms_one_ghost

  std::string BriefReport() const;
};

RenderBenchmarkResult runRenderBenchmark(const RenderBenchmarkOptions& options);
nlohmann::json toJson(const RenderBenchmarkResult& result);

}  // namespace flarekit::model
