#include "render/spectrum.h"

#include <gtest/gtest.h>

namespace flarekit::render {
namespace {

TEST(Spectrum, CieTableHasEqualIntegralsAndItsPeaks) {
  // The CIE 1931 functions are scaled so that an equal-energy spectrum has X = Y = Z.
  cv::Vec3d sum(0, 0, 0);
  for (double l = 380; l <= 780; l += 1) sum += cieColorMatching(l);
  EXPECT_NEAR(sum[0] / sum[1], 1.0, 0.005);
  EXPECT_NEAR(sum[2] / sum[1], 1.0, 0.005);
  EXPECT_NEAR(sum[1], 106.86, 0.3);  // ∫ ȳ dλ
  EXPECT_NEAR(cieColorMatching(560)[1], 0.995, 1e-9);
  EXPECT_NEAR(cieColorMatching(555)[1], 0.994975, 1e-9);  // linear between the 10 nm rows
  EXPECT_EQ(cieColorMatching(300)[1], 0.0);
}

TEST(Spectrum, RgbModeUsesThreeWavelengths) {
  const auto s = spectralSamples(0);
  ASSERT_EQ(s.size(), 3u);
  EXPECT_EQ(s[0].wavelength_nm, 650);
  EXPECT_EQ(s[1].wavelength_nm, 510);
  EXPECT_EQ(s[2].wavelength_nm, 475);
  EXPECT_EQ(s[0].rgb_weight, cv::Vec3f(1, 0, 0));
}

TEST(Spectrum, FlatSpectrumIsNeutralWithUnitLuminance) {
  for (int n : {4, 16, 40}) {
    const auto s = spectralSamples(n);
    ASSERT_EQ(static_cast<int>(s.size()), n);
    cv::Vec3f rgb(0, 0, 0);
    for (const auto& x : s) rgb += x.rgb_weight;
    const double y = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
    EXPECT_NEAR(y, 1.0, 1e-3) << n;
    // Equal-energy white, XYZ = (1, 1, 1), is (1.2048, 0.9484, 0.9087) in linear sRGB (the
    // 4-sample Riemann sum is too coarse to say so).
    if (n < 16) continue;
    EXPECT_NEAR(rgb[0], 1.2048, 0.02) << n;
    EXPECT_NEAR(rgb[1], 0.9484, 0.02) << n;
    EXPECT_NEAR(rgb[2], 0.9087, 0.02) << n;
  }
  // A red wavelength is red.
  const auto s = spectralSamples(40);
  const auto& red = s[30];  // 685 nm
  EXPECT_GT(red.rgb_weight[0], 10 * std::abs(red.rgb_weight[2]));
}

TEST(Spectrum, BandsCoverWhatEachSampleStandsFor) {
  const auto mean_nm = [](const std::vector<BandWavelength>& band) {
    double sw = 0, swl = 0;
    for (const auto& b : band) {
      EXPECT_GT(b.weight, 0);
      EXPECT_GE(b.wavelength_nm, 380);
      EXPECT_LE(b.wavelength_nm, 780);
      sw += b.weight;
      swl += b.weight * b.wavelength_nm;
    }
    return swl / sw;
  };
  // RGB mode: each channel's sRGB colour-matching function, 5 nm apart; red lies beyond green,
  // green beyond blue (their positive lobes peak near 600, 530 and 450 nm).
  const double r = mean_nm(sampleBand(0, 0)), g = mean_nm(sampleBand(0, 1)), b = mean_nm(sampleBand(0, 2));
  EXPECT_GT(r, 580);
  EXPECT_GT(r, g + 30);
  EXPECT_GT(g, b + 30);
  EXPECT_LT(b, 480);
  EXPECT_GT(sampleBand(0, 1).size(), 20u);
  // Spectral mode: sample k's bin, evenly; a bin narrower than the step is its own wavelength.
  const auto s = spectralSamples(8);
  for (int k = 0; k < 8; ++k) {
    const auto band = sampleBand(8, k);
    ASSERT_EQ(band.size(), 10u);  // 50 nm bins at 5 nm
    EXPECT_NEAR(mean_nm(band), s[static_cast<size_t>(k)].wavelength_nm, 1e-9);
    EXPECT_NEAR(band.front().wavelength_nm, 380 + 50 * k + 2.5, 1e-9);
  }
  const auto fine = sampleBand(200, 7);
  ASSERT_EQ(fine.size(), 1u);
  EXPECT_NEAR(fine[0].wavelength_nm, spectralSamples(200)[7].wavelength_nm, 1e-9);
}

}  // namespace
}  // namespace flarekit::render
