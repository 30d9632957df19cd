#pragma once
// Fitting a flare model to a whole capture (Walch et al. 2018 §3.3, automated; docs/fitting.md):
// every ghost is found once, for the whole capture, in the sweep image, and the model fitted to
// all frames. The stages, each in its own file with its own options, run in order:
//
//   1. frames            fit/frames.h            the capture or EXR stack (loaded by the caller)
//   2. horizon           fit/horizon.h           symmetry row, the light in every frame, its pattern
//   3. sweep             fit/sweep.h             the sweep image S(θ, x) and its border traces
//   4. ghost candidates  fit/ghost_candidates.h  traces paired into ghosts, seeds at every frame;
//                                                then the optical zero from their centres
//   5. frame fits        fit/frame_fit.h         every frame's ghosts fitted together
//   6. model fit         fit/model_fit.h         polynomials, refined against the frames
//   5, 6 again           fit/frame_fit.h         the frames seeded from that model's curves
//                                                (reseed_from_model; the first run on every
//                                                other frame)
//
// Evaluation (fit/evaluation.h) and the report (fit/report.h) read the result.

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "fit/frame_fit.h"
#include "fit/frames.h"
#include "fit/ghost_candidates.h"
#include "fit/horizon.h"
#include "fit/model_fit.h"
#include "fit/sweep.h"
#include "model/flare_model.h"

namespace flarekit::fit {

struct FlareFitterOptions {
  HorizonOptions horizon;
  LightPatternOptions light_pattern;
  SweepOptions sweep;
  CandidateOptions candidates;
  OpticalZeroOptions optical_zero;
  FrameFitOptions frame_fit;
  ModelFitOptions model_fit;
  // Fit on every other frame only (0, 2, 4, … in angle order), to evaluate on the others.
  bool holdout_odd = false;
  // Frames fitted one by one in stage 5 are this far apart, degrees (every frame where the
  // capture's step is coarser; the model fit measures all) (> 0).
  double frame_step_deg = 0.8;
  // Stage 5 skipped: the model's polynomials go through the candidates' seeds.
  bool skip_frame_fit = false;
  // Stages 5 and 6 run twice: first on every other of those frames, then on all of them seeded
  // from the first model's curves (seedsFromModel), which pool every frame's evidence where a
  // seed from the traces has only its own frame's.
  bool reseed_from_model = true;
  // Threads (≥ 1); the result is the same for any number.
  int threads = 2;

  bool IsValid(std::string* error) const;
};

struct FitSummary {
  int frames_total = 0;        // frames in the stack
  int frames_used = 0;         // frames the fit saw (all, or the even ones with holdout)
  double horizon_y_px = 0;
  int light_frames = 0;        // frames that show the light
  OpticalZero optical_zero;
  int traces = 0;
  CandidateSummary candidates;
  FrameFitSummary frame_fit;
  ModelFitSummary model_fit;
  int ghosts = 0;              // in the model
  std::vector<std::string> warnings;
  // Wall time of each stage and of the whole fit, seconds.
  double seconds_horizon = 0, seconds_sweep = 0, seconds_candidates = 0, seconds_frame_fit = 0,
         seconds_model_fit = 0, seconds_total = 0;

  std::string BriefReport() const;
  nlohmann::json toJson() const;
};

struct FitResult {
  model::FlareModel model;
  Horizon horizon;
  LightPattern light;
  SweepImage sweep;
  std::vector<BorderTrace> traces;
  std::vector<GhostCandidate> candidates;
  std::vector<FrameFit> frame_fits;  // ascending frame index
  std::vector<int> frames_used;      // indices into the stack
  FitSummary summary;
};

// Stages 2–4 alone (the capture's geometry, no fitting): the horizon, the light in every frame
// and its pattern, the sweep and its traces, the ghost candidates, the optical zero, and the
// lights the optical zero's curve places where the frame's edge cuts or hides their core. The
// result holds those and the summary's horizon, light, optical-zero, trace and candidate figures;
// the model and frame fits are empty. fitFlare starts with it; `flarekit metrics` reports it.
FitResult measureCaptureGeometry(const FrameStack& stack, const FlareFitterOptions& options = {});

// Fits the stack. Throws std::invalid_argument for invalid options. A capture with no ghost gives
// an empty model and a warning in the summary.
FitResult fitFlare(const FrameStack& stack, const FlareFitterOptions& options);

}  // namespace flarekit::fit
