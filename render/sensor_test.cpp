#include "render/sensor.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/error.h"

namespace flarekit::render {
namespace {

cv::Mat flat(float value, int channels = 1) {
  return cv::Mat(64, 96, channels == 1 ? CV_32FC1 : CV_32FC3, cv::Scalar::all(value));
}

TEST(Sensor, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(SensorModel{}.IsValid(&error)) << error;
  EXPECT_EQ(SensorModel{}.whiteLevelDn(), 16383.0);
}

TEST(Sensor, SameSeedSameFrameOtherSeedOtherNoise) {
  SensorModel s;
  const cv::Mat r = flat(1e-4f);
  const cv::Mat a = exposeRaw(r, 0.01, s, 7), b = exposeRaw(r, 0.01, s, 7), c = exposeRaw(r, 0.01, s, 8);
  ASSERT_EQ(a.type(), CV_16UC1);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 0.0);
}

TEST(Sensor, MeanAndVarianceFollowShotAndReadNoise) {
  SensorModel s;
  s.base_gain_e_per_dn = 2.0;
  s.read_noise_e = 6.0;
  s.electrons_per_unit_s = 1e6;
  const double exposure = 0.002, radiance = 1.0;  // 2000 electrons
  const cv::Mat raw = exposeRaw(flat(static_cast<float>(radiance)), exposure, s, 1);
  cv::Scalar mean, stddev;
  cv::meanStdDev(raw, mean, stddev);
  const double electrons = radiance * s.electrons_per_unit_s * exposure;
  EXPECT_NEAR(mean[0], s.black_level_dn + electrons / 2.0, 1.0);
  // Var(DN) = (μ_e + σ_read²) / g² (+ 1/12 quantisation).
  const double expected = std::sqrt((electrons + 36.0) / 4.0 + 1.0 / 12.0);
  EXPECT_NEAR(stddev[0], expected, 0.05 * expected);
  // Doubling the ISO halves the electrons per DN: twice the signal above black.
  s.iso = 200;
  const double mean200 = cv::mean(exposeRaw(flat(1.0f), exposure, s, 1))[0];
  EXPECT_NEAR(mean200 - s.black_level_dn, 2 * (mean[0] - s.black_level_dn), 2.0);
}

TEST(Sensor, ClipsAtWhiteAndSitsAtBlackInTheDark) {
  SensorModel s;
  // A full well (60000 e⁻ at 4 e⁻/DN) reads below the ADC's white level...
  const cv::Mat bright = exposeRaw(flat(1e3f), 1.0, s, 3);
  double lo, hi;
  cv::minMaxLoc(bright, &lo, &hi);
  EXPECT_NEAR(hi, 512 + 60000 / 4.0, 6 * (std::sqrt(60000.0) / 4 + 1));
  EXPECT_LT(hi, 16383.0);
  s.iso = 400;  // ... until the gain puts it past white.
  cv::minMaxLoc(exposeRaw(flat(1e3f), 1.0, s, 3), &lo, &hi);
  EXPECT_EQ(lo, 16383.0);
  s.iso = 100;
  s.full_well_e = 0;  // unlimited well: still clipped by the ADC
  cv::minMaxLoc(exposeRaw(flat(1e6f), 1.0, s, 3), &lo, &hi);
  EXPECT_EQ(lo, 16383.0);
  s.read_noise = false;
  const cv::Mat dark = exposeRaw(flat(0.0f), 1.0, s, 3);
  cv::minMaxLoc(dark, &lo, &hi);
  EXPECT_EQ(lo, 512.0);
  EXPECT_EQ(hi, 512.0);
}

TEST(Sensor, BayerSeesOneColourPerPixel) {
  SensorModel s;
  s.color_filter = ColorFilter::kBayerRggb;
  s.shot_noise = s.read_noise = false;
  s.electrons_per_unit_s = 1000;
  cv::Mat rgb(4, 4, CV_32FC3, cv::Scalar(1.0f, 2.0f, 3.0f));  // R, G, B
  const cv::Mat raw = exposeRaw(rgb, 1.0, s, 0);
  auto signal = [&](int x, int y) { return (raw.at<uint16_t>(y, x) - 512.0) * s.gainEPerDn() / 1000; };
  EXPECT_NEAR(signal(0, 0), 1.0, 0.01);  // R
  EXPECT_NEAR(signal(1, 0), 2.0, 0.01);  // G
  EXPECT_NEAR(signal(0, 1), 2.0, 0.01);  // G
  EXPECT_NEAR(signal(1, 1), 3.0, 0.01);  // B
  const cv::Mat expected = expectedRaw(rgb, 1.0, s);
  EXPECT_NEAR(expected.at<float>(1, 1), raw.at<uint16_t>(1, 1), 0.5);
}

TEST(Sensor, RejectsBadInput) {
  SensorModel s;
  EXPECT_THROW(exposeRaw(cv::Mat(), 1.0, s, 0), InputError);
  EXPECT_THROW(exposeRaw(flat(1.0f), -1.0, s, 0), InputError);
  s.bit_depth = 20;
  EXPECT_FALSE(s.IsValid(nullptr));
  EXPECT_THROW(exposeRaw(flat(1.0f), 1.0, s, 0), InputError);
  cv::Mat nan = flat(std::nanf(""));
  EXPECT_NO_THROW(exposeRaw(nan, 1.0, SensorModel{}, 0));
}

}  // namespace
}  // namespace flarekit::render
