#include "model/pedestal.h"

#include <gtest/gtest.h>

#include <numbers>

namespace flarekit::model {
namespace {

const cv::Size kCapture(200, 100);

// p00 + p20·u²: p00 at the centre, p00 + p20 / 4 at the left and right edges.
Pedestal bowl(double p00, double p20) { return Pedestal{1, {p00, 0, 0, p20, 0, 0}}; }

cv::Mat drawn(const Pedestal& p, cv::Mat under = {}) {
  cv::Mat image =
      under.empty() ? cv::Mat(cv::Mat::zeros(kCapture, CV_32FC(p.channels))) : under.clone();
  p.addTo(image, kCapture);
  return image;
}

TEST(Pedestal, IsAQuadraticInTheCaptureWidthsFromItsCentre) {
  const Pedestal p{1, {0.1, 0.2, 0.3, 0.4, 0.5, 0.6}};
  // At (150, 75): u = 0.25, v = 0.125.
  const double u = 0.25, v = 0.125;
  EXPECT_NEAR(p.at({150, 75}, kCapture, 0),
              0.1 + 0.2 * u + 0.3 * v + 0.4 * u * u + 0.5 * u * v + 0.6 * v * v, 1e-15);
  EXPECT_DOUBLE_EQ(bowl(0.5, -1).at({100, 50}, kCapture, 0), 0.5);
  EXPECT_DOUBLE_EQ(bowl(0.5, -1).at({0, 50}, kCapture, 0), 0.25);
  EXPECT_EQ(pedestalTermName(4, 1), "P11");
  EXPECT_EQ(pedestalTermName(6 + 5, 3), "P02_G");
}

TEST(Pedestal, HoldsTheBordersValueBeyondTheCapture) {
  const Pedestal p = bowl(0.5, -1);
  EXPECT_DOUBLE_EQ(p.at({-300, 50}, kCapture, 0), p.at({0, 50}, kCapture, 0));
  EXPECT_DOUBLE_EQ(p.at({500, 400}, kCapture, 0), p.at({200, 100}, kCapture, 0));
}

TEST(Pedestal, CorrectsTheGhostsUnderItButDrawsNoNegativeLight) {
  // Negative at the edges: it takes light from the ghosts' image there, down to 0, never below.
  const Pedestal p = bowl(0.1, -2);  // 0.1 − 0.5 = −0.4 at the left and right edges
  const cv::Mat under(kCapture, CV_32F, cv::Scalar(0.3));
  const cv::Mat image = drawn(p, under);
  EXPECT_NEAR(image.at<float>(50, 100), 0.4f, 1e-4);  // 0.3 + 0.1 at the centre
  EXPECT_EQ(image.at<float>(50, 0), 0.0f);            // 0.3 − 0.4 + a little
  double low = 0;
  cv::minMaxLoc(drawn(p), &low);
  EXPECT_EQ(low, 0.0);
}

TEST(Pedestal, IsDrawnThroughTheViewAsGhostsAre) {
  const Pedestal p{1, {0.5, 0.3, 0, -0.2, 0, 0}};  // brighter to the right
  const cv::Mat plain = drawn(p);
  EXPECT_NEAR(plain.at<float>(50, 199), p.at({199.5, 50.5}, kCapture, 0), 1e-6);
  // Rolled by 180° about the centre: the brighter side is on the left.
  const ViewTransform half_turn = ViewTransform::roll(std::numbers::pi, {100, 50});
  cv::Mat rolled = cv::Mat::zeros(kCapture, CV_32F);
  p.addTo(rolled, kCapture, half_turn);
  EXPECT_NEAR(rolled.at<float>(50, 0), plain.at<float>(49, 199), 1e-5);
  EXPECT_GT(rolled.at<float>(50, 0), rolled.at<float>(50, 199));
  // Three channels, each its own terms.
  const Pedestal rgb{3, {0.1, 0, 0, 0, 0, 0, 0.2, 0, 0, 0, 0, 0, 0.3, 0, 0, 0, 0, 0}};
  const cv::Vec3f v = drawn(rgb).at<cv::Vec3f>(10, 10);
  EXPECT_FLOAT_EQ(v[0], 0.1f);
  EXPECT_FLOAT_EQ(v[2], 0.3f);
  cv::Mat wrong = cv::Mat::zeros(kCapture, CV_32F);
  EXPECT_THROW(rgb.addTo(wrong, kCapture), std::invalid_argument);
}

TEST(Pedestal, AddsExactlyItsValueAtEachPixelsModelPoint) {
  // addTo is at(view.modelFromImage(pixel centre)) added at every pixel, to the bit, under any view.
  const Pedestal rgb{3, {0.1, 0.2, -0.3, 0.4, 0.5, -0.6, 0.2, -0.1, 0.3, 0.1, -0.2, 0.3, 0.05, 0.3, 0.2, -0.4, 0.1, 0.2}};
  ViewTransform view;
  view.roll_rad = 0.7;
  view.scale = 1.37;
  view.image_center = {120.3, 71.9};
  view.model_center = {96.2, 48.7};
  cv::Mat image(cv::Size(240, 150), CV_32FC3, cv::Scalar::all(0.25));
  rgb.addTo(image, kCapture, view);
  for (int y = 0; y < image.rows; y += 7)
    for (int x = 0; x < image.cols; x += 5) {
      const cv::Point2d q = view.modelFromImage({x + 0.5, y + 0.5});
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(image.at<cv::Vec3f>(y, x)[c], std::max(0.0f, 0.25f + static_cast<float>(rgb.at(q, kCapture, c))))
            << x << "," << y << " channel " << c;
    }
}

}  // namespace
}  // namespace flarekit::model
