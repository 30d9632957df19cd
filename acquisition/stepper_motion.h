#pragma once
// Motion planning shared by the stepper heads: angle ↔ microstep conversion with the whole-step
// check, backlash-aware approach, and constant-acceleration step timing.

#include <string>
#include <vector>

#include "acquisition/rig.h"

namespace flarekit::acquisition {

// Microsteps from the home reference for `angle_deg`. InputError when the angle is not a whole
// number of microsteps (within 1e-6 microstep): the message gives the nearest reachable angle
// and how far off it is. `where` names the source of the angle for the message.
long long microstepsForAngle(const StepperGeometry& g, double angle_deg, const std::string& where);
double angleForMicrosteps(const StepperGeometry& g, long long microsteps);

// InputError when the angle lies outside the soft limits.
void checkSoftLimits(const StepperGeometry& g, double angle_deg, const std::string& where);

// The legs of a move from `from` to `to` (microsteps) so that the target is always reached
// moving in `approach_sign`: one leg when the move already goes that way, else an overshoot of
// `backlash_steps` past the target followed by the return. Empty when from == to.
std::vector<long long> approachWaypoints(long long from, long long to, int approach_sign,
                                         long long backlash_steps);

// Times (seconds from the start of the move) of each of `steps` step pulses for a trapezoidal
// velocity profile with constant acceleration and deceleration `accel` (steps/s²) and cruise
// speed `max_speed` (steps/s); a triangle when the move is too short to reach cruise speed. Exact
// kinematics, t(k) for the k-th step at position k (the Austin 2005 recurrence approximates the
// same profile). The first step is at t(1) = sqrt(2/accel).
std::vector<double> stepTimes(long long steps, double max_speed, double accel);

}  // namespace flarekit::acquisition
