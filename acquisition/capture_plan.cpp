#include "acquisition/capture_plan.h"

#include <cmath>
#include <string>

#include "acquisition/stepper_motion.h"
#include "common/error.h"

namespace flarekit::acquisition {

bool CapturePlan::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!std::isfinite(from_deg) || !std::isfinite(to_deg)) return fail("angles must be finite");
  if (!(step_deg > 0) || !std::isfinite(step_deg)) return fail("step must be positive");
  const double n = std::abs(to_deg - from_deg) / step_deg;
  if (std::abs(n - std::round(n)) > 1e-6)
    return fail("the range from " + std::to_string(from_deg) + "° to " + std::to_string(to_deg) +
                "° is not a whole number of " + std::to_string(step_deg) + "° steps");
  if (n > 1e6) return fail("more than a million angles");
  if (exposures_s.empty()) return fail("need at least one exposure time");
  for (size_t i = 0; i < exposures_s.size(); ++i) {
    if (!(exposures_s[i] > 0) || !std::isfinite(exposures_s[i]))
      return fail("exposure times must be positive");
    for (size_t j = 0; j < i; ++j)
      if (exposures_s[j] == exposures_s[i]) return fail("exposure times must differ");
  }
  if (exposures_s.size() > 16) return fail("at most 16 exposures per bracket");
  if (dark_frames < 0) return fail("dark_frames must be ≥ 0");
  if (!(iso > 0)) return fail("iso must be positive");
  if (!(f_number > 0)) return fail("f_number must be positive");
  if (max_retries < 0) return fail("max_retries must be ≥ 0");
  if (!(retry_delay_s >= 0)) return fail("retry_delay_s must be ≥ 0");
  if (!(settle_s >= 0 && settle_s <= 60)) return fail("settle_s must be in [0, 60] seconds");
  if (light_exposures_s.size() > 8) return fail("at most 8 light exposures");
  for (size_t i = 0; i < light_exposures_s.size(); ++i) {
    if (!(light_exposures_s[i] > 0 && light_exposures_s[i] <= 60))
      return fail("light exposures must be in (0, 60] seconds");
    for (size_t j = 0; j < i; ++j)
      if (light_exposures_s[j] == light_exposures_s[i]) return fail("light exposures must differ");
  }
  if (!(light_nd_factor >= 1 && light_nd_factor <= 1e12))
    return fail("the light exposure's ND factor must be in [1, 1e12]");
  if (light_check_repeats < 1 || light_check_repeats > 256) return fail("light_check_repeats must be 1..256");
  if (light_nd_factor != 1 && light_exposures_s.empty())
    return fail("an ND factor declares the light exposure's filter: it needs a light exposure");
  return true;
}

std::vector<double> CapturePlan::anglesDeg() const {
  const long long n = std::llround(std::abs(to_deg - from_deg) / step_deg);
  const double dir = to_deg >= from_deg ? 1.0 : -1.0;
  std::vector<double> angles;
  angles.reserve(n + 1);
  for (long long i = 0; i <= n; ++i) {
    // Rounded to 1e-9° so that manifests written and read back compare exactly.
    double a = from_deg + dir * static_cast<double>(i) * step_deg;
    angles.push_back(std::round(a * 1e9) / 1e9);
  }
  return angles;
}

CapturePlan CapturePlan::FromRig(const Rig& rig) {
  CapturePlan p;
  p.from_deg = rig.capture.from_deg;
  p.to_deg = rig.capture.to_deg;
  p.step_deg = rig.capture.step_deg;
  p.exposures_s = rig.capture.exposures_s;
  p.dark_frames = rig.capture.dark_frames;
  p.iso = rig.capture.iso;
  p.f_number = rig.capture.f_number;
  p.max_retries = rig.capture.max_retries;
  p.retry_delay_s = rig.capture.retry_delay_s;
  p.settle_s = rig.settle.settle_s;
  p.light_exposures_s = rig.capture.light_exposures_s;
  p.light_nd_factor = rig.capture.light_nd_factor;
  p.light_check_repeats = rig.capture.light_check_repeats;
  return p;
}

void checkPlanForRig(const Rig& rig, const CapturePlan& plan) {
  std::string error;
  if (!plan.IsValid(&error)) throw InputError("capture plan: " + error);
  if (rig.head_driver != HeadDriver::kGpioStepper && rig.head_driver != HeadDriver::kTic) return;
  const StepperGeometry& g =
      rig.head_driver == HeadDriver::kTic ? rig.tic.geometry : rig.gpio.geometry;
  for (double a : plan.anglesDeg()) {
    checkSoftLimits(g, a, rig.file.string());
    microstepsForAngle(g, a, rig.file.string());
  }
}

MergeOptions mergeOptionsForRig(const Rig& rig, double iso) {
  MergeOptions m;
  m.gain_e_per_dn = rig.sensor.gainEPerDn(iso);
  m.read_noise_e = rig.sensor.read_noise_e;
  if (rig.camera_driver == CameraDriver::kSimulated)
    m.output_scale = rig.sensor.electrons_per_unit_s;
  return m;
}

}  // namespace flarekit::acquisition
