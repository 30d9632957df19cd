// The plot panel maps data onto its pixels and draws its axes inside the image.
#include "common/plot.h"

#include <gtest/gtest.h>

namespace flarekit {
namespace {

TEST(Plot, TicksAndMapping) {
  EXPECT_DOUBLE_EQ(plotTickStep(20, 10), 2);
  EXPECT_DOUBLE_EQ(plotTickStep(1, 5), 0.2);
  EXPECT_EQ(plotTickLabel(1e-12), "0");
  EXPECT_EQ(plotTickLabel(2.5), "2.5");
  const PlotPanel p{cv::Rect(10, 20, 100, 50), 0, 10, -6, -1};
  EXPECT_EQ(p.px(0), 10);
  EXPECT_EQ(p.px(10), 110);
  EXPECT_EQ(p.py(-6), 70);
  EXPECT_EQ(p.py(-1), 20);
  cv::Mat image(100, 130, CV_8UC3, cv::Scalar(255, 255, 255));
  p.drawAxes(image, "flux", true, true);
  // The frame is drawn: its corner pixel is ink, not white.
  EXPECT_NE(image.at<cv::Vec3b>(20, 10), cv::Vec3b(255, 255, 255));
  EXPECT_NE(plotSeriesColour(0), plotSeriesColour(1));
  EXPECT_EQ(plotSeriesColour(8), plotSeriesColour(0));
}

}  // namespace
}  // namespace flarekit
