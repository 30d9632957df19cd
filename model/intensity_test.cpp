#include "model/intensity.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flarekit::model {
namespace {

GhostParameters ghost() {
  GhostParameters g;
  g.channels = 3;
  g.border = {2.0, 1.0, 0.5};
  g.inside = {0.25, 0.5, 1.5};
  g.inside_falloff = 8;
  g.inside_exponent = 1.7;
  g.outside_falloff = 3;
  g.outside_exponent = 0.6;
  return g;
}

TEST(Intensity, BorderInsideAndOutsideValues) {
  const GhostParameters g = ghost();
  for (int c = 0; c < 3; ++c) {
    EXPECT_DOUBLE_EQ(intensity(0, g, c), g.border[c]);         // Ib on the outline
    EXPECT_DOUBLE_EQ(intensity(-8, g, c), g.inside[c]);        // Ii from −Fi inwards
    EXPECT_DOUBLE_EQ(intensity(-100, g, c), g.inside[c]);
    EXPECT_DOUBLE_EQ(intensity(3, g, c), 0.0);                 // 0 from Fo outwards
    EXPECT_DOUBLE_EQ(intensity(50, g, c), 0.0);
  }
  // Halfway inside: Ib + (Ii − Ib)·0.5^Ei; halfway outside: Ib·(1 − 0.5^Eo).
  EXPECT_NEAR(intensity(-4, g, 0), 2.0 + (0.25 - 2.0) * std::pow(0.5, 1.7), 1e-15);
  EXPECT_NEAR(intensity(1.5, g, 2), 0.5 * (1 - std::pow(0.5, 0.6)), 1e-15);
}

TEST(Intensity, FallsOffMonotonically) {
  GhostParameters g = ghost();
  double prev = intensity(0, g, 0);
  for (double d = 0.01; d < 4; d += 0.01) {
    const double v = intensity(d, g, 0);
    EXPECT_LE(v, prev + 1e-15);
    prev = v;
  }
}

TEST(Intensity, WeightDerivativesMatchCentralDifferences) {
  GhostParameters g = ghost();
  const ParameterLayout layout{3};
  for (double d : {-7.3, -4.0, -0.6, 0.4, 1.1, 2.7}) {
    const TransferWeights w = transferWeights(d, g, true);
    const double h = 1e-6;
    const TransferWeights plus = transferWeights(d + h, g, false), minus = transferWeights(d - h, g, false);
    EXPECT_NEAR(w.border_d_distance, (plus.border - minus.border) / (2 * h), 1e-6) << d;
    EXPECT_NEAR(w.inside_d_distance, (plus.inside - minus.inside) / (2 * h), 1e-6) << d;
    for (int which = 0; which < 2; ++which) {  // fall-off, exponent of the side d lies on
      const int k = d < 0 ? (which == 0 ? layout.fi() : layout.ei()) : (which == 0 ? layout.fo() : layout.eo());
      std::vector<double> v = toParameterVector(g);
      v[k] += h;
      const TransferWeights wp = transferWeights(d, fromParameterVector(v, 3), false);
      v[k] -= 2 * h;
      const TransferWeights wm = transferWeights(d, fromParameterVector(v, 3), false);
      const double fd_b = (wp.border - wm.border) / (2 * h), fd_i = (wp.inside - wm.inside) / (2 * h);
      EXPECT_NEAR(which == 0 ? w.border_d_falloff : w.border_d_exponent, fd_b, 1e-6) << d;
      EXPECT_NEAR(which == 0 ? w.inside_d_falloff : w.inside_d_exponent, fd_i, 1e-6) << d;
    }
  }
  // Finite at the outline even with an exponent below 1 (infinite slope there).
  const TransferWeights at_border = transferWeights(0, g, true);
  EXPECT_TRUE(std::isfinite(at_border.border_d_distance));
  EXPECT_TRUE(std::isfinite(at_border.border_d_exponent));
}

}  // namespace
}  // namespace flarekit::model
