// Polynomials in θ: least squares, robust least squares, the scaled form, degree by validation.
#include "fit/polynomial.h"

#include <gtest/gtest.h>

namespace flarekit::fit {
namespace {

TEST(Polynomial, RobustIgnoresAFewWildValues) {
  std::vector<double> a, v;
  for (int i = 0; i <= 40; ++i) {
    a.push_back(0.5 * i);
    v.push_back(3 + 0.4 * a.back() - 0.01 * a.back() * a.back());
  }
  v[7] += 50;
  v[30] -= 80;
  std::vector<bool> inliers;
  const model::Polynomial p = robustPolynomial(a, v, 2, 4, 0, &inliers);
  EXPECT_NEAR(p.evaluate(10), 3 + 4 - 1, 1e-6);
  EXPECT_FALSE(inliers[7]);
  EXPECT_FALSE(inliers[30]);
  EXPECT_TRUE(inliers[8]);
  // Plain least squares is pulled by them.
  EXPECT_GT(std::abs(leastSquaresPolynomial(a, v, 2).evaluate(10) - 6), 0.1);
}

TEST(Polynomial, ScaledFormIsTheSamePolynomial) {
  const model::Polynomial p{{1.5, -0.3, 0.02, -0.001}};
  const ScaledPolynomial s = ScaledPolynomial::from(p, 4, 28);
  for (double a : {0.0, 4.0, 13.7, 28.0, 35.0}) EXPECT_NEAR(s.evaluate(a), p.evaluate(a), 1e-9) << a;
  const model::Polynomial back = s.expanded();
  for (size_t k = 0; k < p.coefficients.size(); ++k) EXPECT_NEAR(back.coefficients[k], p.coefficients[k], 1e-9);
}

TEST(Polynomial, DegreeByValidationFindsTheCurve) {
  std::vector<double> a, line, cubic;
  cv::RNG rng(3);
  for (int i = 0; i < 60; ++i) {
    a.push_back(0.5 * i);
    line.push_back(2 + 0.3 * a.back() + rng.gaussian(0.05));
    cubic.push_back(2 + 0.3 * a.back() - 0.05 * a.back() * a.back() + 0.002 * std::pow(a.back(), 3) +
                    rng.gaussian(0.05));
  }
  EXPECT_EQ(degreeByValidation(a, line, 1, 4), 1);
  EXPECT_EQ(degreeByValidation(a, cubic, 1, 4), 3);
}

}  // namespace
}  // namespace flarekit::fit
