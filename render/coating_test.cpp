#include "render/coating.h"

#include <cmath>

#include <gtest/gtest.h>

namespace flarekit::render {
namespace {

TEST(Fresnel, NormalIncidenceOnGlassReflectsFourPercent) {
  EXPECT_NEAR(fresnelReflectance(1.0, 1.5, 1.0).unpolarized(), 0.04, 1e-12);
  // The same from inside the glass (reciprocity).
  EXPECT_NEAR(fresnelReflectance(1.5, 1.0, 1.0).unpolarized(), 0.04, 1e-12);
}

TEST(Fresnel, KnownValuesAt45DegreesAndBrewster) {
  const Reflectance r = fresnelReflectance(1.0, 1.5, std::cos(M_PI / 4));
  EXPECT_NEAR(r.s, 0.0920, 1e-4);  // Hecht, Optics, Fig. 4.12 values for n = 1.5
  EXPECT_NEAR(r.p, 0.00847, 1e-4);
  EXPECT_NEAR(fresnelReflectance(1.0, 1.5, std::cos(std::atan(1.5))).p, 0.0, 1e-12);
}

TEST(Fresnel, TotalInternalReflectionPastTheCriticalAngle) {
  const double critical = std::asin(1.0 / 1.5);
  EXPECT_EQ(fresnelReflectance(1.5, 1.0, std::cos(critical + 0.01)).unpolarized(), 1.0);
  EXPECT_LT(fresnelReflectance(1.5, 1.0, std::cos(critical - 0.05)).unpolarized(), 1.0);
  EXPECT_EQ(thinFilmReflectance(1.5, 1.38, 100, 1.0, 550, std::cos(critical + 0.01)).unpolarized(), 1.0);
}

TEST(Coating, QuarterWaveMgF2OnGlassAtItsDesignWavelength) {
  const double n_c = 1.38, n_g = 1.5, design = 550.0;
  const double d = quarterWaveThickness_nm(design, n_c);
  const double expected = std::pow((n_g - n_c * n_c) / (n_g + n_c * n_c), 2.0);  // ≈ 1.41 %
  EXPECT_NEAR(expected, 0.0141, 1e-4);
  const Reflectance r = thinFilmReflectance(1.0, n_c, d, n_g, design, 1.0);
  EXPECT_NEAR(r.s, expected, 1e-12);
  EXPECT_NEAR(r.p, expected, 1e-12);
  // Away from the design wavelength it reflects more, and always less than bare glass.
  for (double l : {400.0, 450.0, 650.0, 750.0}) {
    const double rl = thinFilmReflectance(1.0, n_c, d, n_g, l, 1.0).unpolarized();
    EXPECT_GT(rl, expected + 1e-4) << l;
    EXPECT_LT(rl, 0.04) << l;
  }
}

// The closed form of a single layer (Born & Wolf §1.6.4, Hecht §9.7) with real amplitude
// coefficients, written out independently of the complex implementation.
double closedForm(double n1, double nc, double d, double n2, double lambda, double theta1, bool s) {
  const double sin1 = std::sin(theta1);
  const double cos1 = std::cos(theta1);
  const double cosc = std::sqrt(1 - std::pow(n1 * sin1 / nc, 2));
  const double cos2 = std::sqrt(1 - std::pow(n1 * sin1 / n2, 2));
  double r12, r23;
  if (s) {
    r12 = (n1 * cos1 - nc * cosc) / (n1 * cos1 + nc * cosc);
    r23 = (nc * cosc - n2 * cos2) / (nc * cosc + n2 * cos2);
  } else {
    r12 = (nc * cos1 - n1 * cosc) / (nc * cos1 + n1 * cosc);
    r23 = (n2 * cosc - nc * cos2) / (n2 * cosc + nc * cos2);
  }
  const double delta = 4 * M_PI * nc * d * cosc / lambda;
  return (r12 * r12 + r23 * r23 + 2 * r12 * r23 * std::cos(delta)) /
         (1 + r12 * r12 * r23 * r23 + 2 * r12 * r23 * std::cos(delta));
}

TEST(Coating, HullinExampleCurveMatchesTheClosedForm) {
  // Hullin 2011 §3.1: a 532 nm quarter-wave MgF₂ layer, d = 96.4 nm, on n = 1.5 glass.
  const double d = quarterWaveThickness_nm(532.0, 1.38);
  EXPECT_NEAR(d, 96.4, 0.05);
  double minimum = 1.0, argmin = 0.0;
  for (double theta_deg : {0.0, 20.0, 40.0, 60.0}) {
    const double t = theta_deg * M_PI / 180;
    for (double l = 380; l <= 780; l += 5) {
      const Reflectance r = thinFilmReflectance(1.0, 1.38, d, 1.5, l, std::cos(t));
      EXPECT_NEAR(r.s, closedForm(1.0, 1.38, d, 1.5, l, t, true), 1e-12) << l << " " << theta_deg;
      EXPECT_NEAR(r.p, closedForm(1.0, 1.38, d, 1.5, l, t, false), 1e-12) << l << " " << theta_deg;
      if (theta_deg == 0.0 && r.unpolarized() < minimum) {
        minimum = r.unpolarized();
        argmin = l;
      }
    }
  }
  EXPECT_NEAR(argmin, 532.0, 5.0);  // the reflectance minimum sits at the design wavelength
  // Oblique light sees a thinner layer: the minimum moves to shorter wavelengths (blue shift).
  const double t = 40 * M_PI / 180;
  EXPECT_LT(thinFilmReflectance(1.0, 1.38, d, 1.5, 490, std::cos(t)).unpolarized(),
            thinFilmReflectance(1.0, 1.38, d, 1.5, 532, std::cos(t)).unpolarized());
}

TEST(Coating, SurfaceCoatingFallsBackToFresnelWhenUncoated) {
  SurfaceCoating bare;
  EXPECT_NEAR(bare.reflectance(1.0, 1.5, 550, 1.0), 0.04, 1e-12);
  SurfaceCoating coated{true, 1.38, quarterWaveThickness_nm(550, 1.38)};
  EXPECT_NEAR(coated.reflectance(1.0, 1.5, 550, 1.0), 0.0141, 1e-4);
}

}  // namespace
}  // namespace flarekit::render
