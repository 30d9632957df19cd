#pragma once
// `flarekit fit --report DIR`: what a person checks after a fit.
//   DIR/summary.json            the FitSummary, every ghost's range, key frame, end reasons, and
//                               how often the model could not describe it (caustics, folds)
//   DIR/ghost_<id>.csv          the ghost's track: angle, every parameter, residual RMS, peak,
//                               unexplained flag, per fitted frame
//   DIR/frame_fits.json         every frame's fits (fit/frame_fits.h), which fit-eval measures
//                               like a model
//   DIR/contact_<angle>.png     for sampled frames: capture | the frame's fits | model |
//                               |capture − model|, on one shared logarithmic scale (decades from
//                               the noise floor to the peak)
// All files are written atomically.

#include <filesystem>

#include "fit/evaluation.h"
#include "fit/fit_capture.h"
#include "fit/frames.h"

namespace flarekit::fit {

struct ReportOptions {
  int contact_sheets = 8;  // frames sampled evenly over the range for contact sheets (≥ 0)
  bool IsValid(std::string* error) const;
};

void writeFitReport(const std::filesystem::path& dir, const FitResult& result,
                    const FrameStack& stack, const ReportOptions& options = {});

// The contact-sheet image (8-bit BGR) of one frame: capture | fits | model | |capture − model|.
cv::Mat contactSheet(const cv::Mat& capture, const cv::Mat& fits_image, const cv::Mat& model_image,
                     double noise_sigma);

// `flarekit fit-eval --plot FILE`: the evaluation over the capture's angles, 8-bit BGR. Above, each
// frame's PSNR against the noise-free flare (against the capture without truth) and, where the
// evaluation has one (Evaluation::setCeiling), the model's ceiling; below, per frame, the true
// ghosts visible and found and, under the axis, the model ghosts matched to none (without truth:
// the model ghosts).
cv::Mat evaluationPlot(const Evaluation& evaluation);

// `flarekit fit-ceiling --sheets DIR`: DIR/ceiling_<angle>.png per measured frame, noise-free flare
// | the model's ceiling | |flare − ceiling| on one logarithmic scale (as the contact sheets),
// written atomically.
void writeCeilingSheets(const std::filesystem::path& dir, const ModelCeiling& ceiling);

}  // namespace flarekit::fit
