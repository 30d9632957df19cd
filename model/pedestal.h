#pragma once
// The pedestal of a frame: the smooth glow under the ghosts, summed from veils each too faint for
// the fitter to find and what is left of the ones it found. Not part of the model of Walch et al.
// 2018, ours. The glow is smooth but not flat, so a quadratic rather than a constant (`flarekit
// fit-ceiling --fit-above N [--quadratic-pedestal]` measures what each can describe).
//
// A quadratic in the capture's pixel coordinates, centred and scaled by the capture width W:
//   u = (x − W/2) / W,  v = (y − H/2) / W,
//   P_c(x, y) = p00 + p10·u + p01·v + p20·u² + p11·u·v + p02·v²   per channel c,
// evaluated at the nearest point of the capture's frame [0, W] × [0, H], so that a view wider than
// the capture (a prediction's scene camera) holds the border's value instead of extrapolating.
// It may be negative where it corrects the ghosts under it; drawn, it is added to their image and
// the sum clamped at 0 (light is not negative). Terms are named "P00", "P10", "P01", "P20", "P11",
// "P02" (the powers of u and v), with "_R", "_G", "_B" appended for RGB, as ghost_shape.h names
// Ib and Ii.

#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/model_renderer.h"

namespace flarekit::model {

inline constexpr int kPedestalTerms = 6;

// The terms (1, u, v, u², uv, v²) at capture pixel `p` of a capture of `capture_size` (p is not
// clamped here).
std::array<double, kPedestalTerms> pedestalTerms(cv::Point2d p, cv::Size capture_size);

// Term `index` in [0, kPedestalTerms · channels) (channel-major: all of R's terms, then G's …).
std::string pedestalTermName(int index, int channels);
std::vector<std::string> pedestalTermNames(int channels);

// One frame's pedestal. Plain data; an empty coefficient vector is no pedestal.
struct Pedestal {
  int channels = 1;                  // 1 or 3
  std::vector<double> coefficients;  // kPedestalTerms × channels, channel-major; or empty

  bool empty() const { return coefficients.empty(); }
  // P_c at capture pixel `p`, the capture being `capture_size`: taken at the nearest point of the
  // capture's frame, and not clamped at 0 (it may be negative).
  double at(cv::Point2d p, cv::Size capture_size, int channel) const;
  // Adds the pedestal to `image` (CV_32FC(channels): the ghosts' image), whose pixel centres map
  // to the capture's pixels through `view` (modelFromImage) as renderGhosts maps them, and clamps
  // the sum at 0. Leaves `image` as it is when empty.
  void addTo(cv::Mat& image, cv::Size capture_size, const ViewTransform& view = {}) const;
  // The pedestal over the whole capture, CV_32FC(channels), not clamped (zeros when empty).
  cv::Mat image(cv::Size capture_size) const;
};

}  // namespace flarekit::model
