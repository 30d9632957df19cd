// Walch 2018 Eq. 2 and its exposure-value form.
#include "predict/brightness.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flarekit::predict {
namespace {

TEST(Brightness, Ev100OfKnownSettings) {
  EXPECT_NEAR(ev100({1.0, 100, 1.0}), 0.0, 1e-12);          // f/1, 1 s, ISO 100
  EXPECT_NEAR(ev100({16.0, 100, 1.0 / 100}), std::log2(25600.0), 1e-12);  // "sunny 16"
  EXPECT_NEAR(ev100({2.0, 400, 1.0}), 0.0, 1e-12);          // two stops of aperture, two of ISO
}

TEST(Brightness, SameCameraAndLightGiveOne) {
  const ExposureSettings e{5.6, 200, 0.02};
  const auto b = brightnessScale(e, e, {10, 10});
  EXPECT_NEAR(b.scale, 1.0, 1e-12);
  EXPECT_NEAR(b.log2_scale, 0.0, 1e-12);
}

TEST(Brightness, DoublingTheCaptureExposureLowersLog2BByOne) {
  const ExposureSettings scene{8, 400, 1.0 / 60};
  const LightPower light{10, 37};
  for (double t : {1.0 / 1000, 1.0 / 30, 0.5, 4.0}) {
    const auto b1 = brightnessScale({2.8, 100, t}, scene, light);
    const auto b2 = brightnessScale({2.8, 100, 2 * t}, scene, light);
    EXPECT_NEAR(b1.log2_scale - b2.log2_scale, 1.0, 1e-12) << "t = " << t;
    EXPECT_NEAR(b2.scale / b1.scale, 0.5, 1e-12);
  }
}

TEST(Brightness, ExposureValueFormEqualsThePapersProduct) {
  const ExposureSettings capture{1.4, 100, 1.0};
  for (const ExposureSettings scene : {ExposureSettings{8, 400, 0.01}, ExposureSettings{2, 3200, 1.0 / 250},
                                       ExposureSettings{22, 50, 30}}) {
    const LightPower light{12.5, 3000};
    const double product = brightnessScaleProduct(capture, scene, light);
    EXPECT_NEAR(brightnessScale(capture, scene, light).scale / product, 1.0, 1e-12);
  }
  // Eq. 2 term by term: one stop smaller scene aperture (N × √2) halves B, double ISO doubles it,
  // a 4× brighter light quadruples it.
  const ExposureSettings scene{4, 200, 0.01};
  const double b = brightnessScale(capture, scene, {10, 10}).scale;
  EXPECT_NEAR(brightnessScale(capture, {4 * std::sqrt(2.0), 200, 0.01}, {10, 10}).scale / b, 0.5, 1e-12);
  EXPECT_NEAR(brightnessScale(capture, {4, 400, 0.01}, {10, 10}).scale / b, 2.0, 1e-12);
  EXPECT_NEAR(brightnessScale(capture, scene, {10, 40}).scale / b, 4.0, 1e-12);
}

TEST(Brightness, RejectsNonPositiveSettings) {
  EXPECT_THROW(ev100({0, 100, 1}), std::invalid_argument);
  EXPECT_THROW(brightnessScale({2, 100, 1}, {2, 100, 1}, {0, 1}), std::invalid_argument);
  EXPECT_THROW(brightnessScale({2, 100, 1}, {2, -1, 1}, {1, 1}), std::invalid_argument);
}

}  // namespace
}  // namespace flarekit::predict
