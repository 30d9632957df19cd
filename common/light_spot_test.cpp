// The light's spot in a light exposure: found above the noise, its centre, peak and flux, and
// what a clipped or cut spot says.
#include "common/light_spot.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flarekit {
namespace {

// A Gaussian spot of total flux `flux` and σ `s` at (cx, cy) on noise of σ `noise`.
cv::Mat spot(cv::Size size, double cx, double cy, double s, double flux, double noise, int seed = 3) {
  cv::Mat m(size, CV_32F);
  cv::theRNG().state = static_cast<uint64_t>(seed);
  cv::randn(m, 0, noise);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double r2 = std::pow(x + 0.5 - cx, 2) + std::pow(y + 0.5 - cy, 2);
      m.at<float>(y, x) += static_cast<float>(flux / (2 * M_PI * s * s) * std::exp(-r2 / (2 * s * s)));
    }
  return m;
}

TEST(LightSpot, CentreFluxAndPeak) {
  const cv::Mat m = spot({160, 107}, 70.3, 50.8, 1.5, 1000, 0.01);
  const LightSpot s = measureLightSpot(m);
  ASSERT_TRUE(s.found);
  EXPECT_TRUE(s.whole());
  EXPECT_NEAR(s.center.x, 70.3, 0.2);
  EXPECT_NEAR(s.center.y, 50.8, 0.2);
  EXPECT_NEAR(s.flux, 1000, 1000 * 0.005);
  EXPECT_NEAR(s.flux_radius_px, std::hypot(160, 107) / 8, 1e-9);
  EXPECT_NEAR(s.peak, 1000 / (2 * M_PI * 1.5 * 1.5), 10);
  EXPECT_NEAR(s.noise_sigma, 0.01, 0.002);
}

TEST(LightSpot, NoiseAloneIsNoLight) {
  const cv::Mat m = spot({160, 107}, -500, 50, 1.5, 1000, 0.01);
  EXPECT_FALSE(measureLightSpot(m).found);
}

TEST(LightSpot, CutAndClippedSpotsAreNotWhole) {
  const cv::Mat edge = spot({160, 107}, 5, 50, 1.5, 1000, 0.01);
  const LightSpot e = measureLightSpot(edge);
  ASSERT_TRUE(e.found);
  EXPECT_TRUE(e.cut);
  EXPECT_FALSE(e.whole());
  const cv::Mat m = spot({160, 107}, 80, 50, 1.5, 1000, 0.01);
  cv::Mat sat = cv::Mat::zeros(m.size(), CV_8U);
  sat.at<uchar>(49, 79) = 1;
  const LightSpot c = measureLightSpot(m, sat);
  EXPECT_EQ(c.saturated, 1);
  EXPECT_FALSE(c.whole());
}

}  // namespace
}  // namespace flarekit
