#include "common/image.h"

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "common/testing.h"

namespace flarekit {
namespace {

TEST(Image, LuminanceUsesRec709Weights) {
  cv::Mat rgb(1, 3, CV_32FC3);
  rgb.at<cv::Vec3f>(0, 0) = {1, 0, 0};
  rgb.at<cv::Vec3f>(0, 1) = {0, 1, 0};
  rgb.at<cv::Vec3f>(0, 2) = {0, 0, 1};
  cv::Mat y = luminance(rgb);
  EXPECT_NEAR(y.at<float>(0, 0), 0.2126f, 1e-6);
  EXPECT_NEAR(y.at<float>(0, 1), 0.7152f, 1e-6);
  EXPECT_NEAR(y.at<float>(0, 2), 0.0722f, 1e-6);
}

TEST(Image, TonemapIsMonotoneAndKeepsColourOrder) {
  cv::Mat ramp(1, 100, CV_32FC1);
  for (int i = 0; i < 100; ++i) ramp.at<float>(0, i) = std::pow(10.f, i / 20.f - 2);
  cv::Mat out = tonemapForDisplay(ramp);
  ASSERT_EQ(out.type(), CV_8UC3);
  for (int i = 1; i < 100; ++i) EXPECT_GE(out.at<cv::Vec3b>(0, i)[0], out.at<cv::Vec3b>(0, i - 1)[0]);
  cv::Mat red(1, 1, CV_32FC3, cv::Scalar(1, 0, 0));
  cv::Vec3b p = tonemapForDisplay(red, PreviewOptions{0, 90, 1.0}).at<cv::Vec3b>(0, 0);
  EXPECT_GT(p[2], 0);  // red lands in OpenCV's third (R) channel
  EXPECT_EQ(p[0], 0);
}

TEST(Image, PreviewPngIsWrittenAndReadable) {
  testing::TempDir dir;
  cv::Mat img(20, 30, CV_32FC3, cv::Scalar(0.1, 0.5, 2.0));
  writePreviewPng(dir / "p.png", img);
  cv::Mat back = cv::imread((dir / "p.png").string());
  EXPECT_EQ(back.size(), img.size());
}

TEST(Image, DefaultPreviewOptionsAreValid) {
  std::string why;
  EXPECT_TRUE(PreviewOptions{}.IsValid(&why)) << why;
}

}  // namespace
}  // namespace flarekit
