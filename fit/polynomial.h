#pragma once
// Polynomials in the rig angle θ (degrees), as the model file stores them (model/flare_model.h):
// least squares, robust least squares, and the degree chosen by validation.

#include <vector>

#include "model/flare_model.h"

namespace flarekit::fit {

// p(θ) = Σ a_k u^k with u = (θ − centre) / scale: a polynomial in a variable of order 1 over its
// range, the form in which the model fit optimises coefficients (powers of θ in degrees span
// many orders of magnitude and condition a solve badly).
struct ScaledPolynomial {
  double centre = 0, scale = 1;
  std::vector<double> coefficients;  // a_0 first

  double variable(double angle_deg) const { return (angle_deg - centre) / scale; }
  double evaluate(double angle_deg) const;
  // Σ c_k θ^k, as the model file stores it.
  model::Polynomial expanded() const;
  // `p` in this form, centred on [lo, hi] (exact: the same polynomial).
  static ScaledPolynomial from(const model::Polynomial& p, double lo, double hi);
};

// Weighted least-squares polynomial of `degree` through (angles, values) (weights empty: all 1).
// The degree is lowered to what the points allow (points − 1). Solved in a centred, scaled
// variable for conditioning, then expanded into powers of θ. No points: the zero polynomial.
model::Polynomial leastSquaresPolynomial(const std::vector<double>& angles_deg,
                                         const std::vector<double>& values, int degree,
                                         const std::vector<double>& weights = {});

// As leastSquaresPolynomial, robust: iteratively reweighted with Tukey's biweight at
// `outlier_sigma` robust σ (1.4826 × MAD of the residuals, at least `floor`), so that a few wild
// values (a frame whose fit went astray) do not bend the curve. `inliers`, when given, receives
// which points kept a non-zero weight.
model::Polynomial robustPolynomial(const std::vector<double>& angles_deg,
                                   const std::vector<double>& values, int degree,
                                   double outlier_sigma = 4, double floor = 0,
                                   std::vector<bool>* inliers = nullptr);

// The least degree in [min_degree, max_degree] whose robust polynomial predicts held-out points
// within two standard errors of the best: fitted on every other point, scored (median absolute error) on the
// others and the other way round. Fewer than 2 × (max_degree + 2) points lower the largest degree tried.
int degreeByValidation(const std::vector<double>& angles_deg, const std::vector<double>& values,
                       int min_degree, int max_degree);

}  // namespace flarekit::fit
