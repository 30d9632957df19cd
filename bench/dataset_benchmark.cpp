// Google Benchmark programs for export-flares (issue 59): one sample's rendering in memory over
// image sizes, and its sRGB encoding; no files. `flarekit bench export-flares` measures the whole
// export to disk, the issue's images-per-second figure.
#include <benchmark/benchmark.h>

#include <string>

#include "dataset/flare_export.h"

namespace flarekit::dataset {
namespace {

const std::string kNikon = std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/view/nikon_model.json";

// Args: width = height. Samples 0, 1, 2, … in turn (different angles, rolls and ghosts).
void BM_RenderSample(benchmark::State& state) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon)};
  ExportOptions o;
  o.count = 1000;
  o.size = {static_cast<int>(state.range(0)), static_cast<int>(state.range(0))};
  long long i = 0;
  for (auto _ : state) {
    const SampleParameters s = sampleParameters(models, o, i++ % o.count);
    benchmark::DoNotOptimize(renderSample(models[0], s, o));
  }
}
BENCHMARK(BM_RenderSample)->Arg(256)->Arg(512)->Arg(1024)->Unit(benchmark::kMillisecond);

void BM_EncodeSrgb8(benchmark::State& state) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon)};
  ExportOptions o;
  const SampleImages images = renderSample(models[0], sampleParameters(models, o, 0), o);
  for (auto _ : state) benchmark::DoNotOptimize(encodeSrgb8(images.flare));
}
BENCHMARK(BM_EncodeSrgb8)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace flarekit::dataset
