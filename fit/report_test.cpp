// Tests of the pictures a person looks at after a fit-eval: the plot draws each frame's PSNR at its
// height and the model's ceiling only where the evaluation has one.
#include "fit/report.h"

#include <gtest/gtest.h>

namespace flarekit::fit {
namespace {

// Rows of pixels in column `x` of `plot` that have the colour `bgr` (within 40 per channel).
std::vector<int> rowsOfColour(const cv::Mat& plot, int x, cv::Vec3b bgr) {
  std::vector<int> rows;
  for (int y = 0; y < plot.rows; ++y) {
    const cv::Vec3b p = plot.at<cv::Vec3b>(y, x);
    if (std::abs(p[0] - bgr[0]) < 40 && std::abs(p[1] - bgr[1]) < 40 &&
        std::abs(p[2] - bgr[2]) < 40)
      rows.push_back(y);
  }
  return rows;
}

// Columns of `plot` holding a pixel of colour `bgr` within the rows [y0, y1).
int columnsOfColour(const cv::Mat& plot, int y0, int y1, cv::Vec3b bgr) {
  int n = 0;
  for (int x = 0; x < plot.cols; ++x) {
    bool any = false;
    for (int y : rowsOfColour(plot, x, bgr)) any = any || (y >= y0 && y < y1);
    n += any;
  }
  return n;
}

TEST(EvaluationPlot, DrawsEachFramesPsnrAtItsHeightAndTheCeilingWhereGiven) {
  Evaluation ev;
  ev.has_truth = true;
  for (auto [angle, psnr] : std::vector<std::pair<double, double>>{{0, 10}, {10, 30}, {20, 20}}) {
    FrameEvaluation f;
    f.angle_deg = angle;
    f.psnr_db = psnr;
    f.true_ghosts_visible = 2;
    f.true_ghosts_found = 1;
    f.model_ghosts = 2;
    f.model_ghosts_matched = 1;
    ev.frames.push_back(f);
  }
  const cv::Vec3b curve(180, 90, 20), ceiling(0, 130, 255), found(60, 160, 50),
      unmatched(50, 50, 210), pieces(160, 60, 160);
  const cv::Mat plot = evaluationPlot(ev);
  ASSERT_EQ(plot.type(), CV_8UC3);
  // The plot spans the angles: the frames at 0°, 10° and 20° sit at its left end, middle and right
  // end; each frame's point is where the curve's pixels are in its column, higher for a higher
  // PSNR.
  auto pointRow = [&](int x) {
    const std::vector<int> rows = rowsOfColour(plot, x, curve);
    EXPECT_FALSE(rows.empty()) << "no curve in column " << x;
    return rows.empty() ? -1 : rows[rows.size() / 2];
  };
  const int left = 60, right = 60 + 870, middle = (left + right) / 2;
  const int at10 = pointRow(left + 1), at30 = pointRow(middle), at20 = pointRow(right - 1);
  EXPECT_LT(at30, at20);
  EXPECT_LT(at20, at10);
  // Equal steps of PSNR are equal steps of height (20 → 30 dB as 10 → 20 dB, within a pixel's
  // rounding and the point's size).
  EXPECT_NEAR(at10 - at20, at20 - at30, 3);
  // Below: each frame's found ghost above the axis, its unmatched model ghost below; no ceiling.
  EXPECT_EQ(rowsOfColour(plot, middle, found).empty(), false);
  EXPECT_EQ(rowsOfColour(plot, middle, unmatched).empty(), false);
  EXPECT_EQ(rowsOfColour(plot, middle, pieces).empty(), true);
  EXPECT_EQ(columnsOfColour(plot, 40, 340, ceiling), 0);
  // An unmatched model ghost that is a piece of a true ghost is drawn apart from one that is not.
  ev.frames[1].model_ghosts = 3;
  ev.frames[1].model_ghosts_pieces = 1;
  const cv::Mat with_pieces = evaluationPlot(ev);
  const std::vector<int> piece_rows = rowsOfColour(with_pieces, middle, pieces);
  const std::vector<int> other_rows = rowsOfColour(with_pieces, middle, unmatched);
  ASSERT_FALSE(piece_rows.empty());
  ASSERT_FALSE(other_rows.empty());
  EXPECT_LT(piece_rows.back(), other_rows.front());  // the pieces next to the axis, the rest below
  EXPECT_TRUE(rowsOfColour(with_pieces, left + 1, pieces).empty());
  ev.frames[1].model_ghosts = 2;
  ev.frames[1].model_ghosts_pieces = 0;

  // With the ceiling measured at 10°: its marker in that frame's column, above the frame's point.
  ev.frames[1].ceiling_psnr_db = 40;
  const cv::Mat with = evaluationPlot(ev);
  const std::vector<int> marker =
      rowsOfColour(with, middle - 4, ceiling);  // the marker's left side
  const std::vector<int> point = rowsOfColour(with, middle, curve);
  ASSERT_FALSE(marker.empty());
  ASSERT_FALSE(point.empty());
  EXPECT_LT(marker.back(), point.front());
  EXPECT_LE(columnsOfColour(with, 40, 340, ceiling), 12);  // one marker, no more
}

}  // namespace
}  // namespace flarekit::fit
