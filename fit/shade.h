#pragma once
// The shade of a frame's ghosts and its pedestal by linear least squares. With every outline and
// fall-off fixed, a frame's model image is linear in each ghost's Ib and Ii and in the pedestal's
// terms (model/intensity.h, model/pedestal.h), so all of them are solved at once, per channel:
// overlapping ghosts share the light they overlap in, which one at a time they trade freely.
// Robust (Tukey's biweight at outlier_sigma times the residual's robust σ, 1.4826 × its MAD and at
// least the pixel noise, reweighted), and Ib, Ii ≥ 0 (an active set: a negative one is held at 0
// and the rest solved again).

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "model/ghost_shape.h"
#include "model/pedestal.h"

namespace flarekit::fit {

struct ShadeOptions {
  int level = 2;               // solved on k×k averages of the frame (≥ 1)
  double outlier_sigma = 6;    // Tukey's biweight, in the residual's robust σ (> 0)
  int iterations = 3;          // reweighting passes (≥ 1)
  bool pedestal = true;        // solve the pedestal's terms too

  bool IsValid(std::string* error) const;
};

// A frame's shade problem as normal equations in its ghosts' Ib and Ii, per channel, with the
// robust weights of the frame's own solve and the pedestal's terms eliminated (they stay free in
// the frame): the model fit sums them over the frames to solve each ghost's shade polynomials
// at once (fit/model_fit.h), which overlapping ghosts' per-frame values, traded between them
// from frame to frame, cannot give.
struct ShadeEquations {
  std::vector<Eigen::MatrixXd> normal;  // per channel, 2g × 2g: ghost j's Ib at 2j, Ii at 2j + 1
  std::vector<Eigen::VectorXd> rhs;     // per channel, 2g
};

// Sets Ib and Ii of every ghost (channel by channel) and `pedestal` (when options.pedestal) to the
// least-squares values for `image` (the frame, CV_32FC(channels), capture pixels) over its
// `valid` pixels. `noise_sigma`: the frame's pixel noise σ (the outliers' scale). `equations`,
// when given, receives the problem's normal equations (above; empty without valid pixels).
void fitShades(const cv::Mat& image, const cv::Mat& valid, double noise_sigma,
               std::vector<model::GhostParameters>& ghosts, model::Pedestal* pedestal,
               const ShadeOptions& options = {}, ShadeEquations* equations = nullptr);

}  // namespace flarekit::fit
