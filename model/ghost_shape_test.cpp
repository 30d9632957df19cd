#include "model/ghost_shape.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace flarekit::model {
namespace {

GhostParameters circle(double r) {
  GhostParameters g;
  g.center_x = 100;
  g.center_y = 80;
  g.left = g.right = g.height = r;
  g.curvature_left = g.curvature_right = 0.5523;
  return g;
}

TEST(GhostShape, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(isValid(GhostParameters{}, &error)) << error;
  GhostParameters rgb;
  rgb.channels = 3;
  EXPECT_TRUE(isValid(rgb, &error)) << error;
}

TEST(GhostShape, FourQuarterBeziersApproximateACircle) {
  // Walch 2018 §3.2: four cubic Béziers approximate a circle; with the control factor 0.5523 the
  // outline stays within 0.03 % of the radius.
  for (double r : {1.0, 37.0, 2500.0}) {
    const GhostParameters g = circle(r);
    double worst = 0;
    for (const CubicBezier& b : ghostOutline(g))
      for (int i = 0; i <= 2000; ++i) {
        const cv::Point2d p = b.at(i / 2000.0);
        worst = std::max(worst, std::abs(std::hypot(p.x - g.center_x, p.y - g.center_y) - r) / r);
      }
    EXPECT_LE(worst, 3e-4) << "r = " << r;
    EXPECT_GT(worst, 1e-5) << "a Bézier quarter is not exactly circular";
  }
}

TEST(GhostShape, OutlinePassesThroughTheFourPointsAndIsMirrorSymmetric) {
  GhostParameters g;
  g.center_x = 10;
  g.center_y = -4;
  g.left = 7;
  g.right = 3;
  g.height = 5;
  g.curvature_left = 0.2;
  g.curvature_right = 0.9;
  const auto s = ghostOutline(g);
  EXPECT_EQ(s[0].at(0), cv::Point2d(3, -4));   // P_L
  EXPECT_EQ(s[0].at(1), cv::Point2d(10, -9));  // P_T (y down: above M)
  EXPECT_EQ(s[1].at(1), cv::Point2d(13, -4));  // P_R
  EXPECT_EQ(s[2].at(1), cv::Point2d(10, 1));   // P_B
  EXPECT_EQ(s[3].at(1), s[0].at(0));           // closed
  for (int i = 0; i <= 20; ++i) {
    const double t = i / 20.0;
    // Segment 3 mirrors segment 0 about y = My with t reversed, segment 2 mirrors segment 1.
    const cv::Point2d a = s[0].at(t), b = s[3].at(1 - t);
    EXPECT_NEAR(a.x, b.x, 1e-12);
    EXPECT_NEAR(a.y - g.center_y, g.center_y - b.y, 1e-12);
    const cv::Point2d c = s[1].at(t), d = s[2].at(1 - t);
    EXPECT_NEAR(c.x, d.x, 1e-12);
    EXPECT_NEAR(c.y - g.center_y, g.center_y - d.y, 1e-12);
  }
  // The tangents at the joints are axis-aligned (C¹ up to speed: the control points move along
  // the axes only).
  EXPECT_NEAR(s[0].derivative(1).y, 0, 1e-12);
  EXPECT_NEAR(s[1].derivative(0).y, 0, 1e-12);
  EXPECT_NEAR(s[0].derivative(0).x, 0, 1e-12);
  EXPECT_NEAR(s[1].derivative(1).x, 0, 1e-12);
}

TEST(GhostShape, OutlineStaysInsideItsBoundsAndIsMonotone) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> size(0.5, 50), curv(0, 1);
  for (int trial = 0; trial < 200; ++trial) {
    GhostParameters g;
    g.left = size(rng);
    g.right = size(rng);
    g.height = size(rng);
    g.curvature_left = curv(rng);
    g.curvature_right = curv(rng);
    const cv::Rect2d box = outlineBounds(g);
    const auto s = ghostOutline(g);
    for (int k = 0; k < 4; ++k) {
      cv::Point2d prev = s[k].at(0);
      for (int i = 1; i <= 100; ++i) {
        const cv::Point2d p = s[k].at(i / 100.0);
        EXPECT_GE(p.x, box.x - 1e-9);
        EXPECT_LE(p.x, box.x + box.width + 1e-9);
        EXPECT_GE(p.y, box.y - 1e-9);
        EXPECT_LE(p.y, box.y + box.height + 1e-9);
        // Clockwise as displayed: 0 goes right and up, 1 right and down, 2 left and down, 3 left
        // and up.
        const double sx = (k < 2) ? 1 : -1, sy = (k == 0 || k == 3) ? -1 : 1;
        EXPECT_GE(sx * (p.x - prev.x), -1e-12);
        EXPECT_GE(sy * (p.y - prev.y), -1e-12);
        prev = p;
      }
    }
  }
}

TEST(GhostShape, ParameterVectorHasTheDocumentedOrder) {
  EXPECT_EQ(parameterCount(1), 13);
  EXPECT_EQ(parameterCount(3), 17);
  const std::vector<std::string> grey = {"Mx", "My", "L", "R", "h", "Cl", "Cr",
                                         "Ib", "Ii", "Fi", "Ei", "Fo", "Eo"};
  EXPECT_EQ(parameterNames(1), grey);
  const std::vector<std::string> rgb = {"Mx",   "My",   "L",    "R",    "h",    "Cl",
                                        "Cr",   "Ib_R", "Ib_G", "Ib_B", "Ii_R", "Ii_G",
                                        "Ii_B", "Fi",   "Ei",   "Fo",   "Eo"};
  EXPECT_EQ(parameterNames(3), rgb);
  for (int channels : {1, 3})
    for (int k = 0; k < parameterCount(channels); ++k)
      EXPECT_EQ(parameterIndex(parameterName(k, channels), channels), k);
  EXPECT_EQ(parameterIndex("Ib_R", 1), -1);
  EXPECT_THROW(parameterName(13, 1), std::out_of_range);

  GhostParameters g;
  g.channels = 3;
  g.center_x = 1;
  g.center_y = 2;
  g.left = 3;
  g.right = 4;
  g.height = 5;
  g.curvature_left = 0.6;
  g.curvature_right = 0.7;
  g.border = {8, 9, 10};
  g.inside = {11, 12, 13};
  g.inside_falloff = 14;
  g.inside_exponent = 1.5;
  g.outside_falloff = 16;
  g.outside_exponent = 1.7;
  const std::vector<double> v = toParameterVector(g);
  const std::vector<double> expected = {1, 2, 3, 4, 5, 0.6, 0.7, 8, 9, 10, 11, 12, 13, 14, 1.5, 16, 1.7};
  EXPECT_EQ(v, expected);
  const ParameterLayout layout{3};
  EXPECT_EQ(v[layout.ii(1)], 12);
  EXPECT_EQ(v[layout.eo()], 1.7);
  const GhostParameters back = fromParameterVector(v, 3);
  EXPECT_EQ(toParameterVector(back), v);
  EXPECT_THROW(fromParameterVector(std::vector<double>(13), 3), std::invalid_argument);
}

TEST(GhostShape, ValidityCheckNamesTheParameter) {
  std::string error;
  GhostParameters g;
  g.left = -2;
  EXPECT_FALSE(isValid(g, &error));
  EXPECT_NE(error.find("L = -2"), std::string::npos) << error;
  g = GhostParameters{};
  g.curvature_right = 1.2;
  EXPECT_FALSE(isValid(g, &error));
  EXPECT_NE(error.find("Cr"), std::string::npos) << error;
  g = GhostParameters{};
  g.inside_exponent = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(isValid(g, &error));
  EXPECT_NE(error.find("Ei"), std::string::npos) << error;
  g = GhostParameters{};
  g.channels = 2;
  EXPECT_FALSE(isValid(g, &error));
  g = GhostParameters{};
  g.border[0] = -1;
  EXPECT_FALSE(isValid(g, &error));
  // Every bound is accepted and just beyond it is not.
  for (int k = 0; k < parameterCount(1); ++k) {
    const ParameterBounds b = parameterBounds(k, 1);
    std::vector<double> v = toParameterVector(GhostParameters{});
    v[k] = b.lower;
    EXPECT_TRUE(isValid(fromParameterVector(v, 1))) << parameterName(k, 1);
    v[k] = b.upper;
    EXPECT_TRUE(isValid(fromParameterVector(v, 1))) << parameterName(k, 1);
    v[k] = b.lower - std::max(1e-6, std::abs(b.lower) * 1e-6);
    EXPECT_FALSE(isValid(fromParameterVector(v, 1))) << parameterName(k, 1);
    v[k] = std::numeric_limits<double>::quiet_NaN();
    EXPECT_FALSE(isValid(fromParameterVector(v, 1))) << parameterName(k, 1);
    EXPECT_TRUE(isValid(clampToBounds(fromParameterVector(v, 1))));
  }
}

TEST(GhostShape, OutlineDerivativesMatchFiniteDifferences) {
  GhostParameters g;
  g.center_x = 5;
  g.center_y = 7;
  g.left = 12;
  g.right = 6;
  g.height = 9;
  g.curvature_left = 0.3;
  g.curvature_right = 0.8;
  for (int q = 0; q < param::kShapeCount; ++q)
    for (int seg = 0; seg < 4; ++seg)
      for (double t : {0.0, 0.2, 0.5, 0.77, 1.0}) {
        std::vector<double> v = toParameterVector(g);
        const double h = 1e-6;
        v[q] += h;
        const cv::Point2d plus = ghostOutline(fromParameterVector(v, 1))[seg].at(t);
        v[q] -= 2 * h;
        const cv::Point2d minus = ghostOutline(fromParameterVector(v, 1))[seg].at(t);
        const cv::Point2d fd = (plus - minus) * (1 / (2 * h));
        const cv::Point2d a = outlineDerivative(g, seg, t, q);
        EXPECT_NEAR(a.x, fd.x, 1e-6) << "q " << q << " seg " << seg << " t " << t;
        EXPECT_NEAR(a.y, fd.y, 1e-6) << "q " << q << " seg " << seg << " t " << t;
      }
}

}  // namespace
}  // namespace flarekit::model
