#pragma once
// The light's own image, the same in every frame that shows it and moved with the light: at each
// offset from the light's centre, a low percentile over those frames keeps it and drops the ghosts
// (which move at other rates), less what lies at the window's edge (the veils under it). As
// fit/horizon.h's LightPattern, but sampled and put back at the light's sub-pixel centre
// (bilinear): a whole-pixel alignment leaves the steep flanks of the light's core behind, as
// bright as the ghosts beside it, and flips by a pixel where a centre sits on a pixel border.

#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::metrics {

struct SubpixelPattern {
  cv::Mat image;  // CV_32F, (2r + 1)², its centre at the light's centre; empty without one
  int radius_px = 0;

  // The pattern in a frame of `size` with the light at `c` (0 beyond the pattern).
  cv::Mat at(cv::Size size, cv::Point2d c) const;
};

// The pattern from frames' luminance `lums` with the light at `centres`: each offset's
// `percentile` over the frames that show it (at least `min_frames`), within `radius_px`.
SubpixelPattern measurePattern(const std::vector<const cv::Mat*>& lums, const std::vector<cv::Point2d>& centres,
                               int radius_px = 80, double percentile = 0.2, int min_frames = 5);

// Where the light lies when nothing measured it (beyond the frame's edge, or its core cut): the
// position along the horizon at which the pattern best matches what the frame shows of the light
// (its tail over the edge), within ±`reach_px` of `guess`. The fit's curve of the light's centres
// extrapolates beyond the frame by several pixels, which leaves the light's tail at the edge as
// bright as a ghost.
cv::Point2d registerLight(const SubpixelPattern& pattern, const cv::Mat& lum, const cv::Mat& known,
                          cv::Point2d guess, double floor_value, double reach_px = 24);

}  // namespace flarekit::metrics
