#include "acquisition/stepper_motion.h"

#include <cmath>
#include <sstream>

#include "common/error.h"

namespace flarekit::acquisition {

long long microstepsForAngle(const StepperGeometry& g, double angle_deg, const std::string& where) {
  const double per_deg = g.microstepsPerDeg();
  const double exact = (angle_deg - g.home_angle_deg) * per_deg;
  const long long nearest = std::llround(exact);
  if (std::abs(exact - static_cast<double>(nearest)) > 1e-6) {
    std::ostringstream m;
    m.precision(10);
    m << "angle " << angle_deg << "° is not a whole number of microsteps (" << per_deg
      << " microsteps per degree: " << g.full_steps_per_rev << " steps × " << g.microsteps
      << " microsteps × gear " << g.gear_ratio << " / 360°); the nearest reachable angle is "
      << angleForMicrosteps(g, nearest) << "° (off by "
      << std::abs(angleForMicrosteps(g, nearest) - angle_deg) << "°): choose a step that is a "
      << "multiple of " << 1.0 / per_deg << "°";
    throw InputError(where, m.str());
  }
  return nearest;
}

double angleForMicrosteps(const StepperGeometry& g, long long microsteps) {
  return g.home_angle_deg + static_cast<double>(microsteps) / g.microstepsPerDeg();
}

void checkSoftLimits(const StepperGeometry& g, double angle_deg, const std::string& where) {
  if (angle_deg < g.min_deg - 1e-9 || angle_deg > g.max_deg + 1e-9) {
    std::ostringstream m;
    m << "angle " << angle_deg << "° lies outside the soft limits [" << g.min_deg << "°, "
      << g.max_deg << "°] (head.soft_limits_deg)";
    throw InputError(where, m.str());
  }
}

std::vector<long long> approachWaypoints(long long from, long long to, int approach_sign,
                                         long long backlash_steps) {
  if (from == to) return {};
  const long long direction = to > from ? 1 : -1;
  if (direction == approach_sign || backlash_steps == 0) return {to};
  return {to - approach_sign * backlash_steps, to};
}

std::vector<double> stepTimes(long long steps, double max_speed, double accel) {
  std::vector<double> t(static_cast<size_t>(std::max<long long>(steps, 0)));
  if (steps <= 0) return t;
  // Steps needed to reach cruise speed: v² = 2 a s.
  const double accel_steps = max_speed * max_speed / (2 * accel);
  const double n = static_cast<double>(steps);
  const double ramp = std::min(accel_steps, n / 2);  // steps spent accelerating (= decelerating)
  const double v_peak = std::sqrt(2 * accel * ramp);
  const double t_ramp = v_peak / accel;
  const double cruise_steps = n - 2 * ramp;
  const double t_cruise = cruise_steps / v_peak;
  for (long long k = 1; k <= steps; ++k) {
    const double s = static_cast<double>(k);
    double time;
    if (s <= ramp) {
      time = std::sqrt(2 * s / accel);
    } else if (s <= ramp + cruise_steps) {
      time = t_ramp + (s - ramp) / v_peak;
    } else {
      // Decelerating: distance left to the end d = n − s, time before the end sqrt(2 d / a).
      const double left = n - s;
      time = 2 * t_ramp + t_cruise - std::sqrt(2 * left / accel);
    }
    t[static_cast<size_t>(k - 1)] = time;
  }
  return t;
}

}  // namespace flarekit::acquisition
