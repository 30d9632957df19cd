#pragma once
// A small synthetic rig for acquisition's tests and the capture fuzz targets (header-only; not
// part of the library): a 32×24 scene with one spot that follows the angle, a 12-bit Poisson
// sensor, and simulated head and camera on one stage; and how far two captures' frames differ.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "acquisition/simulated_camera.h"
#include "common/config.h"
#include "common/exr.h"

namespace flarekit::testing {

using namespace acquisition;

// A spot whose position follows the angle, on a dim background; its truth has the spot as the
// light and half of it as one ghost layer. Calls `on_render` with the angle of every render.
class SpotScene : public SceneProvider {
 public:
  explicit SpotScene(std::function<void(double)> on_render = {}) : on_render_(std::move(on_render)) {}
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

// The sensor of spotRig(): Poisson electrons (1000 e/s per unit), 4 e/DN, black 100, 12 bit.
inline cv::Mat exposeSpot(const cv::Mat& radiance, double t, double, uint64_t seed) {
  std::mt19937_64 rng(seed);
  cv::Mat out(radiance.size(), CV_16UC1);
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x) {
      std::poisson_distribution<int> p(std::max(1e-9, radiance.at<float>(y, x) * 1000.0 * t));
      out.at<uint16_t>(y, x) = static_cast<uint16_t>(std::min(4095, 100 + p(rng) / 4));
    }
  return out;
}

// A rig whose sensor section matches exposeSpot.
inline Rig spotRig(const std::string& name, FaultConfig faults = {}) {
  Rig rig;
  rig.name = name;
  rig.file = name + ".toml";
  rig.sensor.black_level_dn = 100;
  rig.sensor.bit_depth = 12;
  rig.sensor.base_gain_e_per_dn = 4;
  rig.sensor.electrons_per_unit_s = 1000;
  rig.faults = faults;
  return rig;
}

// A simulated head and a mono camera on one stage, both with the rig's faults.
inline RigDevices spotDevices(const Rig& rig, std::shared_ptr<SceneProvider> scene = std::make_shared<SpotScene>()) {
  auto stage = std::make_shared<SimulatedStage>();
  RigDevices d;
  d.head = std::make_unique<SimulatedHead>(stage, SimulatedHeadConfig{}, rig.faults);
  d.camera = std::make_unique<SimulatedCamera>(
      stage, std::move(scene), exposeSpot, Cfa::kMono, 100.0, [](double) { return 4095.0; }, 1, rig.faults);
  return d;
}

// Median and largest of |a − b| / |b| over the values (of every channel) where b ≠ 0: how far two
// captures of the same frames differ. {1e300, 1e300} when b is 0 everywhere.
inline std::pair<double, double> relativeDifference(const cv::Mat& a, const cv::Mat& b) {
  const cv::Mat fa = a.reshape(1), fb = b.reshape(1);
  std::vector<double> d;
  for (int y = 0; y < fa.rows; ++y)
    for (int x = 0; x < fa.cols; ++x) {
      const double r = fb.at<float>(y, x);
      if (r != 0) d.push_back(std::abs(fa.at<float>(y, x) - r) / std::abs(r));
    }
  if (d.empty()) return {1e300, 1e300};
  const double largest = *std::max_element(d.begin(), d.end());
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return {d[d.size() / 2], largest};
}

// How far each frame of the finished capture in `dir` lies from the same frame of `reference`,
// whose values are first multiplied by `scale` (a real camera's electrons/s against the simulated
// camera's render units): relativeDifference per frame, for as many frames as both manifests list.
struct FrameDifference {
  double angle_deg = 0;
  double median = 0, largest = 0;  // {1e300, 1e300} where the two frames' sizes differ
};
inline std::vector<FrameDifference> frameDifferences(const std::filesystem::path& dir,
                                                     const std::filesystem::path& reference,
                                                     double scale = 1.0) {
  const nlohmann::json m = loadJsonFile(dir / "manifest.json").json();
  const nlohmann::json r = loadJsonFile(reference / "manifest.json").json();
  std::vector<FrameDifference> out;
  for (size_t i = 0; i < std::min(m["frames"].size(), r["frames"].size()); ++i) {
    const cv::Mat a = readExrLayer(dir / m["frames"][i]["file"].get<std::string>(), "");
    const cv::Mat b = readExrLayer(reference / r["frames"][i]["file"].get<std::string>(), "") * scale;
    FrameDifference d;
    d.angle_deg = m["frames"][i]["angle_deg"].get<double>();
    if (a.size() == b.size() && a.type() == b.type()) std::tie(d.median, d.largest) = relativeDifference(a, b);
    else d.median = d.largest = 1e300;
    out.push_back(d);
  }
  return out;
}

}  // namespace flarekit::testing
