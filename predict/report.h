#pragma once
// The light planner's report: one self-contained HTML file that opens offline (no scripts, no
// external resources): the composite and overlay as base64 PNG, the severity polar map and the
// timeline as inline SVG written here, the per-light ranking with numbers, the rated estimators,
// and the capture and model the prediction came from.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/flare_model.h"
#include "predict/prediction.h"

namespace flarekit::predict {

// The severity map's colour scale, t in [0, 1] (dark to bright; after matplotlib's "inferno"),
// as R, G, B.
cv::Vec3b severityRampColor(double t);

// RFC 4648 base64 of bytes.
std::string base64(const std::vector<unsigned char>& bytes);

// The severity map as an SVG polar plot: rings of θ, sectors of φ (0° to the left of the image
// centre as the flare convention has it, counter-clockwise as displayed), a colour scale, and the
// lights (in range and out of range) marked by name. `width_px` is the SVG's width.
std::string polarMapSvg(const SeverityMap& map, const std::vector<LightPrediction>& lights,
                        int width_px = 640);

// The timeline as an SVG line plot of severity over time (empty string for no points).
std::string timelineSvg(const std::vector<TimelinePoint>& timeline, Estimator estimator,
                        int width_px = 640);

// The whole page. `composite` and `overlay` are linear images (tone-mapped here).
std::string reportHtml(const PredictionSummary& summary, const model::FlareModel& model,
                       const Scene& scene, const cv::Mat& composite, const cv::Mat& overlay);

}  // namespace flarekit::predict
