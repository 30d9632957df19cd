#include "model/render_benchmark.h"

#include <algorithm>
#include <chrono>
#include <ctime>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>
#include <tbb/global_control.h>
#include <tbb/info.h>

namespace flarekit::model {
namespace {

double processCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

template <typename F>
double medianMs(int repeats, F&& run) {
  std::vector<double> ms;
  for (int i = 0; i < repeats; ++i) {
    const auto start = std::chrono::steady_clock::now();
    run();
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

}  // namespace

bool RenderBenchmarkOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (ghosts < 1 || ghosts > 100000) return fail("ghosts must be in [1, 100000]");
  if (width < 1 || height < 1 || width > 20000 || height > 20000)
    return fail("width and height must be in [1, 20000]");
  if (channels != 1 && channels != 3) return fail("channels must be 1 or 3");
  if (!(min_radius >= 1) || !(max_radius >= min_radius) || max_radius > 5000)
    return fail("radii must satisfy 1 <= min_radius <= max_radius <= 5000");
  if (repeats < 1 || repeats > 1000) return fail("repeats must be in [1, 1000]");
  if (threads < 0 || threads > 1024) return fail("threads must be in [0, 1024]");
  return true;
}

std::vector<GhostParameters> benchmarkGhosts(const RenderBenchmarkOptions& o) {
  std::mt19937 rng(o.seed);
  auto uniform = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  std::vector<GhostParameters> ghosts;
  for (int i = 0; i < o.ghosts; ++i) {
    GhostParameters g;
    g.channels = o.channels;
    const double r = uniform(o.min_radius, o.max_radius);
    g.center_x = uniform(0, o.width);
    g.center_y = uniform(0, o.height);
    g.left = r * uniform(0.85, 1.15);
    g.right = r * uniform(0.85, 1.15);
    g.height = r * uniform(0.85, 1.15);
    g.curvature_left = uniform(0.35, 0.75);
    g.curvature_right = uniform(0.35, 0.75);
    for (int c = 0; c < 3; ++c) {
      g.border[c] = c < o.channels ? uniform(0.5, 2) : 0;
      g.inside[c] = c < o.channels ? uniform(0, 0.5) : 0;
    }
    g.inside_falloff = r * uniform(0.1, 0.35);
    g.outside_falloff = uniform(1.5, 6);
    g.inside_exponent = uniform(0.7, 2.5);
    g.outside_exponent = uniform(0.7, 2.5);
    ghosts.push_back(g);
  }
  return ghosts;
}

RenderBenchmarkResult runRenderBenchmark(const RenderBenchmarkOptions& o) {
  std::string error;
  if (!o.IsValid(&error)) throw std::invalid_argument("benchmark options: " + error);
  std::optional<tbb::global_control> limit;
  if (o.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, o.threads);
  const std::vector<GhostParameters> ghosts = benchmarkGhosts(o);
  const cv::Size size(o.width, o.height);
  const cv::Rect frame(0, 0, o.width, o.height);

  RenderBenchmarkResult r;
  r.ghosts = o.ghosts;
  r.width = o.width;
  r.height = o.height;
  r.channels = o.channels;
  r.repeats = o.repeats;
  r.threads = static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
  r.threads = std::min(r.threads, tbb::info::default_concurrency());

  renderGhosts(ghosts, size, o.channels);  // warm-up
  double cpu = processCpuMs();
  r.ms_render = medianMs(o.repeats, [&] { renderGhosts(ghosts, size, o.channels); });
  r.cpu_ms_render = (processCpuMs() - cpu) / o.repeats;
  cpu = processCpuMs();
  r.ms_render_with_derivatives =
      medianMs(o.repeats, [&] { renderGhostsWithDerivatives(ghosts, frame, o.channels); });
  r.cpu_ms_render_with_derivatives = (processCpuMs() - cpu) / o.repeats;
  r.pixels_per_s = static_cast<double>(o.width) * o.height / (r.ms_render / 1000);
  for (const auto& g : ghosts) r.ghost_pixels += (ghostPixelBounds(g) & frame).area();
  r.ghost_pixels_per_s = r.ghost_pixels / (r.ms_render / 1000);

  // One ghost at a time, over its own region (how a fitter calls the renderer).
  double plain = 0, with = 0;
  for (const auto& g : ghosts) {
    const std::vector<GhostParameters> one = {g};
    const cv::Rect roi = ghostPixelBounds(g) & frame;
    if (roi.area() <= 0) continue;
    plain += medianMs(o.repeats, [&] { renderGhosts(one, roi, o.channels); });
    with += medianMs(o.repeats, [&] { renderGhostsWithDerivatives(one, roi, o.channels); });
  }
  r.ms_one_ghost = plain / o.ghosts;
  r.ms_one_ghost_with_derivatives = with / o.ghosts;
  r.derivative_cost_ratio = plain > 0 ? with / plain : 0;
  return r;
}

std::string RenderBenchmarkResult::BriefReport() const {
  std::ostringstream s;
  s.precision(4);
  s << ghosts << " ghosts at " << width << "x" << height << " (" << channels << " channel"
    << (channels > 1 ? "s" : "") << ", " << threads << " threads): " << ms_render << " ms per frame, "
    << ms_render_with_derivatives << " ms with all derivative images (CPU " << cpu_ms_render << " and "
    << cpu_ms_render_with_derivatives << " ms over all threads); one ghost " << ms_one_ghost
    << " ms, with derivatives " << ms_one_ghost_with_derivatives << " ms (" << derivative_cost_ratio
    << "x).";
  return s.str();
}

nlohmann::json toJson(const RenderBenchmarkResult& r) {
  return {{"ghosts", r.ghosts},
          {"width", r.width},
          {"height", r.height},
          {"channels", r.channels},
          {"threads", r.threads},
          {"repeats", r.repeats},
          {"ms_render", r.ms_render},
          {"ms_render_with_derivatives", r.ms_render_with_derivatives},
          {"cpu_ms_render", r.cpu_ms_render},
          {"cpu_ms_render_with_derivatives", r.cpu_ms_render_with_derivatives},
          {"pixels_per_s", r.pixels_per_s},
          {"ghost_pixels", r.ghost_pixels},
          {"ghost_pixels_per_s", r.ghost_pixels_per_s},
          {"ms_one_ghost", r.ms_one_ghost},
          {"ms_one_ghost_with_derivatives", r.ms_one_ghost_with_derivatives},
          {"derivative_cost_ratio", r.derivative_cost_ratio}};
}

}  // namespace flarekit::model
