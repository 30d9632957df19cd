#pragma once
// `flarekit bench fit`: Ceres's Levenberg–Marquardt against the paper's gradient descent
// (Walch et al. 2018 §3.3.2) on the same frames from the same starting points (the ghost
// candidates' seeds, fit/ghost_candidates.h), on the same cost. Per case: the GD's final cost, its time and cost
// evaluations to reach it, and Ceres's time and evaluations to reach that cost (or its final
// cost if it never does); why Ceres stopped, and where each optimizer ended (its final
// parameters), so that a case Ceres does not win can be looked into: describeCeresEnd tells a
// stall (the cost still falls from Ceres's end towards the GD's) from a basin of the GD's own.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "fit/cost.h"
#include "fit/flare_fitter.h"
#include "fit/frames.h"

namespace flarekit::fit {

struct OptimizerBenchOptions {
  int frames = 3;            // frames sampled evenly from the stack (≥ 1)
  int seeds_per_frame = 1;   // brightest ghost candidates per frame used as starts (≥ 1)
  int gd_iterations = 200;   // GD iterations per case (≥ 1)
  FlareFitterOptions fit;    // the stages that find the seeds, the cost, threads

  bool IsValid(std::string* error) const;
};

nlohmann::json benchOptimizers(const FrameStack& stack, const OptimizerBenchOptions& options);

// Why Ceres ended above the GD's cost, from the cost on the straight line between the two ends.
// Where it falls from Ceres's end towards the GD's, Ceres stopped on a slope (a stall: its
// projected step went nowhere, as where a parameter sits on its bound, fit/group_solver.cpp);
// where it rises first, the GD went on into another basin, which a local method cannot reach.
struct CeresEnd {
  std::vector<double> path_costs;          // at t = 0, 0.1, …, 1 from Ceres's end to the GD's
  bool stalled = false;                    // path_costs[1] < path_costs[0]
  std::vector<std::string> on_bounds;      // Ceres's parameters on their fit bounds (cost.h fitBounds)
};
// `cost`: the group cost both optimizers minimised (one ghost).
CeresEnd describeCeresEnd(GroupCost& cost, const model::GhostParameters& ceres_end,
                          const model::GhostParameters& gd_end);

}  // namespace flarekit::fit
