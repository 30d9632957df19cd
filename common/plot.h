#pragma once
// Line and bar plots drawn with OpenCV for the reports' PNG pictures (fit/report.h's evaluation
// plot, metrics/report.h's plots over the light angle): a panel maps data coordinates onto a pixel
// rectangle and draws its frame, grid and tick labels.

#include <string>

#include <opencv2/core.hpp>

namespace flarekit {

// A tick step of 1, 2 or 5 × 10^k giving about `count` ticks over `range` (> 0).
double plotTickStep(double range, int count);
// A tick's label: up to four significant digits, 0 for values within 1e-9 of it.
std::string plotTickLabel(double v);

// One panel of a plot (8-bit BGR image).
struct PlotPanel {
  cv::Rect area;   // the panel's pixels
  double x0, x1;   // data range along x (x0 < x1)
  double y0, y1;   // along y (y0 < y1); log10 of the data for a logarithmic axis

  int px(double x) const;
  int py(double y) const;
  // Grid, frame, tick labels and the y label above the panel. `x_labels`: label the x ticks
  // under the panel. `y_log10`: the y values are decades (log10): ticks at whole decades (every
  // second or more when they crowd), labelled 1e-3, 1e-4, …
  void drawAxes(cv::Mat& image, const std::string& y_label, bool x_labels,
                bool y_log10 = false) const;
};

// The k-th series' colour (BGR): eight well-separated colours, then again.
cv::Scalar plotSeriesColour(int k);

}  // namespace flarekit
