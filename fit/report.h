#pragma once
// `flarekit fit --report DIR`: what a person checks after a fit.
//   DIR/summary.json            the FitSummary (every stage's figures and times), and every
//                               ghost's borders, angle range and frames fitted
//   DIR/ghost_<id>.csv          the ghost's fit in every frame: angle, every parameter
//   DIR/frame_fits.json         every frame's fits (fit/frame_fits.h), which fit-eval measures
//                               like a model
//   DIR/sweep.png               the sweep image with the traces and ghost ids, beside the model's
//   DIR/contact_<angle>.png     for sampled frames: capture | the frame's fits | model |
//                               |capture − model|, on one shared logarithmic scale (decades from
//                               the noise floor to the peak)
// All files are written atomically.

#include <filesystem>

#include "fit/evaluation.h"
#include "fit/flare_fitter.h"
#include "fit/frames.h"

namespace flarekit::fit {

struct ReportOptions {
  int contact_sheets = 8;  // frames sampled evenly over the range for contact sheets (≥ 0)
  bool IsValid(std::string* error) const;
};

void writeFitReport(const std::filesystem::path& dir, const FitResult& result,
                    const FrameStack& stack, const ReportOptions& options = {});

// The sweep picture (8-bit BGR; `flarekit sweep`, the report's sweep.png): S(θ, x) in log scale,
// θ down (three picture rows a frame), with the border traces (orange: left borders, rising; blue:
// right borders, falling), the light's centre (yellow) and each ghost's id; beside it, when
// `model_rows` is not empty, the model's own S on the same scale (sweepRows).
cv::Mat sweepPicture(const SweepImage& sweep, const std::vector<BorderTrace>& traces,
                     const std::vector<GhostCandidate>& candidates, const cv::Mat& model_rows = {});
// The model's S: the same band about the horizon of the model rendered at every row's angle.
cv::Mat sweepRows(const model::FlareModel& model, const SweepImage& sweep, cv::Size size, int channels);

// The contact-sheet image (8-bit BGR) of one frame: capture | fits | model | |capture − model|.
cv::Mat contactSheet(const cv::Mat& capture, const cv::Mat& fits_image, const cv::Mat& model_image,
                     double noise_sigma);

// `flarekit fit-eval --plot FILE`: the evaluation over the capture's angles, 8-bit BGR. Above, each
// frame's PSNR against the noise-free flare (against the capture without truth) and, where the
// evaluation has one (Evaluation::setCeiling), the ceiling, named; below, per frame, the true
// ghosts visible and found and, under the axis, the model ghosts matched to none (without truth:
// the model ghosts).
cv::Mat evaluationPlot(const Evaluation& evaluation);

// `flarekit fit-ceiling --sheets DIR`: DIR/ceiling_<angle>.png per measured frame, noise-free flare
// | the model's ceiling | |flare − ceiling| on one logarithmic scale (as the contact sheets),
// written atomically.
void writeCeilingSheets(const std::filesystem::path& dir, const ModelCeiling& ceiling);

}  // namespace flarekit::fit
