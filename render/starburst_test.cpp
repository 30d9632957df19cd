#include "render/starburst.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

namespace flarekit::render {
namespace {

// The pattern's radial profile between two spikes, bins r0..r1 from the zero frequency.
std::vector<double> profileBetweenSpikes(const cv::Mat& pattern, int r0, int r1) {
  // A 6-blade iris at rotation 0 has its spikes every 30° from some direction; 15° off the spikes
  // is the middle of the ringing between them. Which direction holds a spike: the brightest ray.
  const double c = pattern.cols / 2;
  auto at = [&](double r, double a) {
    return static_cast<double>(pattern.at<float>(static_cast<int>(std::lround(c + r * std::sin(a))),
                                                 static_cast<int>(std::lround(c + r * std::cos(a)))));
  };
  double spike = 0, best = -1;
  for (int k = 0; k < 360; ++k) {
    const double a = k * std::numbers::pi / 180;
    double sum = 0;
    for (int r = r0; r < r1; ++r) sum += at(r, a);
    if (sum > best) best = sum, spike = a;
  }
  std::vector<double> p;
  for (int r = r0; r <= r1; ++r) p.push_back(at(r, spike + std::numbers::pi / 12));
  return p;
}

// Fringe contrast: the median over the profile of (max − min) / (max + min) in windows of one
// fringe period (4 bins: the iris spans a quarter of the FFT).
double fringeContrast(const std::vector<double>& p) {
  std::vector<double> c;
  for (size_t i = 0; i + 4 < p.size(); ++i) {
    const auto [lo, hi] = std::minmax_element(p.begin() + static_cast<long>(i), p.begin() + static_cast<long>(i) + 5);
    if (*hi > 0) c.push_back((*hi - *lo) / (*hi + *lo));
  }
  std::nth_element(c.begin(), c.begin() + static_cast<long>(c.size() / 2), c.end());
  return c[c.size() / 2];
}

TEST(Starburst, ABandOfWavelengthsBlursOutTheRingingOfOne) {
  const Aperture iris(ApertureShape{});  // 6 blades
  const cv::Mat one = starburstPattern(iris, 256);
  EXPECT_NEAR(cv::sum(one)[0], 1.0, 1e-4);
  double scale_nm = 0;
  const auto band = sampleBand(0, 1);  // the green channel's 5 nm band
  const cv::Mat green = starburstBand(one, band, &scale_nm);
  ASSERT_EQ(green.size(), one.size());
  EXPECT_NEAR(cv::sum(green)[0], 1.0, 1e-4);
  EXPECT_DOUBLE_EQ(scale_nm, band.back().wavelength_nm);
  // The zero frequency stays at the centre, as the brightest bin.
  cv::Point peak;
  cv::minMaxLoc(green, nullptr, nullptr, nullptr, &peak);
  EXPECT_EQ(peak, cv::Point(128, 128));
  // Hullin 2011 §3.3: the single wavelength's fringes are deep (zeros between them), the band's
  // nearly gone.
  const double single = fringeContrast(profileBetweenSpikes(one, 30, 100));
  const double banded = fringeContrast(profileBetweenSpikes(green, 30, 100));
  // (Measured: 0.97 and 0.22; what is left of the band's is the hexagonal texture across the ray.)
  EXPECT_GT(single, 0.8);
  EXPECT_LT(banded, single / 3);
  // One wavelength is a band of one: the pattern itself.
  const BandWavelength only[] = {{510.0, 1.0}};
  const cv::Mat same = starburstBand(one, only, &scale_nm);
  EXPECT_EQ(scale_nm, 510.0);
  EXPECT_LT(cv::norm(same, one, cv::NORM_INF), 1e-9);
  EXPECT_TRUE(starburstBand(one, {}, &scale_nm).empty());
}

// Centroid of channel 0 of a CV_32FC3 image (pixel centres at i + 0.5).
cv::Point2d centroidPx(const cv::Mat& image) {
  double sum = 0, sx = 0, sy = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const double v = image.at<cv::Vec3f>(y, x)[0];
      sum += v;
      sx += v * (x + 0.5);
      sy += v * (y + 0.5);
    }
  return {sx / sum, sy / sum};
}

// The starburst is the light's image: its centroid (the zero frequency, the pattern being point
// symmetric about it) lies on the light's image position whatever that position's sub-pixel offset,
// for each wavelength band's scale. Radii as on the simulated rig (a 320×214 frame's diagonal / 8
// at 550 nm) and wider.
TEST(Starburst, CentroidLiesOnTheLightsImagePosition) {
  const cv::Mat pattern = starburstPattern(Aperture(ApertureShape{}), 256);
  for (int s = 0; s < 3; ++s) {
    double scale_nm = 0;
    const cv::Mat band = starburstBand(pattern, sampleBand(0, s), &scale_nm);
    for (const double radius_550 : {std::hypot(320.0, 214.0) / 8, 100.0}) {
      const double radius = radius_550 * scale_nm / 550.0;
      for (const cv::Point2d at : {cv::Point2d(200.0, 200.0), cv::Point2d(200.37, 199.81),
                                   cv::Point2d(199.5, 200.25)}) {
        cv::Mat image(400, 400, CV_32FC3, cv::Scalar::all(0));
        addStarburst(band, at, radius, 1.0, cv::Vec3f(1, 1, 1), &image);
        const cv::Point2d c = centroidPx(image);
        SCOPED_TRACE(::testing::Message() << "band " << s << ", radius " << radius << " px, at " << at);
        EXPECT_NEAR(cv::sum(image)[0], 1.0, 1e-4);
        EXPECT_NEAR(c.x, at.x, 0.05);
        EXPECT_NEAR(c.y, at.y, 0.05);
      }
    }
  }
}

}  // namespace
}  // namespace flarekit::render
