#include "metrics/light_pattern.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

namespace flarekit::metrics {

cv::Mat SubpixelPattern::at(cv::Size size, cv::Point2d c) const {
  if (image.empty()) return cv::Mat::zeros(size, CV_32F);
  cv::Mat mx(size, CV_32F), my(size, CV_32F);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      mx.at<float>(y, x) = static_cast<float>(x + 0.5 - c.x + radius_px);
      my.at<float>(y, x) = static_cast<float>(y + 0.5 - c.y + radius_px);
    }
  cv::Mat out;
  cv::remap(image, out, mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  return out;
}


SubpixelPattern measurePattern(const std::vector<const cv::Mat*>& lums, const std::vector<cv::Point2d>& centres,
                               int radius_px, double percentile, int min_frames) {
  SubpixelPattern p;
  if (static_cast<int>(lums.size()) < min_frames) return p;
  const int side = 2 * radius_px + 1;
  // Each frame's window about its light, NaN beyond the frame.
  std::vector<cv::Mat> windows(lums.size());
  tbb::parallel_for(size_t{0}, lums.size(), [&](size_t k) {
    cv::Mat mx(side, side, CV_32F), my(side, side, CV_32F);
    for (int v = 0; v < side; ++v)
      for (int u = 0; u < side; ++u) {
        mx.at<float>(v, u) = static_cast<float>(centres[k].x - 0.5 + u - radius_px);
        my.at<float>(v, u) = static_cast<float>(centres[k].y - 0.5 + v - radius_px);
      }
    cv::remap(*lums[k], windows[k], mx, my, cv::INTER_LINEAR, cv::BORDER_CONSTANT,
              cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  });
  p.image = cv::Mat::zeros(side, side, CV_32F);
  p.radius_px = radius_px;
  tbb::parallel_for(0, side, [&](int v) {
    std::vector<float> samples;
    for (int u = 0; u < side; ++u) {
      samples.clear();
      for (const auto& w : windows) {
        const float s = w.at<float>(v, u);
        if (std::isfinite(s)) samples.push_back(s);
      }
      if (static_cast<int>(samples.size()) < min_frames) continue;
      const size_t q = static_cast<size_t>(percentile * (samples.size() - 1));
      std::nth_element(samples.begin(), samples.begin() + q, samples.end());
      p.image.at<float>(v, u) = samples[q];
    }
  });
  std::vector<float> edge;
  for (int k = 0; k < side; ++k)
    for (float e : {p.image.at<float>(0, k), p.image.at<float>(side - 1, k), p.image.at<float>(k, 0),
                    p.image.at<float>(k, side - 1)})
      edge.push_back(e);
  std::nth_element(edge.begin(), edge.begin() + edge.size() / 2, edge.end());
  p.image = cv::max(p.image - edge[edge.size() / 2], 0.0f);
  return p;
}

cv::Point2d registerLight(const SubpixelPattern& pattern, const cv::Mat& lum, const cv::Mat& known,
                          cv::Point2d guess, double floor_value, double reach_px) {
  if (pattern.image.empty()) return guess;
  std::vector<cv::Point> pixels;
  for (int y = 0; y < lum.rows; ++y)
    for (int x = 0; x < lum.cols; ++x)
      if (known.at<uchar>(y, x) && lum.at<float>(y, x) > floor_value) pixels.emplace_back(x, y);
  if (pixels.size() < 16) return guess;
  auto cost = [&](double dx) {
    const cv::Mat p = pattern.at(lum.size(), {guess.x + dx, guess.y});
    double s = 0;
    for (const auto& q : pixels) {
      const double d = std::log(lum.at<float>(q)) - std::log(std::max<double>(p.at<float>(q), floor_value));
      s += d * d;
    }
    return s;
  };
  auto search = [&](double from, double to, double step) {
    double best = from, best_cost = std::numeric_limits<double>::infinity();
    for (double dx = from; dx <= to + 1e-9; dx += step)
      if (const double c = cost(dx); c < best_cost) {
        best_cost = c;
        best = dx;
      }
    return best;
  };
  double dx = search(-reach_px, reach_px, 1.0);
  dx = search(dx - 1, dx + 1, 0.1);
  return {guess.x + dx, guess.y};
}

}  // namespace flarekit::metrics
