#include "common/light_spot.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "common/image.h"
#include "common/robust_statistics.h"

namespace flarekit {
namespace {

// kSigmaPerMad / √2 × the median absolute difference of horizontal neighbours: the pixel
// noise, which the light's smooth fall-off hardly moves.
double neighbourNoiseSigma(const cv::Mat& lum) {
  std::vector<float> d;
  d.reserve(lum.total() / 2);
  for (int y = 0; y < lum.rows; ++y) {
    const float* p = lum.ptr<float>(y);
    for (int x = 0; x + 1 < lum.cols; x += 2) d.push_back(std::abs(p[x + 1] - p[x]));
  }
  if (d.empty()) return 0;
  return kSigmaPerMad / std::numbers::sqrt2 * upperMedian(d);
}

}  // namespace

double lightFluxRadiusPx(cv::Size size) { return std::hypot(size.width, size.height) / 8.0; }

LightSpot measureLightSpot(const cv::Mat& image, const cv::Mat& saturated, double flux_radius_px) {
  LightSpot s;
  if (image.empty()) return s;
  const cv::Mat lum = luminance(image);
  cv::Mat clipped;
  if (!saturated.empty()) {
    cv::Mat sat1 = saturated.channels() > 1 ? luminance(saturated) : saturated;
    cv::compare(sat1, 0, clipped, cv::CMP_GT);
  } else {
    clipped = cv::Mat::zeros(lum.size(), CV_8U);
  }
  s.flux_radius_px = flux_radius_px > 0 ? flux_radius_px : lightFluxRadiusPx(lum.size());
  s.noise_sigma = neighbourNoiseSigma(lum);
  double peak = 0;
  cv::Point at;
  cv::minMaxLoc(lum, nullptr, &peak, nullptr, &at);
  const bool any_clipped = cv::countNonZero(clipped) > 0;
  if (!any_clipped && !(peak > 50 * s.noise_sigma && peak > 0)) return s;
  // The core: pixels at least half the peak (clipped ones count as brightest), connected to the
  // brightest.
  cv::Mat core = (lum >= 0.5 * peak) | clipped;
  cv::Mat labels;
  cv::connectedComponents(core, labels, 8, CV_32S);
  const int label = labels.at<int>(at);
  // Its centroid weighted by the luminance (a clipped pixel weighs as the peak).
  double sx = 0, sy = 0, sw = 0, n = 0;
  for (int y = 0; y < labels.rows; ++y) {
    const int* l = labels.ptr<int>(y);
    const float* p = lum.ptr<float>(y);
    const uchar* c = clipped.ptr<uchar>(y);
    for (int x = 0; x < labels.cols; ++x)
      if (l[x] == label) {
        const double w = c[x] ? peak : std::max(0.0f, p[x]);
        sx += w * (x + 0.5);
        sy += w * (y + 0.5);
        sw += w;
        n += 1;
      }
  }
  s.found = true;
  s.peak = peak;
  s.center = {sx / sw, sy / sw};
  s.half_max_radius_px = std::sqrt(n / std::numbers::pi);
  const double r = s.flux_radius_px;
  s.cut = s.center.x - r < 0 || s.center.y - r < 0 || s.center.x + r > lum.cols ||
          s.center.y + r > lum.rows;
  const int y0 = std::max(0, static_cast<int>(std::floor(s.center.y - r)));
  const int y1 = std::min(lum.rows - 1, static_cast<int>(std::ceil(s.center.y + r)));
  const int x0 = std::max(0, static_cast<int>(std::floor(s.center.x - r)));
  const int x1 = std::min(lum.cols - 1, static_cast<int>(std::ceil(s.center.x + r)));
  double flux = 0;
  for (int y = y0; y <= y1; ++y) {
    const float* p = lum.ptr<float>(y);
    const uchar* c = clipped.ptr<uchar>(y);
    for (int x = x0; x <= x1; ++x) {
      if (std::hypot(x + 0.5 - s.center.x, y + 0.5 - s.center.y) > r) continue;
      flux += p[x];
      if (c[x]) ++s.saturated;
    }
  }
  s.flux = flux;
  return s;
}

}  // namespace flarekit
