#include "fit/pedestal.h"

#include <gtest/gtest.h>

#include <limits>

#include <opencv2/imgproc.hpp>

namespace flarekit::fit {
namespace {

const cv::Size kCapture(320, 212);  // divisible by 4, for the level below

// A glow brighter towards the left and the top (as a light beyond the left edge leaves one).
model::Pedestal glow() { return model::Pedestal{1, {0.02, -0.015, -0.004, 0.01, 0.002, -0.006}}; }

cv::Mat drawn(const model::Pedestal& p) {
  cv::Mat image = cv::Mat::zeros(kCapture, CV_32FC(p.channels));
  p.addTo(image, kCapture);
  return image;
}

cv::Mat allValid(cv::Size size) { return cv::Mat(size, CV_8U, cv::Scalar(255)); }

TEST(FitPedestal, FindsTheQuadraticUnderNoiseAndAGhostNotFitted) {
  const model::Pedestal truth = glow();
  cv::Mat frame = drawn(truth);
  cv::Mat noise(kCapture, CV_32F);
  cv::randn(noise, 0, 1e-3);
  frame += noise;
  // A ghost the fitter missed, 50 σ bright: least squares lifts the glow under it, the robust fit
  // does not.
  cv::circle(frame, {240, 100}, 30, cv::Scalar(0.05), cv::FILLED);
  const cv::Mat valid = allValid(kCapture);
  const model::Pedestal robust = fitPedestal(frame, valid, kCapture, 1, 1e-3);
  PedestalFitOptions plain;
  plain.outlier_sigma = 0;
  const model::Pedestal squares = fitPedestal(frame, valid, kCapture, 1, 1e-3, plain);
  const double robust_error = cv::norm(drawn(robust), drawn(truth), cv::NORM_INF);
  const double squares_error = cv::norm(drawn(squares), drawn(truth), cv::NORM_INF);
  EXPECT_LT(robust_error, 1e-3);  // within the noise σ everywhere
  EXPECT_GT(squares_error, 3 * robust_error);
}

TEST(FitPedestal, ReadsALevelOfTheCaptureAndLeavesInvalidPixelsOut) {
  const model::Pedestal truth = glow();
  // The capture at a quarter of its size: pixel (i, j) centred at 4·(i + 0.5, j + 0.5).
  cv::Mat level;
  cv::resize(drawn(truth), level, {kCapture.width / 4, kCapture.height / 4}, 0, 0, cv::INTER_AREA);
  cv::Mat valid = allValid(level.size());
  // Saturated pixels (NaN) are not valid and must not count.
  level(cv::Rect(10, 10, 8, 8)).setTo(std::numeric_limits<float>::quiet_NaN());
  valid(cv::Rect(10, 10, 8, 8)).setTo(0);
  PedestalFitOptions every;
  every.step = 1;
  const model::Pedestal p = fitPedestal(level, valid, kCapture, 4, 1e-4, every);
  EXPECT_LT(cv::norm(drawn(p), drawn(truth), cv::NORM_INF), 2e-5);
  // No valid pixel: no glow.
  const model::Pedestal none =
      fitPedestal(level, cv::Mat::zeros(level.size(), CV_8U), kCapture, 4, 1e-4);
  for (double c : none.coefficients) EXPECT_EQ(c, 0.0);
  PedestalFitOptions bad;
  bad.iterations = 0;
  EXPECT_FALSE(bad.IsValid(nullptr));
  EXPECT_THROW(fitPedestal(level, valid, kCapture, 4, 1e-4, bad), std::invalid_argument);
}

}  // namespace
}  // namespace flarekit::fit
