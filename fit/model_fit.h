#pragma once
// Stage 6 of the fit (docs/fitting.md): the flare model from the frames.
//
// First each ghost's parameters become polynomials in the field angle θ − θ0 (the optical zero)
// by robust least squares over its frame fits (a border's over the frames where the sweep saw
// it), each of the degree that predicts held-out fits best; then the shades' polynomials of all
// ghosts at once, by linear least squares against the frames for those outlines (fit/shade.h
// ShadeEquations). With `refine`, the coefficients themselves are then refined against the
// frames directly, in one Ceres problem whose parameter blocks are each ghost's coefficients and
// whose residuals are the fitted frames' pixels (each frame less the pedestal found under the
// ghosts, at a level of its pyramid), each frame's in units of its brightest model ghost's peak.
// It is off by default: it does not raise the model's PSNR (docs/fitting.md, limits). A ghost is
// kept over the frames where its shades draw light above the noise, and dropped where they never
// do. The pedestal under the ghosts is fitted last, to what the model's ghosts leave of every
// frame, and kept as polynomials too.

#include <string>
#include <vector>

#include "fit/cost.h"
#include "fit/frame_fit.h"
#include "fit/frames.h"
#include "fit/ghost_candidates.h"
#include "fit/horizon.h"
#include "fit/pedestal.h"
#include "fit/shade.h"
#include "model/flare_model.h"

namespace flarekit::fit {

struct ModelFitOptions {
  int min_degree = 1;                  // polynomial degrees tried by validation (≥ 0)
  int max_degree = 4;                  // (min_degree … kMaxPolynomialDegree)
  bool reshade = true;                 // the shades' polynomials against the frames, for the outlines'
  ShadeOptions shade;                  // how (fit/shade.h)
  bool refine = false;                 // refine the coefficients against the frames (docs/fitting.md)
  int refine_pixels = 30000;           // each fitted frame at the first level within this many pixels
  int refine_iterations = 10;          // Levenberg–Marquardt iterations of the refinement (≥ 1)
  CostOptions cost;                    // the refinement's cost (its shape prior is not used)
  double min_peak_sigma = 1;           // a ghost's range ends where its brightest value falls below
                                       // this × the frame's noise σ (≥ 0; 0 keeps the candidates')
  bool pedestal = true;                // fit the model's pedestal
  int pedestal_degree = 8;             // its polynomials' degree (the glow changes over the capture)
  int pedestal_level = 2;              // fitted on k×k averages of each frame (≥ 1)
  PedestalFitOptions pedestal_fit;

  bool IsValid(std::string* error) const;
};

struct ModelFitSummary {
  int ghosts = 0;
  int ghosts_unseen = 0;               // candidates whose shades are below min_peak_sigma throughout
  int refine_frames = 0;               // frames the refinement used
  int refine_iterations = 0;
  double refine_initial_cost = 0, refine_final_cost = 0;
  std::string refine_termination;
  double seconds_polynomials = 0, seconds_refine = 0, seconds_pedestal = 0;
};

// The model from the frame fits (`fits`, at frames of `stack`) of `candidates`, measured against
// the frames with the light's image taken out (`pattern` at `horizon`'s lights). The model
// records the capture's metadata, the optical zero and the horizon.
model::FlareModel fitModel(const FrameStack& stack, const Horizon& horizon, const LightPattern& pattern,
                           const std::vector<GhostCandidate>& candidates,
                           const std::vector<FrameFit>& fits, const OpticalZero& zero,
                           const ModelFitOptions& options,
                           ModelFitSummary* summary = nullptr);

}  // namespace flarekit::fit
