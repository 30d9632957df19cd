#pragma once
// The simulated rig: a head that only records its angle and a camera that renders the scene at
// that angle and turns it into RAW frames with a sensor model. Both can inject faults, seeded, so
// tests exercise the capture session's retries and resume (rig file section [faults]).
//
// The scene is a provider (angle → linear radiance), so the camera does not depend on how the
// radiance is made: rigs use the physical renderer (acquisition/render_scene.h); unit tests may
// pass simple scenes. Frames are deterministic: the noise seed depends on the rig seed, the
// angle and the exposure time only, so a resumed capture gives the same frames as an
// uninterrupted one.

#include <functional>
#include <memory>
#include <mutex>
#include <random>
#include <string>

#include "acquisition/device.h"
#include "acquisition/rig.h"
#include "common/exr.h"

namespace flarekit::acquisition {

// What a simulated camera sees.
class SceneProvider {
 public:
  virtual ~SceneProvider() = default;
  // Linear radiance (CV_32FC1 or CV_32FC3, render units) with the light at `angle_deg`, seen
  // through the lens at `f_number`.
  virtual cv::Mat radiance(double angle_deg, double f_number) = 0;
  // Ground truth for the capture's truth/ folder: main layer = noise-free radiance in the merged
  // frames' units and channels, plus per-ghost layers "ghost.<id>". Empty when the scene has none.
  virtual ExrImage truth(double angle_deg, double f_number) = 0;
  virtual std::string lensName() const = 0;
  virtual double pixelPitchUm() const = 0;
  virtual double focalLengthMm() const = 0;  // where a light at θ images: f·tan θ
};

// Turns radiance (render units) into a RAW frame: (radiance, exposure_s, iso, seed) → CV_16UC1.
using RawExposer =
    std::function<cv::Mat(const cv::Mat& radiance, double exposure_s, double iso, uint64_t seed)>;

// Shared state of the simulated head and camera: where the head points.
struct SimulatedStage {
  double angle_deg = 0;
  bool homed = false;
};

// Seeded fault injection (FaultConfig): draws per call, counts calls.
class FaultInjector {
 public:
  FaultInjector(uint64_t seed, std::string device);
  // Throws a transient DeviceError with `probability`, and a persistent one once `calls` reached
  // `disconnect_after` (≥ 0).
  void maybeFail(double transient_probability, int disconnect_after, double timeout_probability = 0,
                 double timeout_s = 0);

 private:
  std::mt19937_64 rng_;
  std::string device_;
  long long calls_ = 0;
  bool disconnected_ = false;
};

class SimulatedHead : public RotationHead {
 public:
  SimulatedHead(std::shared_ptr<SimulatedStage> stage, SimulatedHeadConfig config,
                FaultConfig faults);
  std::string describe() const override;
  void home() override;
  void moveTo(double angle_deg) override;
  double angleDeg() const override { return stage_->angle_deg; }

 private:
  std::shared_ptr<SimulatedStage> stage_;
  SimulatedHeadConfig config_;
  FaultConfig faults_;
  FaultInjector injector_;
};

class SimulatedCamera : public Camera {
 public:
  // `black_level_dn` and `white_level_dn(iso)` describe what `exposer` produces.
  SimulatedCamera(std::shared_ptr<SimulatedStage> stage, std::shared_ptr<SceneProvider> scene,
                  RawExposer exposer, Cfa cfa, double black_level_dn,
                  std::function<double(double iso)> white_level_dn, uint64_t seed,
                  FaultConfig faults);
  std::string describe() const override;
  void setExposure(double exposure_s) override { exposure_s_ = exposure_s; }
  void setIso(double iso) override { iso_ = iso; }
  void setAperture(double f_number) override { f_number_ = f_number; }
  RawFrame capture() override;
  RawFrame captureDark() override;

  SceneProvider& scene() { return *scene_; }
  double fNumber() const { return f_number_; }

  // The light's irradiance relative to the rig's (a drifting light, [simulation]
  // light_drift_pct): scales what the following exposures see (1 = as rendered, bit for bit).
  void setLightScale(double scale) { light_scale_ = scale; }
  double lightScale() const { return light_scale_; }
  // The light exposure (acquisition/capture.h): the following exposures see the light through a
  // neutral-density filter of `attenuation` (≥ 1), and draw their noise apart from the bracket's
  // (an exposure of the same time is another photograph), and `take` > 0 apart from the first
  // light exposure at that angle (the light check goes back to a frame's angle). Off: the
  // bracket's exposures.
  void setLightExposure(bool on, double attenuation = 1, int take = 0) {
    light_exposure_ = on;
    attenuation_ = on ? attenuation : 1;
    take_ = on ? take : 0;
  }

 private:
  RawFrame expose(const cv::Mat& radiance, bool dark);
  const cv::Mat& radianceAt(double angle_deg);

  std::shared_ptr<SimulatedStage> stage_;
  std::shared_ptr<SceneProvider> scene_;
  RawExposer exposer_;
  Cfa cfa_;
  double black_;
  std::function<double(double)> white_;
  uint64_t seed_;
  FaultConfig faults_;
  FaultInjector injector_;
  double exposure_s_ = 1, iso_ = 100, f_number_ = 8;
  double cached_angle_ = 0, cached_f_number_ = 0;
  bool cached_ = false;
  cv::Mat cached_radiance_;
  double light_scale_ = 1, attenuation_ = 1;
  bool light_exposure_ = false;
  int take_ = 0;
};

// A 64-bit mix of values (splitmix64), for per-frame seeds.
uint64_t mixSeed(uint64_t a, uint64_t b);

}  // namespace flarekit::acquisition
