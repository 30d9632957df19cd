// Google Benchmark programs for the renderer: the three rendering methods on the Heliar Tronnier
// and the Nikon 28-75 (351 ghosts) at the 1280×720, RGB, 64² grid, plus a size sweep.
// `flarekit bench render` prints the same comparison as one JSON object.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <map>
#include <string>

#include "render/flare_renderer.h"
#include "render/sensor.h"

namespace {

using namespace flarekit::render;

const Lens& lensNamed(const std::string& name) {
  static std::map<std::string, Lens> cache;
  auto it = cache.find(name);
  if (it == cache.end())
    it = cache.emplace(name, loadLens(std::filesystem::path(FLAREKIT_SOURCE_DIR) / "lenses" / name)).first;
  return it->second;
}

void renderWith(benchmark::State& state, const std::string& lens, RenderMethod method) {
  FlareRenderOptions o;
  o.width_px = static_cast<int>(state.range(0));
  o.height_px = o.width_px * 9 / 16;
  o.method = method;
  o.light_source = false;
  long long rays = 0;
  for (auto _ : state) {
    const FlareImage img = renderFlare(lensNamed(lens), {10.0, 0.0}, o);
    rays += img.summary.rays_traced;
    benchmark::DoNotOptimize(img.radiance.data);
  }
  state.counters["rays_per_s"] = benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsRate);
}

void BM_HeliarTiled(benchmark::State& s) { renderWith(s, "heliar_tronnier.json", RenderMethod::kTiled); }
void BM_HeliarPerGhost(benchmark::State& s) { renderWith(s, "heliar_tronnier.json", RenderMethod::kPerGhost); }
void BM_HeliarMatrix(benchmark::State& s) { renderWith(s, "heliar_tronnier.json", RenderMethod::kMatrix); }
void BM_NikonTiled(benchmark::State& s) { renderWith(s, "nikon_zoom_28_75mm_at_28mm.json", RenderMethod::kTiled); }
void BM_NikonPerGhost(benchmark::State& s) { renderWith(s, "nikon_zoom_28_75mm_at_28mm.json", RenderMethod::kPerGhost); }
void BM_NikonMatrix(benchmark::State& s) { renderWith(s, "nikon_zoom_28_75mm_at_28mm.json", RenderMethod::kMatrix); }

BENCHMARK(BM_HeliarTiled)->Arg(320)->Arg(640)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HeliarPerGhost)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HeliarMatrix)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_NikonTiled)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_NikonPerGhost)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_NikonMatrix)->Arg(1280)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SensorExposeRaw(benchmark::State& state) {
  const cv::Mat radiance(720, 1280, CV_32FC3, cv::Scalar::all(1e-3));
  SensorModel sensor;
  sensor.color_filter = ColorFilter::kBayerRggb;
  uint64_t seed = 0;
  for (auto _ : state) benchmark::DoNotOptimize(exposeRaw(radiance, 0.01, sensor, ++seed).data);
}
BENCHMARK(BM_SensorExposeRaw)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
