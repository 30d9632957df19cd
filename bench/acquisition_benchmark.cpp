// Acquisition benchmarks (kept out of CTest):
//   BM_Merge/<megapixels>       HDR merge of three 16-bit frames (the goal: ≤ 0.25 s for
//                               24 MP on 2 cores; `flarekit bench merge --megapixels 24 --json`
//                               prints the same with the memcpy ratio)
//   BM_Memcpy/<megapixels>      a plain memcpy of the same bytes, the floor to compare with
//   BM_SimulatedCapture         frames per second of a simulated capture at 640×427 (render,
//                               sensor model, three exposures, merge, EXR writes, manifest)
#include <benchmark/benchmark.h>

#include <cmath>
#include <cstring>
#include <filesystem>

#include "acquisition/capture.h"
#include "acquisition/hdr_merge.h"
#include "acquisition/rig.h"
#include "common/log.h"
#include "common/testing.h"

namespace {

using namespace flarekit::acquisition;

std::vector<RawFrame> bracket(int megapixels) {
  const int cols = static_cast<int>(std::lround(std::sqrt(megapixels * 1e6 * 1.5)));
  const int rows = static_cast<int>(std::lround(megapixels * 1e6 / cols));
  cv::Mat scene(rows, cols, CV_32F);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) {
      const double r2 = std::pow(x - cols * 0.3, 2) + std::pow(y - rows * 0.5, 2);
      scene.at<float>(y, x) = static_cast<float>(0.02 + 2e3 / (1 + r2 / 400.0));
    }
  std::vector<RawFrame> frames;
  for (double t : {0.25, 1.0, 4.0}) {
    RawFrame f;
    f.exposure_s = t;
    f.black_level = 512;
    f.white_level = 16383;
    cv::Mat dn = scene * (t * 1000 / 4.0) + 512;
    cv::Mat noise(rows, cols, CV_32F);
    cv::randn(noise, 0, 2);
    dn += noise;
    dn.convertTo(f.data, CV_16U);
    cv::min(f.data, 16383, f.data);
    frames.push_back(f);
  }
  return frames;
}

void BM_Merge(benchmark::State& state) {
  const auto frames = bracket(static_cast<int>(state.range(0)));
  MergeOptions options;
  options.gain_e_per_dn = 4;
  for (auto _ : state) benchmark::DoNotOptimize(mergeBracket(frames, options));
  state.SetBytesProcessed(state.iterations() * 3 * frames[0].data.total() * 2);
}
BENCHMARK(BM_Merge)->Arg(1)->Arg(6)->Arg(24)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_Memcpy(benchmark::State& state) {
  const auto frames = bracket(static_cast<int>(state.range(0)));
  const size_t bytes = frames[0].data.total() * 2;
  std::vector<uint8_t> dst(3 * bytes, 1);
  for (auto _ : state) {
    for (size_t k = 0; k < 3; ++k) std::memcpy(dst.data() + k * bytes, frames[k].data.data, bytes);
    benchmark::ClobberMemory();
  }
  state.SetBytesProcessed(state.iterations() * 3 * bytes);
}
BENCHMARK(BM_Memcpy)->Arg(1)->Arg(6)->Arg(24)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_SimulatedCapture(benchmark::State& state) {
  flarekit::setLogLevel(flarekit::LogLevel::kWarning);
  Rig rig = loadRig(std::filesystem::path(FLAREKIT_SOURCE_DIR) / "rigs/sim-heliar.toml");
  rig.simulation.width_px = 640;
  rig.simulation.height_px = 427;
  const int frames_per_run = 5;
  long long frames = 0;
  for (auto _ : state) {
    state.PauseTiming();
    flarekit::testing::TempDir dir;
    RigDevices devices = openRig(rig);
    CapturePlan plan = CapturePlan::FromRig(rig);
    plan.from_deg = 0;
    plan.to_deg = 0.5 * (frames_per_run - 1);
    plan.step_deg = 0.5;
    CaptureOptions options;
    options.progress = false;
    state.ResumeTiming();
    frames += runCapture(rig, devices, plan, dir / "cap", options).frames_captured;
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SimulatedCapture)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(2);

}  // namespace
