#include "acquisition/simulated_camera.h"

#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>
#include <thread>

namespace flarekit::acquisition {

uint64_t mixSeed(uint64_t a, uint64_t b) {
  uint64_t z = a + 0x9E3779B97F4A7C15ull * (b + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

FaultInjector::FaultInjector(uint64_t seed, std::string device)
    : rng_(seed), device_(std::move(device)) {}

void FaultInjector::maybeFail(double transient_probability, int disconnect_after,
                              double timeout_probability, double timeout_s) {
  const long long call = calls_++;
  if (disconnected_ || (disconnect_after >= 0 && call >= disconnect_after)) {
    disconnected_ = true;
    throw DeviceError(device_ + ": disconnected (simulated persistent fault after " +
                          std::to_string(disconnect_after) + " operations)",
                      /*transient=*/false);
  }
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double draw_fault = u(rng_), draw_timeout = u(rng_);
  if (draw_fault < transient_probability)
    throw DeviceError(device_ + ": I/O error (simulated transient fault)", /*transient=*/true);
  if (draw_timeout < timeout_probability) {
    std::this_thread::sleep_for(std::chrono::duration<double>(timeout_s));
    throw DeviceError(device_ + ": timed out (simulated)", /*transient=*/true);
  }
}

SimulatedHead::SimulatedHead(std::shared_ptr<SimulatedStage> stage, SimulatedHeadConfig config,
                             FaultConfig faults)
    : stage_(std::move(stage)),
      config_(config),
      faults_(faults),
      injector_(mixSeed(faults.seed, 1), "simulated head") {}

std::string SimulatedHead::describe() const { return "simulated rotation head"; }

void SimulatedHead::home() {
  injector_.maybeFail(faults_.head_transient_probability, faults_.head_disconnect_after_moves);
  stage_->angle_deg = 0;
  stage_->homed = true;
}

void SimulatedHead::moveTo(double angle_deg) {
  injector_.maybeFail(faults_.head_transient_probability, faults_.head_disconnect_after_moves);
  if (config_.speed_deg_s > 0) {
    const double seconds = std::abs(angle_deg - stage_->angle_deg) / config_.speed_deg_s;
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  }
  stage_->angle_deg = angle_deg;
}

SimulatedCamera::SimulatedCamera(std::shared_ptr<SimulatedStage> stage,
                                 std::shared_ptr<SceneProvider> scene, RawExposer exposer, Cfa cfa,
                                 double black_level_dn,
                                 std::function<double(double)> white_level_dn, uint64_t seed,
                                 FaultConfig faults)
    : stage_(std::move(stage)),
      scene_(std::move(scene)),
      exposer_(std::move(exposer)),
      cfa_(cfa),
      black_(black_level_dn),
      white_(std::move(white_level_dn)),
      seed_(seed),
      faults_(faults),
      injector_(mixSeed(faults.seed, 2), "simulated camera") {}

std::string SimulatedCamera::describe() const {
  return "simulated camera (" + scene_->lensName() + ")";
}

const cv::Mat& SimulatedCamera::radianceAt(double angle_deg) {
  if (!cached_ || cached_angle_ != angle_deg || cached_f_number_ != f_number_) {
    cached_radiance_ = scene_->radiance(angle_deg, f_number_);
    cached_angle_ = angle_deg;
    cached_f_number_ = f_number_;
    cached_ = true;
  }
  return cached_radiance_;
}

RawFrame SimulatedCamera::expose(const cv::Mat& radiance, bool dark) {
  // The seed depends on what is photographed only (angle, exposure, dark or not), never on how
  // many frames came before: resumed captures reproduce uninterrupted ones.
  uint64_t exposure_bits = 0;
  static_assert(sizeof exposure_bits == sizeof exposure_s_);
  std::memcpy(&exposure_bits, &exposure_s_, sizeof exposure_bits);
  const auto angle_mdeg = static_cast<int64_t>(std::llround(stage_->angle_deg * 1000.0));
  uint64_t seed = mixSeed(seed_, static_cast<uint64_t>(angle_mdeg));
  seed = mixSeed(seed, exposure_bits);
  seed = mixSeed(seed, dark ? 1 : 0);
  if (light_exposure_) seed = mixSeed(seed, 2);
  if (take_ > 0) seed = mixSeed(seed, 100 + static_cast<uint64_t>(take_));
  RawFrame frame;
  const double scale = light_scale_ / attenuation_;
  frame.data = exposer_(scale == 1.0 || dark ? radiance : cv::Mat(radiance * scale), exposure_s_, iso_, seed);
  frame.cfa = cfa_;
  frame.black_level = black_;
  frame.white_level = white_(iso_);
  frame.exposure_s = exposure_s_;
  frame.iso = iso_;
  frame.f_number = f_number_;
  frame.camera = "simulated";
  return frame;
}

RawFrame SimulatedCamera::capture() {
  injector_.maybeFail(faults_.camera_transient_probability, faults_.camera_disconnect_after_frames,
                      faults_.camera_timeout_probability, faults_.timeout_s);
  return expose(radianceAt(stage_->angle_deg), false);
}

RawFrame SimulatedCamera::captureDark() {
  injector_.maybeFail(faults_.camera_transient_probability, faults_.camera_disconnect_after_frames,
                      faults_.camera_timeout_probability, faults_.timeout_s);
  const cv::Mat& r = radianceAt(stage_->angle_deg);
  return expose(cv::Mat::zeros(r.size(), r.type()), true);
}

}  // namespace flarekit::acquisition
