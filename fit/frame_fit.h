#pragma once
// Stage 5 of the fit (docs/fitting.md): every frame's ghosts fitted to the frame, seeded from the
// ghost candidates at the frame's angle. A ghost is present where its candidate is (its traces
// span the frame's row of the sweep); nothing here decides to keep or drop one.
//
// Per frame, the shades of all ghosts present and the frame's pedestal (model/pedestal.h, the glow
// of veils with no border in the frame) are solved together (fit/shade.h); then each ghost is
// fitted in turn, largest first, on its own region and level (fit/cost.h) with the others and the
// pedestal held (Gauss–Seidel), and the shades solved together again, in `sweeps` passes. The
// outlines are fitted to the luminance, the shades per channel: one shape per ghost.
// My is held on the horizon: every ghost is symmetric about it. A shape prior holds each outline
// near its seed: tightly where the sweep saw the border, loosely elsewhere. Frames are independent and fitted
// in parallel; each one's result does not depend on the thread count.

#include <string>
#include <vector>

#include "fit/cost.h"
#include "fit/frames.h"
#include "fit/ghost_candidates.h"
#include "fit/horizon.h"
#include "fit/group_solver.h"
#include "fit/shade.h"
#include "model/flare_model.h"
#include "model/ghost_shape.h"
#include "model/pedestal.h"

namespace flarekit::fit {

struct FrameFitOptions {
  CostOptions cost;                  // the cost: MSE + λ edge, per-pixel Cauchy loss, levels
  SolverOptions solver;              // Ceres Levenberg–Marquardt (or the paper's GD)
  int sweeps = 1;                    // passes over a frame's ghosts (≥ 1)
  bool pedestal = true;              // fit each frame's pedestal
  ShadeOptions shade;                // the shades and the pedestal by linear least squares
  // The shape prior about each ghost's seed: σ of a border the sweep saw in the frame, pixels,
  // and of the rest of the outline (a border beyond the frame, h), a fraction of its size.
  double seen_border_sigma_px = 1.5;
  double unseen_sigma_fraction = 0.3;

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

// Fits the frames `frames` (indices into the stack) with the candidates present in each, the
// light's image (`pattern`, at each frame's light in `horizon`) taken out of them.
std::vector<FrameFit> fitFrames(const FrameStack& stack, const std::vector<int>& frames,
                                const Horizon& horizon, const LightPattern& pattern,
                                const std::vector<GhostCandidate>& candidates,
                                const FrameFitOptions& options, FrameFitSummary* summary = nullptr);

// The candidates re-seeded from a model fitted to them: at every frame of a candidate's range that
// its model ghost covers, the model's parameters there, with the borders the sweep saw in that
// frame kept where they were (the middle moved to lie between them). Candidates without a model
// ghost, and frames it does not cover, keep their seeds.
std::vector<GhostCandidate> seedsFromModel(const std::vector<GhostCandidate>& candidates,
                                           const model::FlareModel& model, const FrameStack& stack);

// The ghosts' outline value and inside value in a canonical form: an inside fall-off no longer
// than the deepest any point of the outline can lie, min(h, (L + R) / 2), with Ii the value the
// fall-off reaches there. A longer fall-off draws exactly the same image (the power fall-off is
// scale-free), so without this Fi, Ii and Ei trade freely and their curves over θ jump.
model::GhostParameters canonicalShade(const model::GhostParameters& ghost);

}  // namespace flarekit::fit
