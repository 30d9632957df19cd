#include "common/plot.h"

#include <cmath>
#include <iomanip>
#include <sstream>

#include <opencv2/imgproc.hpp>

namespace flarekit {

double plotTickStep(double range, int count) {
  const double raw = range / count, decade = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * decade >= raw) return m * decade;
  return 10 * decade;
}

std::string plotTickLabel(double v) {
  std::ostringstream s;
  s << std::setprecision(4) << (std::abs(v) < 1e-9 ? 0.0 : v);
  return s.str();
}

int PlotPanel::px(double x) const {
  return area.x + static_cast<int>(std::lround((x - x0) / (x1 - x0) * area.width));
}

int PlotPanel::py(double y) const {
  return area.y + area.height - static_cast<int>(std::lround((y - y0) / (y1 - y0) * area.height));
}

void PlotPanel::drawAxes(cv::Mat& image, const std::string& y_label, bool x_labels,
                         bool y_log10) const {
  const cv::Scalar grid(225, 225, 225), ink(60, 60, 60);
  if (y_log10) {
    const int first = static_cast<int>(std::ceil(y0 - 1e-9)), last = static_cast<int>(std::floor(y1 + 1e-9));
    const int every = std::max(1, (last - first + 7) / 8);
    for (int k = first; k <= last; ++k) {
      if ((k - first) % every != 0) continue;
      cv::line(image, {area.x, py(k)}, {area.x + area.width, py(k)}, grid);
      cv::putText(image, "1e" + std::to_string(k), {area.x - 44, py(k) + 4}, cv::FONT_HERSHEY_SIMPLEX,
                  0.4, ink, 1, cv::LINE_AA);
    }
  } else {
    const double ys = plotTickStep(y1 - y0, 5);
    for (double y = std::ceil(y0 / ys) * ys; y <= y1 + 1e-9; y += ys) {
      cv::line(image, {area.x, py(y)}, {area.x + area.width, py(y)}, grid);
      cv::putText(image, plotTickLabel(y), {area.x - 42, py(y) + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4,
                  ink, 1, cv::LINE_AA);
    }
  }
  const double xs = plotTickStep(x1 - x0, 10);
  for (double x = std::ceil(x0 / xs) * xs; x <= x1 + 1e-9; x += xs) {
    cv::line(image, {px(x), area.y}, {px(x), area.y + area.height}, grid);
    if (x_labels)
      cv::putText(image, plotTickLabel(x), {px(x) - 8, area.y + area.height + 16},
                  cv::FONT_HERSHEY_SIMPLEX, 0.4, ink, 1, cv::LINE_AA);
  }
  cv::rectangle(image, area, ink);
  cv::putText(image, y_label, {area.x + 4, area.y - 6}, cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1,
              cv::LINE_AA);
}

cv::Scalar plotSeriesColour(int k) {
  // After the Okabe–Ito palette (colour-blind safe), as B, G, R.
  static const cv::Scalar kColours[] = {
      {178, 114, 0},   {0, 94, 213},   {115, 158, 0},  {167, 121, 204},
      {0, 159, 230},   {233, 180, 86}, {66, 228, 240}, {60, 60, 60}};
  return kColours[((k % 8) + 8) % 8];
}

}  // namespace flarekit
