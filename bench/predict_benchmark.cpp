// Prediction speed (kept out of CTest): the overlay of one scene, the estimators of one image, the
// severity map, and the whole analysis, on the hand-made test model and the example stage.
#include <benchmark/benchmark.h>

#include "model/flare_model.h"
#include "predict/prediction.h"
#include "predict/scene.h"

namespace {

using namespace flarekit;

const model::FlareModel& testModel() {
  static const model::FlareModel m = model::FlareModel::load(FLAREKIT_SOURCE_DIR "/tests/data/predict/test_model.json");
  return m;
}
const predict::Scene& stage() {
  static const predict::Scene s = predict::loadScene(FLAREKIT_SOURCE_DIR "/predict/examples/stage.json");
  return s;
}

// Overlay of the stage's lights at a width of range(0) pixels.
void BM_Overlay(benchmark::State& state) {
  const predict::PredictOptions o;
  const cv::Size size = predict::predictionImageSize(testModel(), stage(), static_cast<int>(state.range(0)));
  for (auto _ : state)
    benchmark::DoNotOptimize(predict::renderOverlay(testModel(), stage(), stage().camera.pose, size, o));
  state.SetItemsProcessed(state.iterations() * size.area());
}
BENCHMARK(BM_Overlay)->Arg(320)->Arg(640)->Arg(1280)->Unit(benchmark::kMillisecond);

// All estimators of one range(0)-wide image.
void BM_Estimators(benchmark::State& state) {
  const int w = static_cast<int>(state.range(0));
  cv::Mat overlay(w * 2 / 3, w, CV_32FC3), scene(w * 2 / 3, w, CV_32FC3);
  cv::randu(overlay, 0, 1);
  cv::randu(scene, 0, 1);
  for (auto _ : state) benchmark::DoNotOptimize(predict::computeEstimators(overlay, scene));
  state.SetItemsProcessed(state.iterations() * overlay.total());
}
BENCHMARK(BM_Estimators)->Arg(320)->Arg(1280)->Arg(4096)->Unit(benchmark::kMillisecond);

// The severity map at the default grid, rendered range(0) pixels wide.
void BM_SeverityMap(benchmark::State& state) {
  predict::PredictOptions o;
  o.map_image_width_px = static_cast<int>(state.range(0));
  const cv::Mat scene = predict::sceneImage(stage(), predict::predictionImageSize(testModel(), stage(), 0));
  for (auto _ : state) benchmark::DoNotOptimize(predict::severityMap(testModel(), scene, 1.0, o));
}
BENCHMARK(BM_SeverityMap)->Arg(96)->Arg(192)->Arg(384)->Unit(benchmark::kMillisecond);

// Everything `flarekit predict` computes, without writing files.
void BM_Analyze(benchmark::State& state) {
  const predict::PredictOptions o;
  for (auto _ : state) benchmark::DoNotOptimize(predict::analyze(testModel(), stage(), o));
}
BENCHMARK(BM_Analyze)->Unit(benchmark::kMillisecond);

}  // namespace
