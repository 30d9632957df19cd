#pragma once
// A capture's plan: the angles, the bracket, the light exposures and the pauses of a session
// (acquisition/capture.h), from the rig's [capture] defaults and the command line, and checked
// against the rig before any device is opened.

#include <string>
#include <vector>

#include "acquisition/hdr_merge.h"
#include "acquisition/rig.h"

namespace flarekit::acquisition {

struct CapturePlan {
  double from_deg = 0;    // first angle
  double to_deg = 20;     // last angle (inclusive); may be below from_deg
  double step_deg = 0.5;  // step (> 0); (to − from)/step must be a whole number
  std::vector<double> exposures_s{0.25, 1, 4};  // bracket (distinct, > 0)
  int dark_frames = 0;    // dark frames averaged per exposure time (0 = black level only)
  bool keep_raw = false;  // also store the RAW exposures under raw/
  double iso = 100;       // camera ISO (> 0)
  double f_number = 8;    // aperture (> 0)
  int max_retries = 3;    // retries of a transiently failing device operation (≥ 0)
  double retry_delay_s = 0.5;  // pause before a retry (≥ 0)
  double settle_s = 0;    // pause after each move before exposing (rig [head] settle_s; 0–60)
  // The light exposures: more exposures per frame, merged apart from the frames, the shortest
  // short enough (or through a declared ND filter) that the light's image does not clip. Empty =
  // none; each in (0, 60] s, distinct, at most 8.
  std::vector<double> light_exposures_s;
  double light_nd_factor = 1;  // the declared filter's attenuation (≥ 1; only with light exposures)
  // Light exposures taken for the light check, at its start and again at its end (1–256): their
  // mean measures the drift with √n times less shot noise than one.
  int light_check_repeats = 16;

  bool IsValid(std::string* error) const;
  // The angles, from from_deg to to_deg in steps of step_deg.
  std::vector<double> anglesDeg() const;
  // The rig's [capture] defaults.
  static CapturePlan FromRig(const Rig& rig);
};

// Checks a plan against the rig before any device is opened: InputError naming the rig file when
// an angle lies outside the head's soft limits or is not a whole number of microsteps.
void checkPlanForRig(const Rig& rig, const CapturePlan& plan);

// The merge options a rig implies at `iso` (gain, read noise, output scale).
MergeOptions mergeOptionsForRig(const Rig& rig, double iso);

}  // namespace flarekit::acquisition
