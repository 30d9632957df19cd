#include "render/aperture.h"

#include <cmath>

#include <gtest/gtest.h>

namespace flarekit::render {
namespace {

double meanOf(const Aperture& a) { return cv::mean(a.raster(400))[0]; }

TEST(Aperture, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(ApertureShape{}.IsValid(&error)) << error;
}

TEST(Aperture, AreasOfCircleAndPolygons) {
  ApertureShape circle;
  circle.kind = ApertureKind::kCircle;
  EXPECT_NEAR(meanOf(Aperture(circle)), M_PI / 4, 2e-3);
  for (int n : {5, 6, 9}) {
    ApertureShape p;
    p.blades = n;
    // Regular n-gon inscribed in the unit circle: area n/2 · sin(2π/n).
    EXPECT_NEAR(meanOf(Aperture(p)), n / 2.0 * std::sin(2 * M_PI / n) / 4, 2e-3) << n;
  }
  ApertureShape round;
  round.rounding = 1.0;
  EXPECT_NEAR(meanOf(Aperture(round)), M_PI / 4, 2e-3);
  ApertureShape half;
  half.rounding = 0.5;
  const double m = meanOf(Aperture(half));
  EXPECT_GT(m, 6 / 2.0 * std::sin(2 * M_PI / 6) / 4 + 0.005);
  EXPECT_LT(m, M_PI / 4 - 0.005);
}

TEST(Aperture, PolygonRotationTurnsItsCorners) {
  ApertureShape p;
  p.blades = 6;
  Aperture a(p);
  // A vertex at angle π/6·0 = 0 (on +u) reaches radius 1; an edge midpoint only cos(π/6).
  EXPECT_EQ(a.transmission(0.99f, 0.0f), 1.0f);
  p.rotation_deg = 30;
  EXPECT_EQ(Aperture(p).transmission(0.99f, 0.0f), 0.0f);
}

TEST(Aperture, MaskIsSampledOverTheUnitSquare) {
  ApertureShape m;
  m.kind = ApertureKind::kMask;
  m.mask = cv::Mat(64, 64, CV_8UC1, cv::Scalar(0));
  m.mask(cv::Rect(32, 0, 32, 64)).setTo(255);  // right half open
  Aperture a(m);
  EXPECT_NEAR(a.transmission(0.5f, 0.2f), 1.0f, 1e-6);
  EXPECT_NEAR(a.transmission(-0.5f, 0.2f), 0.0f, 1e-6);
  EXPECT_EQ(a.transmission(2.0f, 0.0f), 0.0f);
  ApertureShape empty;
  empty.kind = ApertureKind::kMask;
  EXPECT_FALSE(empty.IsValid(nullptr));
}

}  // namespace
}  // namespace flarekit::render
