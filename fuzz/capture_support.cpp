#include "fuzz/capture_support.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <random>
#include <string>

#include <opencv2/imgproc.hpp>

#include "acquisition/simulated_camera.h"
#include "common/exr.h"
#include "fuzz/fuzz_support.h"

namespace flarekit::fuzz {

using namespace acquisition;

namespace {

// A spot whose position follows the angle, on a dim background.
class SpotScene : public SceneProvider {
 public:
  explicit SpotScene(std::function<void(double)> on_render = {})
      : on_render_(std::move(on_render)) {}
  cv::Mat radiance(double angle_deg, double) override {
    if (on_render_) on_render_(angle_deg);
    cv::Mat r(24, 32, CV_32FC1, cv::Scalar(0.05));
    cv::circle(r, {16 - static_cast<int>(angle_deg), 12}, 4, cv::Scalar(3.0), -1);
    return r;
  }
  ExrImage truth(double angle_deg, double f) override {
    ExrImage e;
    e.layers.push_back({"", radiance(angle_deg, f)});
    e.layers.push_back({"ghost.1", radiance(angle_deg, f) * 0.5});
    return e;
  }
  std::string lensName() const override { return "spot"; }
  double pixelPitchUm() const override { return 5; }
  double focalLengthMm() const override { return 50; }

 private:
  std::function<void(double)> on_render_;
};

// Poisson electrons (1000 e/s per unit), 4 e/DN, black 100, 12 bit.
cv::Mat expose(const cv::Mat& radiance, double t, double, uint64_t seed) {
  std::mt19937_64 rng(seed);
  cv::Mat out(radiance.size(), CV_16UC1);
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x) {
      std::poisson_distribution<int> p(std::max(1e-9, radiance.at<float>(y, x) * 1000.0 * t));
      out.at<uint16_t>(y, x) = static_cast<uint16_t>(std::min(4095, 100 + p(rng) / 4));
    }
  return out;
}

RigDevices devicesWith(const Rig& rig, std::shared_ptr<SceneProvider> scene) {
  auto stage = std::make_shared<SimulatedStage>();
  RigDevices d;
  d.head = std::make_unique<SimulatedHead>(stage, SimulatedHeadConfig{}, rig.faults);
  d.camera = std::make_unique<SimulatedCamera>(
      stage, std::move(scene), expose, Cfa::kMono, 100.0, [](double) { return 4095.0; }, 1,
      rig.faults);
  return d;
}

}  // namespace

Rig captureRig() {
  Rig rig;
  rig.name = "fuzz";
  rig.file = "fuzz.toml";
  rig.sensor.black_level_dn = 100;
  rig.sensor.bit_depth = 12;
  rig.sensor.base_gain_e_per_dn = 4;
  rig.sensor.electrons_per_unit_s = 1000;
  return rig;
}

RigDevices captureDevices(const Rig& rig) { return devicesWith(rig, std::make_shared<SpotScene>()); }

CapturePlan capturePlan() {
  CapturePlan p;
  p.from_deg = 0;
  p.to_deg = 2;
  p.step_deg = 1;
  p.exposures_s = {0.25, 1};
  p.dark_frames = 1;
  p.retry_delay_s = 0;
  return p;
}

void makeSmallCapture(const std::filesystem::path& dir, int stop_after_frames) {
  const Rig rig = captureRig();
  std::atomic<bool> stop{false};
  // The plan's angles are 0, 1, 2°: rendering frame k (at k°) requests the stop when k + 1 frames
  // are enough; the session notices after that frame.
  RigDevices d = devicesWith(rig, std::make_shared<SpotScene>([&](double angle_deg) {
    if (stop_after_frames > 0 && angle_deg + 1 >= stop_after_frames) stop = true;
  }));
  CaptureOptions options;
  options.progress = false;
  options.stop_requested = &stop;
  if (stop_after_frames == 0) stop = true;
  runCapture(rig, d, capturePlan(), dir, options);
}

const std::filesystem::path& scratchCapture() {
  static const std::filesystem::path dir = [] {
    const auto d = scratchDir() / "capture";
    makeSmallCapture(d);
    return d;
  }();
  return dir;
}

}  // namespace flarekit::fuzz
