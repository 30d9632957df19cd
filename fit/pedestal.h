#pragma once
// Fitting a frame's pedestal (model/pedestal.h): the quadratic closest to what the fitted ghosts
// leave of a frame. It is linear in its terms, so iteratively reweighted least squares solves it
// without a solver. The model fit (fit/model_fit.h) fits one to every frame under the model's
// ghosts; the frame fits solve theirs with the ghosts' shades (fit/shade.h).

#include <string>

#include <opencv2/core.hpp>

#include "model/pedestal.h"

namespace flarekit::fit {

struct PedestalFitOptions {
  // Residuals beyond this many noise σ from the pedestal do not count (Tukey's biweight, weighed
  // first against the residual's median), so that the light's remains or a ghost the fitter
  // missed do not tilt the glow; 0: plain least squares (≥ 0).
  double outlier_sigma = 6;
  // Reweighting passes (≥ 1).
  int iterations = 8;
  // Every step-th pixel in x and y is sampled (≥ 1): the glow is smooth.
  int step = 2;

  bool IsValid(std::string* error) const;
};

// The pedestal closest to `residual` (CV_32FC(channels)) over the non-zero pixels of `valid`
// (CV_8U, same size). `residual` may be a level of the capture: pixel (i, j) is centred at
// factor · (i + 0.5, j + 0.5) in capture pixels, the capture being `capture_size`. With no valid
// pixel, every term is 0. `noise_sigma`: the residual's noise σ (the outliers' scale; ≤ 0 gives
// least squares).
model::Pedestal fitPedestal(const cv::Mat& residual, const cv::Mat& valid, cv::Size capture_size,
                            int factor, double noise_sigma, const PedestalFitOptions& options = {});

}  // namespace flarekit::fit
