// Walch 2018 §3.5 estimators on small hand-made overlays, against values worked out by hand.
#include "predict/estimators.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flarekit::predict {
namespace {

TEST(Estimators, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(EstimatorOptions{}.IsValid(&error)) << error;
  EXPECT_FALSE(EstimatorOptions{.log_epsilon = 0}.IsValid(&error));
}

TEST(Estimators, TwoByTwoOverlayOverUniformScene) {
  // F = [0 1; 2 5], R = 1 everywhere, δ = 1 so the logarithms are easy:
  //   min 0, max 5, sum 8, mean 2;
  //   L̄(R) = exp(log 2) = 2, L̄(F) = (1·2·3·6)^(1/4) = √6, ratio 2/√6;
  //   contrast without flare (1+1)/(1+1) = 1, with flare R+F = [1 2; 3 6]: (6+1)/(1+1) = 3.5.
  const cv::Mat f = (cv::Mat_<float>(2, 2) << 0, 1, 2, 5);
  const cv::Mat r(2, 2, CV_32FC1, cv::Scalar(1));
  const Estimators e = computeEstimators(f, r, {.log_epsilon = 1.0});
  EXPECT_DOUBLE_EQ(e.min, 0);
  EXPECT_DOUBLE_EQ(e.max, 5);
  EXPECT_DOUBLE_EQ(e.sum, 8);
  EXPECT_DOUBLE_EQ(e.mean, 2);
  EXPECT_NEAR(e.log_average_ratio, 2 / std::sqrt(6.0), 1e-12);
  EXPECT_NEAR(e.contrast_without_flare, 1.0, 1e-12);
  EXPECT_NEAR(e.contrast_with_flare, 3.5, 1e-12);
  EXPECT_NEAR(e.contrast_ratio, 1 / 3.5, 1e-12);
  // The uniform-level overload agrees.
  const Estimators u = computeEstimators(f, 1.0, {.log_epsilon = 1.0});
  EXPECT_NEAR(u.log_average_ratio, e.log_average_ratio, 1e-12);
  EXPECT_NEAR(u.contrast_ratio, e.contrast_ratio, 1e-12);
}

TEST(Estimators, FlareInTheShadowsLowersContrast) {
  // Scene [1 9; 1 9] (contrast (9+δ)/(1+δ)); flare 1 on the dark pixels only: [2 9; 2 9].
  // δ = 1: ideal 10/2 = 5, real 10/3, ratio 1.5 (> 1: the flare cost contrast).
  const cv::Mat r = (cv::Mat_<float>(2, 2) << 1, 9, 1, 9);
  const cv::Mat f = (cv::Mat_<float>(2, 2) << 1, 0, 1, 0);
  const Estimators e = computeEstimators(f, r, {.log_epsilon = 1.0});
  EXPECT_NEAR(e.contrast_without_flare, 5.0, 1e-12);
  EXPECT_NEAR(e.contrast_with_flare, 10.0 / 3.0, 1e-12);
  EXPECT_NEAR(e.contrast_ratio, 1.5, 1e-12);
  // L̄(R) = √(2·10) = √20, L̄(F) = √(2·1) = √2: ratio √10.
  EXPECT_NEAR(e.log_average_ratio, std::sqrt(10.0), 1e-12);
}

TEST(Estimators, ColourImagesUseRec709Luminance) {
  // Pure green 1 has luminance 0.7152; pure blue 2 has 0.1444.
  cv::Mat f(1, 2, CV_32FC3);
  f.at<cv::Vec3f>(0, 0) = {0, 1, 0};
  f.at<cv::Vec3f>(0, 1) = {0, 0, 2};
  const Estimators e = computeEstimators(f, 0.0);
  EXPECT_NEAR(e.max, 0.7152, 1e-6);
  EXPECT_NEAR(e.min, 0.1444, 1e-6);
  EXPECT_NEAR(e.sum, 0.8596, 1e-6);
}

TEST(Estimators, MismatchedImagesAreRejected) {
  EXPECT_THROW(computeEstimators(cv::Mat(2, 2, CV_32FC1), cv::Mat(3, 2, CV_32FC1)), std::invalid_argument);
  EXPECT_THROW(computeEstimators(cv::Mat(), 1.0), std::invalid_argument);
  EXPECT_THROW(computeEstimators(cv::Mat(2, 2, CV_8UC1), 1.0), std::invalid_argument);
}

TEST(Estimators, NamesRoundTrip) {
  for (Estimator e : allEstimators()) {
    Estimator parsed;
    ASSERT_TRUE(parseEstimator(toString(e), &parsed));
    EXPECT_EQ(parsed, e);
  }
  Estimator x;
  EXPECT_FALSE(parseEstimator("median", &x));
}

TEST(Percentile, MidRankOfHandCountedCases) {
  const std::vector<double> d = {1, 2, 3, 4};
  EXPECT_DOUBLE_EQ(percentile(d, 0), 0);
  EXPECT_DOUBLE_EQ(percentile(d, 2.5), 50);
  EXPECT_DOUBLE_EQ(percentile(d, 2), 37.5);  // one below, one equal: (1 + 0.5) / 4
  EXPECT_DOUBLE_EQ(percentile(d, 9), 100);
  EXPECT_DOUBLE_EQ(percentile({5, 5, 5}, 5), 50);
  EXPECT_TRUE(std::isnan(percentile({}, 1)));
}

TEST(Spearman, HandComputedRankCorrelations) {
  // Same order: 1; reversed: −1.
  EXPECT_DOUBLE_EQ(spearmanCorrelation({1, 2, 3, 4}, {10, 20, 30, 400}), 1.0);
  EXPECT_DOUBLE_EQ(spearmanCorrelation({1, 2, 3, 4}, {4, 3, 2, 1}), -1.0);
  // Ranks (1 2 3 4 5) against (2 1 4 3 5): Σd² = 4, ρ = 1 − 6·4 / (5·24) = 0.8.
  EXPECT_NEAR(spearmanCorrelation({1, 2, 3, 4, 5}, {0.2, 0.1, 0.4, 0.3, 0.5}), 0.8, 1e-12);
  // Ties take the mean rank: (1, 2.5, 2.5, 4) against (1 2 3 4), Pearson of the ranks:
  // deviations (−1.5, 0, 0, 1.5) and (−1.5, −0.5, 0.5, 1.5): Σ = 4.5, √(4.5 · 5) = √22.5.
  EXPECT_NEAR(spearmanCorrelation({1, 5, 5, 9}, {1, 2, 3, 4}), 4.5 / std::sqrt(22.5), 1e-12);
  EXPECT_TRUE(std::isnan(spearmanCorrelation({1, 1, 1}, {1, 2, 3})));
  EXPECT_THROW(spearmanCorrelation({1}, {1}), std::invalid_argument);
  EXPECT_THROW(spearmanCorrelation({1, 2}, {1, 2, 3}), std::invalid_argument);
}

}  // namespace
}  // namespace flarekit::predict
