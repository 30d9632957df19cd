#include "model/intensity.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "model/detail/transfer_math.h"

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

// The batch form (vector lanes, what plain renders use) gives each distance the scalar weights bit
// for bit: random distances across both fall-off bands and beyond, the special values, and those
// that leave the fast ranges (τ subnormal; τ^E below e^−700 with a large exponent), for counts
// that fill the lanes and counts that do not.
TEST(Intensity, BatchWeightsEqualTheScalarOnesBitForBit) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int trial = 0; trial < 200; ++trial) {
    GhostParameters g = ghost();
    g.inside_falloff = 0.5 + 40 * unit(rng);
    g.outside_falloff = 0.5 + 10 * unit(rng);
    g.inside_exponent = trial % 10 == 0 ? 200.0 : 0.1 * std::pow(100.0, unit(rng));
    g.outside_exponent = 0.1 * std::pow(100.0, unit(rng));
    const int count = 1 + trial % 70;
    std::vector<double> d(count);
    for (int i = 0; i < count; ++i) {
      const double u = unit(rng);
      d[i] = u < 0.1   ? -g.inside_falloff * std::pow(10.0, -30 * unit(rng))  // τ near 0, down to 1e-30
             : u < 0.15 ? -g.inside_falloff * 1e-310                          // τ subnormal
             : u < 0.2  ? (unit(rng) < 0.5 ? -g.inside_falloff : g.outside_falloff)
             : u < 0.25 ? (unit(rng) < 0.5 ? 0.0 : -0.0)
                        : (2 * unit(rng) - 1) * 1.2 * (unit(rng) < 0.5 ? g.inside_falloff : g.outside_falloff);
    }
    std::vector<double> border(count), inside(count);
    transferValueWeights(d.data(), count, g, border.data(), inside.data());
    for (int i = 0; i < count; ++i) {
      double b = 0, in = 0;
      transferValueWeights(d[i], g, b, in);
      ASSERT_EQ(std::bit_cast<std::uint64_t>(border[i]), std::bit_cast<std::uint64_t>(b)) << "d = " << d[i];
      ASSERT_EQ(std::bit_cast<std::uint64_t>(inside[i]), std::bit_cast<std::uint64_t>(in)) << "d = " << d[i];
    }
  }
}

// The renderer's inline logarithm and exponential (detail/transfer_math.h) against glibc's: within
// 2 ulp each, and the power τ^E they form within 1e-13 relative of exp(E·ln τ) by libm over the
// whole parameter range (E in [0.1, 10], τ down to 1e-12), so images in float do not move.
TEST(Intensity, InlineLogAndExpAgreeWithLibm) {
  auto ulps = [](double a, double b) {
    const auto x = std::bit_cast<std::int64_t>(a), y = std::bit_cast<std::int64_t>(b);
    return x > y ? x - y : y - x;
  };
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  std::int64_t worst_log = 0, worst_exp = 0;
  double worst_power = 0;
  for (int i = 0; i < 200000; ++i) {
    const double tau = i % 2 ? unit(rng) : std::pow(10.0, -12 * unit(rng));
    const double exponent = 0.1 * std::pow(100.0, unit(rng));
    const double y = -690 * unit(rng) * unit(rng);
    worst_log = std::max(worst_log, ulps(detail::transferLog(tau), std::log(tau)));
    worst_exp = std::max(worst_exp, ulps(detail::transferExp(y), std::exp(y)));
    const double reference = std::exp(exponent * std::log(tau));
    if (reference > 0)
      worst_power = std::max(worst_power, std::abs(transferPower(tau, exponent) - reference) / reference);
  }
  EXPECT_LE(worst_log, 2);
  EXPECT_LE(worst_exp, 2);
  EXPECT_LE(worst_power, 1e-13);
  // Outside the fast ranges libm answers: the exact values and special cases.
  EXPECT_EQ(detail::transferLog(1.0), 0.0);
  EXPECT_EQ(detail::transferExp(0.0), 1.0);
  EXPECT_EQ(detail::transferLog(0.0), -HUGE_VAL);
  EXPECT_TRUE(std::isnan(detail::transferLog(-1.0)));
  EXPECT_EQ(detail::transferExp(-800.0), std::exp(-800.0));
  EXPECT_EQ(detail::transferLog(1e-310), std::log(1e-310));
  EXPECT_EQ(transferPower(0.0, 2.0), 0.0);
  EXPECT_EQ(transferPower(1.0, 2.0), 1.0);
}

}  // namespace
}  // namespace flarekit::model
