#pragma once
// `flarekit bench fit`: Ceres's Levenberg–Marquardt against the paper's gradient descent
// (Walch et al. 2018 §3.3.2) on the same frames from the same starting points (the seeds
// detection finds), on the same cost. Per case: the GD's final cost, its time and cost
// evaluations to reach it, and Ceres's time and evaluations to reach that cost (or its final
// cost if it never does); why Ceres stopped, and where each optimizer ended (its final
// parameters), so that a case Ceres does not win can be looked into (a local minimum of its own,
// a bound).

#include <nlohmann/json.hpp>

#include "fit/fit_capture.h"
#include "fit/frames.h"

namespace flarekit::fit {

struct OptimizerBenchOptions {
  int frames = 3;            // frames sampled evenly from the stack (≥ 1)
  int seeds_per_frame = 1;   // brightest detections per frame used as starts (≥ 1)
  int gd_iterations = 200;   // GD iterations per case (≥ 1)
  FitOptions fit;            // cost, detection, threads

  bool IsValid(std::string* error) const;
};

nlohmann::json benchOptimizers(const FrameStack& stack, const OptimizerBenchOptions& options);

}  // namespace flarekit::fit
