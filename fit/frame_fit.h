#pragma once
// Stage 5 of the fit (docs/fitting.md): every frame's ghosts fitted to the frame, seeded from the
// ghost candidates at the frame's angle. A ghost is present where its traces say so: no
// detection, no tracking, no decision to keep or drop.
//
// Per frame, the ghosts present are fitted in turn, largest first, each on its own region and
// level (fit/cost.h) with all the others held where they stand (Gauss–Seidel), in `sweeps`
// passes; the frame's pedestal (model/pedestal.h, the glow of veils with no border in the frame)
// is fitted to what the ghosts leave after each pass and taken out of the frame for the next.
// My is held on the horizon: every ghost is symmetric about it. Frames are independent and fitted
// in parallel; each one's result does not depend on the thread count.

#include <string>
#include <vector>

#include "fit/cost.h"
#include "fit/frames.h"
#include "fit/ghost_candidates.h"
#include "fit/group_solver.h"
#include "fit/pedestal.h"
#include "model/ghost_shape.h"
#include "model/pedestal.h"

namespace flarekit::fit {

struct FrameFitOptions {
  CostOptions cost;                  // the cost: MSE + λ edge, per-pixel Cauchy loss, levels
  SolverOptions solver;              // Ceres Levenberg–Marquardt (or the paper's GD)
  int sweeps = 2;                    // passes over a frame's ghosts (≥ 1)
  bool pedestal = true;              // fit each frame's pedestal
  PedestalFitOptions pedestal_fit;   // how
  int pedestal_level = 2;            // the pedestal is fitted on k×k averages of the frame (≥ 1)

  bool IsValid(std::string* error) const;
};

// One frame's fit.
struct FrameFit {
  int frame = 0;                    // index in the FrameStack (= sweep row)
  double angle_deg = 0;             // the frame's rig angle
  double noise_sigma = 0;           // the frame's pixel noise σ (estimatePixelNoiseSigma)
  std::vector<int> ghost_ids;       // candidate ids of the ghosts fitted
  std::vector<model::GhostParameters> ghosts;  // their fits, in ghost_ids' order
  model::Pedestal pedestal;         // empty without one
  double cost = 0;                  // the last pass's summed final costs
  long long evaluations = 0;        // cost evaluations (each renders the ghost once)
  int iterations = 0;
};

struct FrameFitSummary {
  int frames = 0;
  int ghost_fits = 0;               // (frame, ghost) fits
  long long evaluations = 0;
  long long iterations = 0;
  double seconds = 0;
};

// Fits the frames `frames` (indices into the stack) with the candidates present in each.
std::vector<FrameFit> fitFrames(const FrameStack& stack, const std::vector<int>& frames,
                                const std::vector<GhostCandidate>& candidates,
                                const FrameFitOptions& options, FrameFitSummary* summary = nullptr);

// The ghosts' outline value and inside value in a canonical form: an inside fall-off no longer
// than the deepest any point of the outline can lie, min(h, (L + R) / 2), with Ii the value the
// fall-off reaches there. A longer fall-off draws exactly the same image (the power fall-off is
// scale-free), so without this Fi, Ii and Ei trade freely and their curves over θ jump.
model::GhostParameters canonicalShade(const model::GhostParameters& ghost);

}  // namespace flarekit::fit
