#pragma once
// Fitting a whole capture (Walch et al. 2018 §3.3.2, automated): every ghost is found, tracked
// over the angles, fitted per frame, and summarised by one polynomial per parameter (the flare
// model file of model/flare_model.h).
//
// The flow:
//  1. Forward sweep over the frames in angle order. In each frame the ghosts being tracked are
//     seeded from their previous fits, extrapolated to the frame's angle by a least-squares
//     polynomial over the last frames (§3.3.2: "we fit a polynomial to each parameter ... to
//     estimate initial parameters for neighboring images"); ghosts whose regions overlap are
//     fitted together (fit/group_solver.h). Then the residual (frame minus all fitted ghosts) is
//     searched for new ghosts (fit/detection.h): veiling glare first while none is modelled (the
//     pedestal of veils too faint to see one by one, flat over the frame, the only ghost whose
//     outline is soft: fit/cost.h isGlare), then blobs; each new one is fitted and kept when it
//     explains its blob.
//     The frame where a ghost is first found is its key frame.
//  2. Backward sweep: every ghost is tracked from its key frame towards smaller angles too (ghosts
//     are hardest to see near the light, where the sweep starts), the whole frame refitted with
//     the ghosts known there.
//  3. A track ends where the ghost leaves the image (less than min_visible_fraction of its box
//     inside), sinks into the noise (its peak below min_peak_sigma noise σ), or the fit breaks
//     down (a size at its bound): trackEndReason. Glare ends only where it leaves the image or
//     sinks into the noise. Identities are kept where ghosts cross because each ghost keeps its
//     own parameter block seeded from its own extrapolation.
//  4. Polynomials per ghost and parameter over its tracked range (degree 2 by default, or chosen
//     1–4 by held-out error), refined in image space: each ghost towards its own fits, then all
//     together towards the sum of the fits in each frame (buildFlareModel).

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "fit/cost.h"
#include "fit/detection.h"
#include "fit/frames.h"
#include "fit/group_solver.h"
#include "fit/pedestal.h"
#include "model/flare_model.h"

namespace flarekit::fit {

struct TrackingOptions {
  // Frames of a track used for the polynomial extrapolation of the next seed (≥ 1).
  int extrapolation_frames = 8;
  // Degree of that extrapolation (0–3; capped by the frames available).
  int extrapolation_degree = 2;
  // A ghost ends when its peak max(Ib, Ii) falls below this many noise σ (> 0).
  double min_peak_sigma = 4;
  // A ghost ends when less than this fraction of its box lies in the image (0–1).
  double min_visible_fraction = 0.05;
  // A new ghost is kept when its fit removes at least this fraction of the residual energy over
  // the blob it was found in (0–1).
  double min_cost_reduction = 0.5;
  // A ghost's fit counts as "not described by the model" (a caustic, fold or other shape the
  // model cannot draw) when the residual's RMS over its region exceeds this fraction of its peak.
  double unexplained_fraction = 0.25;
  // Frames in which new ghosts are searched for (1 = every frame; larger saves time) (≥ 1).
  int detect_every = 1;
  // Tracks shorter than this many frames are dropped as spurious (and counted) (≥ 1).
  int min_track_frames = 3;

  bool IsValid(std::string* error) const;
};

struct FitOptions {
  CostOptions cost;
  SolverOptions solver;
  DetectionOptions detection;
  TrackingOptions tracking;
  // Polynomial degree per parameter (1–kMaxPolynomialDegree); ignored when auto_degree.
  int degree = 2;
  // Choose the degree 1–4 per ghost and parameter by held-out error (every other tracked frame).
  bool auto_degree = false;
  // Fit on every other frame only (frames 0, 2, 4, … in angle order), to evaluate on the others.
  bool holdout_odd = false;
  // Refine every ghost's polynomials together in image space, towards its fits rendered
  // (buildFlareModel's refine_in_image). On the 640×427 captures (0–30° at 0.2°), means over
  // λ × 0.99, 1, 1.01 of recall / precision / median PSNR / median centroid error, without → with:
  //   Heliar Tronnier: 68.9 → 69.8 %, 89.0 → 88.6 %, 23.1 → 23.7 dB, 8.0 → 7.5 px;
  //   Brendel Tessar:  53.6 → 55.6 %, 76.6 → 78.1 %, 21.6 → 23.2 dB, 15.8 → 13.1 px;
  // about 11 s more for the Heliar capture.
  bool refine_in_image = true;
  // Then refine the ghosts' polynomials together, in this many sweeps, towards the sum of the fits
  // in each frame rather than each ghost towards its own (buildFlareModel's joint_sweeps; ≥ 0;
  // needs refine_in_image). On the 640×427 captures (0–30° at 0.2°), means over λ × 0.98, 0.99, 1,
  // 1.01, 1.02 of the model's recall / precision / median PSNR / median centroid error, 0 → 2:
  //   Heliar Tronnier: 71.8 → 73.1 %, 80.9 → 81.6 %, 24.5 → 25.8 dB, 7.8 → 7.7 px;
  //   Brendel Tessar:  75.1 → 75.0 %, 68.7 → 69.3 %, 24.0 → 25.5 dB, 10.7 → 10.6 px;
  // every one of the ten fits gains 0.5–2.2 dB, most from 9° on, where frame-wide veils overlap
  // (median PSNR there 21.4 → 23.6 and 22.2 → 23.9 dB; the frames' own fits: 25.8 and 26.1 dB).
  // One sweep with the whole shortfall instead (λ × 1 only): 25.0 and 25.2 dB against 25.6 and
  // 25.7; three sweeps: 26.1 and 26.1 dB, but held out (--holdout odd) 24.7 and 22.7 against
  // 24.6 and 23.0. It costs time: the model step of λ × 1 took 9.9 → 17.5 s (Heliar) and
  // 11.0 → 15.0 s (Tessar).
  int joint_refine_sweeps = 2;
  // Count the fitter's thresholds (detection levels, a track's end, the glare's seed, the light's
  // zone, the cost's scale floor) in σ of the frame's pixel noise (estimatePixelNoiseSigma: the σ
  // by which fit-eval calls a ghost visible) instead of the background's spread
  // (estimateNoiseSigma, 2–9× that once veils fill the frame), and keep detection off the light's
  // residue (DetectionOptions::light_residue_fraction); `flarekit fit --no-pixel-noise` turns it
  // off. On the 640×427 captures (0–30° at 0.2°), means over λ × 0.99, 1, 1.01 of the model's
  // recall / precision / median PSNR / median centroid error, off → on (with glare ended by its
  // own rules, trackEndReason):
  //   Heliar Tronnier: 67.8 → 79.4 %, 83.5 → 82.2 %, 25.0 → 24.2 dB, 9.2 → 8.6 px;
  //   Brendel Tessar:  51.3 → 78.1 %, 79.3 → 69.1 %, 22.6 → 23.5 dB, 11.7 → 11.3 px;
  // the frames' own fits' PSNR 26.9 → 27.8 dB and 24.0 → 27.3 dB; the fit takes about a third
  // longer (more ghosts). Where the light is in the frame (0–9°) the Tessar's fits draw ghost 15's
  // bright core, whose body the model cannot hold, with several ghosts, 3–7 a frame matched to no
  // true ghost; from 9° on, where the veils fill the frame, they find the ghosts of 12–20 pixel σ
  // that the background's σ hides. Before glare had its own end rules, on was the better in
  // recall and centroid only: Heliar 71.2 → 74.1 %, 86.5 → 82.4 %, 24.0 → 23.3 dB, 8.8 → 7.9 px,
  // Tessar 51.4 → 71.1 %, 78.0 → 69.0 %, 22.5 → 21.9 dB, 15.6 → 10.1 px. The pixel noise alone,
  // without the light's floor: Heliar 70.2 / 81.1 / 21.8 / 8.2, Tessar 71.2 / 66.7 / 21.6 / 10.9.
  bool pixel_noise = true;
  // Fit each frame's pedestal (model/pedestal.h) to what its final ghosts leave of it
  // (fit/pedestal.h), once the tracks stand, and the model's to what the model's ghosts leave,
  // through polynomials (buildPedestalTrack). The ghosts are found and fitted without it, so
  // recall, precision and centroid errors are unchanged. On the 640×427 captures (0–30° at
  // 0.2°), means over λ × 0.98, 0.99, 1, 1.01, 1.02 of the median PSNR, without → with:
  //   Heliar Tronnier: model 25.1 → 25.4 dB, the frames' fits 28.8 → 29.6 dB;
  //   Brendel Tessar:  model 26.2 → 26.6 dB, the frames' fits 28.3 → 29.2 dB.
  // (The model's pedestal polynomials then of degree 4; of degree 8, kPedestalDegree, on captures
  // simulated afresh on another machine: Heliar 25.3 → 25.8 dB, Tessar 27.2 → 27.5 dB.)
  // Fitted inside the sweeps instead, so that the ghosts were fitted on the frame without it, it
  // took part of the large veils not found yet and detection lost them (fit/evaluation.h
  // CeilingOptions::quadratic_pedestal).
  bool pedestal = true;
  PedestalFitOptions pedestal_fit;
  // Threads for the model renderer (≥ 1); the fit is the same for any number.
  int threads = 2;
  // Progress on stderr.
  bool progress = true;

  bool IsValid(std::string* error) const;
};

// One ghost over the frames it was tracked in.
struct GhostTrackFit {
  int id = 0;
  int key_frame = 0;                          // index into the fitted frame list
  std::vector<double> angles_deg;             // ascending
  std::vector<model::GhostParameters> fits;   // per angle
  std::vector<double> residual_rms;           // RMS residual over the ghost's region, per angle
  std::vector<double> peak;                   // max(Ib, Ii) per angle
  std::vector<bool> unexplained;              // residual_rms > unexplained_fraction × peak
  std::vector<bool> carried;                  // not fitted: carried through the light's image
  std::string end_low, end_high;              // why the track ends at either side
};

// One fitted frame.
struct FrameFit {
  double angle_deg = 0;
  int frame = 0;                    // index in the FrameStack
  double noise_sigma = 0;
  bool light_found = false;
  cv::Point2d light_center;
  double light_zone_px = 0;
  std::vector<int> ghost_ids;       // the ghosts fitted in this frame
  std::vector<model::GhostParameters> ghosts;
  model::Pedestal pedestal;         // the glow the ghosts leave (FitOptions::pedestal); or empty
  double cost = 0;                  // sum of the groups' final costs
  long long evaluations = 0;
  int iterations = 0;
};

struct FitSummary {
  std::string optimizer;
  int frames_total = 0;        // frames in the stack
  int frames_fitted = 0;       // frames used (all, or the even ones with holdout)
  int ghosts = 0;              // ghosts in the model
  int ghosts_dropped_short = 0;  // tracks shorter than min_track_frames, left out of the model
  int detections = 0;          // new ghosts accepted
  int detections_rejected = 0; // candidates whose fit did not explain their blob
  long long evaluations = 0;   // cost evaluations over all solves
  long long iterations = 0;
  // Wall time of the whole fit, and of its parts: the frames' fits, detection, and the model
  // (the residual check of every frame, the polynomials and their refinement in image space).
  double seconds_total = 0, seconds_fitting = 0, seconds_detecting = 0, seconds_modelling = 0;
  int degree = 2;              // or -1 for auto
  // Ghosts the model cannot describe well: id and the fraction of its frames flagged.
  std::vector<std::pair<int, double>> unexplained;
  std::vector<std::string> warnings;

  std::string BriefReport() const;
};

struct FitResult {
  model::FlareModel model;
  std::vector<GhostTrackFit> tracks;
  std::vector<FrameFit> frames;     // in angle order
  FitSummary summary;
};

// Fits the stack. Throws std::invalid_argument for invalid options, InputError when nothing can be
// fitted (no ghost found anywhere).
FitResult fitCapture(const FrameStack& stack, const FitOptions& options);

// Least-squares polynomial of `degree` through (angles, values), in θ degrees as the model file
// stores it (solved in a centred, scaled variable for conditioning, then expanded).
model::Polynomial fitPolynomial(const std::vector<double>& angles_deg,
                                const std::vector<double>& values, int degree);

// Which of (angles, values) a polynomial of `degree` should pass through: all but the spikes, the
// values beyond 4 robust σ of a least-absolute-deviations fit (a frame whose fit jumped into the
// light or a neighbouring ghost). All of them when there are fewer than degree + 3.
std::vector<bool> polynomialInliers(const std::vector<double>& angles_deg,
                                    const std::vector<double>& values, int degree);

// The least degree of a glare's polynomials (fit/cost.h isGlare): its one track spans the
// capture, and its pedestal falls 20× over 0–30° on the 640×427 captures (buildFlareModel).
inline constexpr int kGlareDegree = 4;

// The degree of the model's pedestal polynomials (buildPedestalTrack). Its one track spans the
// capture and each term follows the glow of every frame, which a low degree leaves behind. On the
// 640×427 captures, λ × 1, model median PSNR with degree 2 / 4 / 6 / 8: Heliar Tronnier 25.3 /
// 25.5 / 26.0 / 26.2 dB, Brendel Tessar 28.3 / 28.6 / 28.8 / 28.9 dB; held out (--holdout odd),
// degree 4 / 8: 25.7 / 25.9 and 27.7 / 27.7 dB. Degree 8 over λ × 0.98–1.02: Heliar higher at
// every λ (+0.3 to +1.0 dB), Tessar at four and the same at one (0 to +0.9 dB).
inline constexpr int kPedestalDegree = 8;

// The flare model from the tracks: one GhostTrack per track, each parameter a polynomial of the
// given degree (or auto 1–4 by held-out error when degree < 0; a glare's at least kGlareDegree)
// through the track's fits but its spikes (polynomialInliers). Degrees are lowered where a
// polynomial would leave the parameter's bounds inside the range. Each ghost's angle range reaches
// `range_margin_deg` beyond its first and last fitted angle, within [capture_min_deg,
// capture_max_deg]: a ghost fitted in one frame and not in the next ends somewhere between them,
// and the fitter passes half the spacing of its frames, so that the model has no gaps between
// tracks that follow each other and covers the frames --holdout odd left out next to a track.
// With `refine_in_image`, every ghost's polynomials are then refined together in image space, so
// that its rendered image comes closest to its fits', each frame weighed by its brightest fit;
// and then, in `joint_sweeps` sweeps over all ghosts, so that the model's image comes closest to
// the sum of the fits in each fitted frame.
model::FlareModel buildFlareModel(const std::vector<GhostTrackFit>& tracks,
                                  const model::CaptureInfo& info, int channels, int degree,
                                  double range_margin_deg = 0, double capture_min_deg = -90,
                                  double capture_max_deg = 90, bool refine_in_image = false,
                                  int joint_sweeps = 0);

// The model's pedestal (model/pedestal.h) through the pedestals of frames at `angles_deg`: per
// term, a polynomial of `degree` (fewer with fewer frames) through all but its spikes
// (polynomialInliers), by least squares in σ of each frame's noise (`noise_sigma`, weights 1/σ²;
// 0: weight 1), `range_margin_deg` beyond the frames within [capture_min_deg, capture_max_deg] as
// buildFlareModel's ranges. nullopt without frames.
std::optional<model::PedestalTrack> buildPedestalTrack(
    const std::vector<double>& angles_deg, const std::vector<model::Pedestal>& pedestals,
    const std::vector<double>& noise_sigma, int channels, int degree, double range_margin_deg,
    double capture_min_deg, double capture_max_deg);

// Tracks whose polynomials cannot follow their fits, split until they can: a track that turns
// from glare into a sharp ghost or back (fit/cost.h isGlare) for at least min_frames fits on either
// side is cut there; a track whose model ghost (degree as in buildFlareModel) at one of its fitted
// angles is not the same ghost as the fit there (outline boxes overlapping by IoU < 0.5) is cut
// where consecutive fits differ most. Each piece keeps ≥ min_frames frames; tracks shorter than
// 2 × min_frames are kept whole. The later piece gets a new id (from first_new_id on) and
// key_frame −1 (the caller sets it). A track that jumped from one ghost onto another (a Heliar
// ghost beside the light at 5° and a flat wide ellipse at 12.6° in one track) otherwise became one
// polynomial describing neither.
std::vector<GhostTrackFit> splitTracksPolynomialsCannotFollow(std::vector<GhostTrackFit> tracks,
                                                              const model::CaptureInfo& info,
                                                              int channels, int degree,
                                                              int min_frames, int first_new_id);

// Why a track ends at fitted ghost `g` in a frame of noise σ `noise_sigma`, or "" when it goes
// on: "left the image" (less than min_visible_fraction of its outline's box in the image),
// "sank into the noise" (its peak max(Ib, Ii) below min_peak_sigma σ), "fit broke down (size at
// its bound)" (L, R or h beyond 0.98 of the image's diagonal or below 0.6 px). Glare (fit/cost.h
// isGlare) has no outline to break down: it leaves the image only when its outline's box grown
// by its outside fall-off misses the image, and its sizes may sit at their bounds.
std::string trackEndReason(const model::GhostParameters& g, cv::Size image_size, double noise_sigma,
                           const TrackingOptions& options);

// The frame minus the light's own image (detection.h estimateLightImage, from the frame alone):
// what the fitter detects and fits ghosts in. The frame itself without a light in it or with
// options.light_symmetry off.
cv::Mat frameWithoutLight(const Frame& frame, const LightImage& light, double noise_sigma,
                          const DetectionOptions& options);

// The seeds detection finds in one frame with nothing modelled yet (brightest first), in the
// stack's channel count: what the fitter starts new ghosts from (and what `bench fit` starts both
// optimizers from). `data`: the frame as the fitter sees it (frameWithoutLight, with the frame's
// noise σ); `light`: the light found in the frame (findLight).
std::vector<model::GhostParameters> detectSeeds(const FramePyramid& data, const LightImage& light,
                                                int channels, const FitOptions& options);

// Seeds every parameter of a ghost at `angle_deg` from a track's last fits (polynomial
// extrapolation over at most `frames` of them, degree ≤ `degree`).
model::GhostParameters extrapolate(const std::vector<double>& angles_deg,
                                   const std::vector<model::GhostParameters>& fits,
                                   double angle_deg, int frames, int degree);

}  // namespace flarekit::fit
