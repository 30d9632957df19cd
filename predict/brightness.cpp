#include "predict/brightness.h"

#include <cmath>
#include <stdexcept>

namespace flarekit::predict {
namespace {

void check(const ExposureSettings& s, const char* which) {
  if (!(s.f_number > 0) || !(s.iso > 0) || !(s.exposure_s > 0) || !std::isfinite(s.f_number) ||
      !std::isfinite(s.iso) || !std::isfinite(s.exposure_s))
    throw std::invalid_argument(std::string(which) + " exposure: f-number, ISO and time must be positive");
}

void check(const LightPower& l) {
  if (!(l.capture_illuminance_lux > 0) || !(l.scene_illuminance_lux > 0) ||
      !std::isfinite(l.capture_illuminance_lux) || !std::isfinite(l.scene_illuminance_lux))
    throw std::invalid_argument("light illuminances must be positive");
}

}  // namespace

double ev100(const ExposureSettings& s) {
  check(s, "");
  // Stingray 2017 (Lagarde & de Rousiers): EV100 = log2(N² · 100 / (t · S)).
  return std::log2(s.f_number * s.f_number / s.exposure_s * 100.0 / s.iso);
}

BrightnessScale brightnessScale(const ExposureSettings& capture, const ExposureSettings& scene,
                                const LightPower& light) {
  check(capture, "capture");
  check(scene, "scene");
  check(light);
  BrightnessScale b;
  b.ev100_capture = ev100(capture);
  b.ev100_scene = ev100(scene);
  // log2 B = (EV100_F − EV100_R) + log2((l_R·α_R)/(l_F·α_F)), which is
  // Walch 2018 Eq. 2 with the f-number, ISO and time ratios gathered into exposure values.
  b.log2_scale = (b.ev100_capture - b.ev100_scene) +
                 std::log2(light.scene_illuminance_lux / light.capture_illuminance_lux);
  b.scale = std::exp2(b.log2_scale);
  return b;
}

double brightnessScaleProduct(const ExposureSettings& capture, const ExposureSettings& scene,
                              const LightPower& light) {
  check(capture, "capture");
  check(scene, "scene");
  check(light);
  // Walch 2018 Eq. 2, factor by factor.
  return (capture.f_number * capture.f_number) / (scene.f_number * scene.f_number) * (scene.iso / capture.iso) *
         (scene.exposure_s / capture.exposure_s) * (light.scene_illuminance_lux / light.capture_illuminance_lux);
}

}  // namespace flarekit::predict
