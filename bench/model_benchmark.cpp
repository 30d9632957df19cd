// Google Benchmark programs for the ghost model (issue 4): frame renders over ghost counts and
// sizes, derivative images, and the nearest-point searches (samples + Newton vs the paper's
// 12-step bisection). `flarekit bench model` prints the figures as one JSON object.
#include <benchmark/benchmark.h>

#include <random>

#include "model/model_renderer.h"
#include "model/render_benchmark.h"
#include "model/signed_distance.h"

namespace flarekit::model {
namespace {

// Args: ghosts, width, height.
void BM_RenderFrame(benchmark::State& state) {
  RenderBenchmarkOptions o;
  o.ghosts = static_cast<int>(state.range(0));
  o.width = static_cast<int>(state.range(1));
  o.height = static_cast<int>(state.range(2));
  const auto ghosts = benchmarkGhosts(o);
  for (auto _ : state) benchmark::DoNotOptimize(renderGhosts(ghosts, cv::Size(o.width, o.height), 1));
  state.counters["pixels_per_s"] =
      benchmark::Counter(static_cast<double>(o.width) * o.height, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_RenderFrame)->Args({10, 1280, 720})->Args({100, 1280, 720})->Args({100, 640, 360})->Args({300, 1920, 1080})->Unit(benchmark::kMillisecond);

void BM_RenderFrameRgb(benchmark::State& state) {
  RenderBenchmarkOptions o;
  o.channels = 3;
  const auto ghosts = benchmarkGhosts(o);
  for (auto _ : state) benchmark::DoNotOptimize(renderGhosts(ghosts, cv::Size(o.width, o.height), 3));
}
BENCHMARK(BM_RenderFrameRgb)->Unit(benchmark::kMillisecond);

void BM_RenderFrameWithDerivatives(benchmark::State& state) {
  RenderBenchmarkOptions o;
  o.ghosts = static_cast<int>(state.range(0));
  const auto ghosts = benchmarkGhosts(o);
  for (auto _ : state)
    benchmark::DoNotOptimize(renderGhostsWithDerivatives(ghosts, cv::Rect(0, 0, o.width, o.height), 1));
}
BENCHMARK(BM_RenderFrameWithDerivatives)->Arg(10)->Arg(100)->Unit(benchmark::kMillisecond);

// One ghost of radius range(0) over its own region, plain (range(1) = 0) or with derivatives.
void BM_OneGhost(benchmark::State& state) {
  RenderBenchmarkOptions o;
  o.ghosts = 1;
  o.min_radius = o.max_radius = static_cast<double>(state.range(0));
  auto ghosts = benchmarkGhosts(o);
  ghosts[0].center_x = 640;
  ghosts[0].center_y = 360;
  const cv::Rect roi = ghostPixelBounds(ghosts[0]);
  for (auto _ : state) {
    if (state.range(1))
      benchmark::DoNotOptimize(renderGhostsWithDerivatives(ghosts, roi, 1));
    else
      benchmark::DoNotOptimize(renderGhosts(ghosts, roi, 1));
  }
}
BENCHMARK(BM_OneGhost)->ArgsProduct({{20, 50, 80}, {0, 1}})->Unit(benchmark::kMicrosecond);

// Nearest-point searches per point in the fall-off band of a random ghost.
void BM_SignedDistance(benchmark::State& state) {
  SignedDistanceOptions options;
  options.method = state.range(0) ? NearestPointMethod::kBisection12 : NearestPointMethod::kSampledNewton;
  RenderBenchmarkOptions o;
  o.ghosts = 20;
  const auto ghosts = benchmarkGhosts(o);
  std::mt19937 rng(3);
  std::vector<std::pair<int, cv::Point2d>> points;
  for (int i = 0; i < 4096; ++i) {
    const int g = i % o.ghosts;
    const cv::Rect2d box = outlineBounds(ghosts[g]);
    std::uniform_real_distribution<double> x(box.x, box.x + box.width), y(box.y, box.y + box.height);
    points.push_back({g, {x(rng), y(rng)}});
  }
  size_t i = 0;
  for (auto _ : state) {
    const auto& [g, p] = points[i++ % points.size()];
    benchmark::DoNotOptimize(signedDistance(ghosts[g], p, options));
  }
}
BENCHMARK(BM_SignedDistance)->Arg(0)->Arg(1)->ArgNames({"paper_bisection"});

}  // namespace
}  // namespace flarekit::model
