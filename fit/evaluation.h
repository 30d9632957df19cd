#pragma once
// Measuring a fitted flare model, or the per-frame fits it was made from (fit/frame_fits.h),
// against a capture and, for simulated captures, against the ground truth under truth/ (issue 6,
// `flarekit fit-eval`):
//
//  - PSNR of the model against the noise-free flare (the sum of the per-ghost truth layers) over
//    the flare region: the pixels where that flare exceeds the frame's noise σ and the frame is
//    not saturated. Peak = the flare's maximum over the region: PSNR = 10 log10(peak² / MSE).
//  - Ghost centroids (intensity-weighted, over the image) of every model ghost and every true
//    ghost; a true ghost is visible when its peak exceeds visible_factor × the noise floor (the
//    issue's rule: 10×). Model and true ghosts are matched greedily by centroid distance within a
//    gate of max(min_match_px, match_fraction × the true ghost's radius), the radius being √2 ×
//    its intensity-weighted RMS distance from the centroid (R for a uniform disc of radius R).
//  - Recall: matched visible true ghosts / visible true ghosts. Precision: model ghosts matched to
//    any true ghost / model ghosts present. Centroid errors over matched visible pairs.
//  - Each unmatched model ghost: whether it draws a piece of a true ghost (most of its light lies
//    within that ghost's light) or light no ghost has (FrameEvaluation::Unmatched).
//  - Per matched visible pair: the centroid error in px and in % of the true ghost's radius; the
//    flux error |Σ model − Σ truth| / Σ truth of the ghost's luminance over the image (the model
//    ghost rendered alone against the true ghost's layer); the PSNR of the model's whole image
//    against the noise-free flare over that true ghost's own support (its layer > σ).
//  - Continuity of each true ghost: of the frames it is visible in, the largest share matched by
//    one and the same model ghost id (1: one model ghost drew it throughout; 0: never found).
//  - Light ghosts: unmatched model ghosts on the light's own image, the truth's main
//    layer minus its ghost layers, where it exceeds light_factor × σ (the core and the
//    starburst's rays): their centroid inside that region, or most of their light on it.
//  - Without truth: PSNR of the model against the frame over the pixels where the model exceeds
//    the noise σ.
// The noise floor σ (truth known) is measured on frame − noise-free luminance at a scale above a
// demosaic's correlation (noiseFloor): a mono and a demosaiced RGGB capture of one lens and noise
// model get the same σ and the same visible ghosts. Without truth it is the pixel noise from
// neighbour differences (fit/cost.h estimatePixelNoiseSigma: frame-filling veils do not inflate
// it).

#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "fit/cost.h"
#include "fit/frame_fits.h"
#include "fit/frames.h"
#include "model/flare_model.h"

namespace flarekit::fit {

// The noise floor of a frame from its noise image (frame − noise-free luminance) over the valid
// pixels: 1.4826 × the median absolute deviation of the noise's means over block_px × block_px
// blocks (wholly valid ones), times block_px; per pixel at block_px 1. The MAD, not the RMS, is the
// typical (background) pixel's, not the light core's shot noise. 0 when no block is valid.
double noiseFloor(const cv::Mat& noise, const cv::Mat& valid, int block_px = kNoiseBlockPx);

struct EvaluationOptions {
  bool odd_frames_only = false;   // evaluate frames 1, 3, 5, … (the ones --holdout odd left out)
  double visible_factor = 10;     // a true ghost counts when its peak > this × noise σ (> 0)
  double match_fraction = 0.25;   // gate as a fraction of the true ghost's radius (> 0)
  double min_match_px = 3;        // smallest gate, pixels (> 0)
  double light_factor = 10;       // the light's region: its own image > this × noise σ (> 0)
  int noise_block_px = kNoiseBlockPx;  // the noise floor's block width, pixels (≥ 1; noiseFloor)

  bool IsValid(std::string* error) const;
};

struct FrameEvaluation {
  double angle_deg = 0;
  double noise_sigma = 0;
  double pixel_noise_sigma = 0;    // truth known: noiseFloor per pixel (block 1), for comparison
  double psnr_db = 0;              // vs truth (NaN without truth)
  double capture_psnr_db = 0;      // vs the frame (NaN when the model is empty here)
  int true_ghosts_visible = 0;
  int true_ghosts_found = 0;       // visible and matched
  int model_ghosts = 0;            // model ghosts with any pixel in the image
  int model_ghosts_matched = 0;    // matched to some true ghost
  int model_ghosts_pieces = 0;     // unmatched model ghosts that are pieces of a true ghost
  int light_ghosts = 0;            // unmatched model ghosts on the light (Unmatched::onLight)
  // Each matched visible true ghost: its model ghost, how far their centroids are apart, how
  // their light compares, and how well the model draws the flare where that ghost is.
  struct Matched {
    int true_id = 0, model_id = 0;
    double radius_px = 0;             // the true ghost's, as the gate uses it
    double centroid_error_px = 0;
    double centroid_error_pct = 0;    // 100 × centroid_error_px / radius_px
    double flux_error = 0;            // |model − true flux| / true flux (fraction; Σ luminance)
    double psnr_db = 0;               // the model's image vs the noise-free flare over the true
                                      // ghost's support (its layer > σ); NaN when it has none
  };
  std::vector<Matched> matched;
  double medianCentroidErrorPx() const;   // over `matched` (NaN when none)
  double medianCentroidErrorPct() const;  // over `matched` (NaN when none)
  double medianFluxError() const;         // over `matched` (NaN when none)
  double medianGhostPsnrDb() const;       // over `matched` (NaN when none)
  std::vector<int> missed_true_ids;        // visible true ghosts without a match
  // Each missed visible true ghost: where it is, and the nearest model ghost (why it is missed:
  // none near it, or one beyond the gate).
  struct Missed {
    int id = 0;
    cv::Point2d centroid;             // image pixels
    double radius_px = 0;             // as the gate uses it
    double peak_sigma = 0;            // its peak in noise σ
    int nearest_model_id = -1;        // −1: no model ghost in the frame
    double nearest_distance_px = 0;   // centroid distance to it
  };
  std::vector<Missed> missed;
  // Each model ghost without a true ghost, and whose light it draws: the true ghost whose layer
  // holds the largest part of the model ghost's light, Σ min(model, truth) / Σ model over its
  // pixels. With at least kPieceFraction of its light in one true ghost it is a piece of that
  // ghost: the model drew the ghost in several pieces, or drew it with its centroid beyond the
  // gate (a caustic's bright core apart from its faint body, Brendel Tessar ghost 15 at 3–9°).
  // With less, it draws light no one true ghost holds (the light's own image, noise, or where
  // several ghosts overlap). Precision counts both as unmatched; this says which loss is which.
  // On the light when its centroid lies in the light's region (EvaluationOptions::light_factor)
  // or more than kLightFraction of its light does: a ghost drawn on the core or a starburst ray.
  // The two are told apart independently: a piece of a ghost that lies on the light is both.
  struct Unmatched {
    static constexpr double kPieceFraction = 0.5;
    static constexpr double kLightFraction = 0.5;
    int model_id = 0;
    int true_id = -1;                 // the true ghost holding most of its light (−1: none)
    double fraction_in_true = 0;      // that part, 0–1
    double fraction_on_light = 0;     // the part of its light on the light's region, 0–1
    double peak_sigma = 0;            // its peak in noise σ (as Missed::peak_sigma)
    bool centroid_on_light = false;   // its centroid's pixel is in that region
    bool piece() const { return fraction_in_true >= kPieceFraction; }
    bool onLight() const { return centroid_on_light || fraction_on_light > kLightFraction; }
  };
  std::vector<Unmatched> unmatched;
  // The model's ceiling in this frame (`flarekit fit-ceiling`, Evaluation::setCeiling); NaN where
  // it was not measured or not given.
  double ceiling_psnr_db = std::numeric_limits<double>::quiet_NaN();
};

// The model's ceiling at one angle, as `flarekit fit-ceiling --json` writes it (ModelCeiling).
struct CeilingPoint {
  double angle_deg = 0;
  double psnr_db = 0;
};

// A ceiling read from `flarekit fit-ceiling --json`: its points, and which ceiling it is. With
// every true ghost fitted it is the model's; with --fit-above N only the ghosts brighter than
// N noise σ are, the rest drawn as a pedestal: what a fitter that finds those could reach.
struct CeilingCurve {
  std::vector<CeilingPoint> points;
  double fit_above_sigma = 0;       // 0: every true ghost fitted
  bool quadratic_pedestal = false;  // with fit_above_sigma: the pedestal a quadratic, else flat

  // What it is, for reports: "the model's ceiling (fit-ceiling)", or e.g. "the ceiling of the
  // ghosts above 10 σ (fit-ceiling --fit-above 10 --quadratic-pedestal)".
  std::string name() const;
  // The same in a few ASCII words, for a plot's legend: e.g. "ceiling of the ghosts above 10 sigma".
  std::string label() const;
};

// One true ghost over the evaluated frames: in how many it was visible and found, and where and
// how bright it was where it was missed (which ghosts a fit loses, at a glance; the per-frame
// `missed` entries hold the details).
struct TrueGhostSummary {
  int id = 0;
  int frames_visible = 0;
  int frames_found = 0;
  double missed_min_deg = 0, missed_max_deg = 0;  // the angles it was missed at (when missed)
  double missed_median_peak_sigma = 0;            // its median peak there, noise σ (NaN when never missed)
  double median_radius_px = 0;                    // over the frames it was visible in
  int unmatched_pieces = 0;  // unmatched model ghosts, over the frames, that are pieces of it
  // Of the frames it is visible in, the largest share matched by one model ghost id (0–1), and
  // that id (−1 when never found).
  double continuity = 0;
  int continuity_model_id = -1;
};

struct Evaluation {
  bool has_truth = false;
  std::vector<FrameEvaluation> frames;
  std::vector<TrueGhostSummary> true_ghosts;  // every ghost visible in some frame, by id
  double median_psnr_db = 0;
  double median_capture_psnr_db = 0;
  double median_centroid_error_px = 0;
  double median_centroid_error_pct = 0;  // in % of the true ghost's radius, over matched pairs
  double median_flux_error = 0;          // fraction, over matched pairs
  double median_ghost_psnr_db = 0;       // PSNR over each true ghost's support, over matched pairs
  double continuity = 0;                 // mean over true_ghosts of their continuity (NaN: none)
  double recall = 0, precision = 0;
  int true_ghosts_visible = 0, true_ghosts_found = 0, model_ghosts = 0, model_ghosts_matched = 0;
  int model_ghosts_pieces = 0;  // of the unmatched, pieces of a true ghost (FrameEvaluation::Unmatched)
  int light_ghosts = 0;         // of the unmatched, on the light's core or rays, over the frames
  // Against a ceiling (setCeiling): the ceiling as given (no points: none), the frames it was
  // measured in, and the median of ceiling − PSNR over them (what the fitter falls short of that
  // best by; NaN when none).
  CeilingCurve ceiling;
  int ceiling_frames = 0;
  double median_ceiling_gap_db = std::numeric_limits<double>::quiet_NaN();

  // Sets each frame's ceiling_psnr_db from the point at its angle (within kAngleToleranceDeg) and
  // the summary above; frames without one keep NaN.
  void setCeiling(const CeilingCurve& curve);

  nlohmann::json toJson() const;
  std::string BriefReport() const;
};

// What a model or a frame's fits draw at one angle: the ghosts, matched one by one, and the
// pedestal under them (model/pedestal.h; empty for none), counted in the PSNR with them.
struct FlareAtAngle {
  std::vector<model::GhostAtAngle> ghosts;
  model::Pedestal pedestal;
};

// The flare to measure in the frame at `angle_deg`, or nullopt for a frame to leave out. Frames
// are evaluated in parallel: it is called from several threads at once.
using GhostsAtAngle = std::function<std::optional<FlareAtAngle>(double angle_deg)>;
Evaluation evaluateGhosts(const GhostsAtAngle& ghosts_at, int channels, const FrameStack& stack,
                          const EvaluationOptions& options = {});

// The model's ghosts and pedestal (its polynomials) in every frame (frames outside every ghost's
// range: none).
Evaluation evaluateModel(const model::FlareModel& model, const FrameStack& stack,
                         const EvaluationOptions& options = {});
// The per-frame fits in the frames that were fitted; the others are left out.
Evaluation evaluateFrameFits(const FrameFits& fits, const FrameStack& stack,
                             const EvaluationOptions& options = {});

// ── The model's ceiling ──────────────────────────────────────────────────────────────────────────
// What the ghost model (model/ghost_shape.h, Walch et al. 2018 §3.2) can describe of a simulated
// capture at best, whatever the fitter's search for ghosts and its optimizer: every true ghost of
// a frame is fitted alone to its own noise-free truth layer, from four starts taken from the
// layer itself (evaluation.cpp ceilingStarts), each with the fit's cost (the edge term on) and
// then with the plain squared error, which is what PSNR measures; the best in PSNR is kept. The
// frame's ceiling is the sum of those fits, measured as fit-eval measures a model: PSNR against
// the noise-free flare over the flare region, and the centroid error of every visible true ghost
// (peak > visible_factor × σ) against its fit. A fit that lands below these figures loses to the
// fitter's search for ghosts or its optimizer; a target above them is beyond the model. Starts
// are local, so the figures are lower bounds on what the model could reach, as is fitting
// crossing ghosts apart (a joint fit of their sum may trade one's error against the other's).
struct CeilingOptions {
  int frame_step = 10;          // measure frames 0, N, 2N, … of the stack (≥ 1)
  // Fit each true ghost whose peak exceeds this × σ (≥ 0; 0: every ghost with any light, the
  // model's ceiling). Above 0, the fainter ones are drawn as one pedestal, the constant closest
  // to their sum (CeilingFrame::pedestal): what a fitter that found and described every ghost
  // above that level, and drew the rest as a glow, could reach. Ghosts each below the noise sum
  // to much of the flare once the light has left the frame.
  double fit_factor = 0;
  // With fit_factor > 0, the pedestal a quadratic in the pixel's x and y (1, x, y, x², xy, y²),
  // the form the fitter's pedestal has (model/pedestal.h), fitted the same way, instead of a
  // constant.
  bool quadratic_pedestal = false;
  double visible_factor = 10;   // centroid errors over ghosts above this × σ, fit-eval's rule (> 0)
  int max_iterations = 100;     // Levenberg–Marquardt iterations per start and stage (≥ 1)
  // The fit's cost without its robust loss and shape prior: the truth has no outliers to resist
  // and no unseen parts to hold.
  CostOptions cost = [] {
    CostOptions c;
    c.loss_scale = 0;
    c.prior_fraction = 0;
    return c;
  }();

  bool IsValid(std::string* error) const;
};

struct CeilingGhost {
  int id = 0;
  double peak_sigma = 0;          // its peak in noise σ
  double radius_px = 0;           // √2 × its intensity-weighted RMS radius (as fit-eval's gate)
  bool visible = false;           // peak > visible_factor × σ
  double psnr_db = 0;             // its best fit against its own layer, over the layer's footprint
                                  // (pixels > 0: faint ghosts have none above σ)
  double centroid_error_px = 0;   // its best fit's centroid against its own
  model::GhostParameters parameters;  // its best fit
};

struct CeilingFrame {
  double angle_deg = 0;
  double noise_sigma = 0;
  double psnr_db = 0;             // the sum of the best fits against the noise-free flare
  double pedestal = 0;            // with fit_factor > 0: the pedestal drawn for the rest (its
                                  // mean over the flare region, when quadratic)
  std::vector<CeilingGhost> ghosts;  // every fitted true ghost
  cv::Mat flare;                  // the noise-free flare, luminance (CV_32F)
  cv::Mat described;              // the sum of the best fits, luminance (CV_32F)
};

// One true ghost over the measured frames where it was visible.
struct CeilingGhostSummary {
  int id = 0;
  int frames_visible = 0;
  double median_psnr_db = 0;
  double median_centroid_error_px = 0;
  double max_centroid_error_px = 0;
};

struct ModelCeiling {
  cv::Size image_size;                      // the capture's
  std::vector<CeilingFrame> frames;
  std::vector<CeilingGhostSummary> ghosts;  // every ghost visible in some measured frame, by id
  double median_psnr_db = 0;                // over frames
  double median_centroid_error_px = 0;      // over visible ghosts in every frame
  int visible_ghosts = 0;                   // (frame, ghost) pairs
  int within_half_px = 0;                   // of them, centroid error ≤ 0.5 px
  double fit_above_sigma = 0;               // CeilingOptions::fit_factor (fainter ghosts: a pedestal)
  bool quadratic_pedestal = false;          // CeilingOptions::quadratic_pedestal

  nlohmann::json toJson() const;
  std::string BriefReport() const;
};

// InputError when the stack has no ground truth.
ModelCeiling measureModelCeiling(const FrameStack& stack, const CeilingOptions& options = {});

// The ceiling of ModelCeiling::toJson output (format kModelCeilingFormat) measured on a capture of
// `image_size`; InputError naming `source` when `json` is not that.
inline constexpr const char* kModelCeilingFormat = "flarekit-model-ceiling";
CeilingCurve parseCeiling(const nlohmann::json& json, cv::Size image_size, const std::string& source);

// Median of the finite values (NaN when none).
double medianOf(std::vector<double> values);

}  // namespace flarekit::fit
