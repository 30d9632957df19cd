#include "fit/polynomial.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Dense>

#include "common/robust_statistics.h"

namespace flarekit::fit {

namespace {

// Σ a_k ((θ − t0)/s)^k: the polynomial in the centred variable.
struct CentredPolynomial {
  Eigen::VectorXd a;
  double t0 = 0, scale = 1;
  double evaluate(double angle) const {
    const double t = (angle - t0) / scale;
    double v = 0;
    for (int k = static_cast<int>(a.size()) - 1; k >= 0; --k) v = v * t + a(k);
    return v;
  }
};

CentredPolynomial solveCentred(const std::vector<double>& angles, const std::vector<double>& values,
                               const std::vector<double>& weights, int degree) {
  const int n = static_cast<int>(angles.size());
  CentredPolynomial p;
  p.t0 = std::accumulate(angles.begin(), angles.end(), 0.0) / n;
  p.scale = 0;
  for (double a : angles) p.scale = std::max(p.scale, std::abs(a - p.t0));
  if (p.scale <= 0) p.scale = 1;
  degree = std::clamp(degree, 0, n - 1);
  Eigen::MatrixXd A(n, degree + 1);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const double t = (angles[i] - p.t0) / p.scale;
    const double w = weights.empty() ? 1.0 : std::sqrt(weights[i]);
    double power = 1;
    for (int k = 0; k <= degree; ++k, power *= t) A(i, k) = w * power;
    b(i) = w * values[i];
  }
  p.a = A.colPivHouseholderQr().solve(b);
  return p;
}

model::Polynomial expanded(const CentredPolynomial& centred) {
  const int d = static_cast<int>(centred.a.size()) - 1;
  std::vector<double> c(d + 1, 0.0);
  for (int k = 0; k <= d; ++k) {
    const double ak = centred.a(k) / std::pow(centred.scale, k);
    double binom = 1;  // C(k, j)
    for (int j = 0; j <= k; ++j) {
      c[j] += ak * binom * std::pow(-centred.t0, k - j);
      binom = binom * (k - j) / (j + 1);
    }
  }
  return {c};
}

double median(std::vector<double> v) { return v.empty() ? 0 : upperMedian(v); }

CentredPolynomial robustCentred(const std::vector<double>& angles, const std::vector<double>& values,
                                int degree, double outlier_sigma, double floor,
                                std::vector<double>* weights_out) {
  const int n = static_cast<int>(angles.size());
  std::vector<double> weights(n, 1.0), residuals(n);
  CentredPolynomial p = solveCentred(angles, values, weights, degree);
  for (int iteration = 0; iteration < 10 && n > degree + 2; ++iteration) {
    for (int i = 0; i < n; ++i) residuals[i] = std::abs(values[i] - p.evaluate(angles[i]));
    const double sigma = std::max(kSigmaPerMad * median(residuals), floor);
    if (!(sigma > 0)) break;
    for (int i = 0; i < n; ++i) {
      const double u = residuals[i] / (outlier_sigma * sigma);
      weights[i] = u < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
    }
    p = solveCentred(angles, values, weights, degree);
  }
  if (weights_out) *weights_out = weights;
  return p;
}

}  // namespace

double ScaledPolynomial::evaluate(double angle_deg) const {
  const double u = variable(angle_deg);
  double v = 0;
  for (int k = static_cast<int>(coefficients.size()) - 1; k >= 0; --k) v = v * u + coefficients[k];
  return v;
}

model::Polynomial ScaledPolynomial::expanded() const {
  CentredPolynomial c;
  c.t0 = centre;
  c.scale = scale;
  c.a = Eigen::Map<const Eigen::VectorXd>(coefficients.data(), static_cast<Eigen::Index>(coefficients.size()));
  return fit::expanded(c);
}

ScaledPolynomial ScaledPolynomial::from(const model::Polynomial& p, double lo, double hi) {
  ScaledPolynomial s;
  s.centre = 0.5 * (lo + hi);
  s.scale = hi > lo ? 0.5 * (hi - lo) : 1.0;
  const int n = std::max<int>(1, p.coefficients.size());
  // Sampled at n Chebyshev points and solved: exact for a polynomial of degree n − 1.
  Eigen::MatrixXd a(n, n);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const double u = n == 1 ? 0 : std::cos(3.141592653589793 * (i + 0.5) / n);
    double power = 1;
    for (int k = 0; k < n; ++k, power *= u) a(i, k) = power;
    b(i) = p.evaluate(s.centre + s.scale * u);
  }
  const Eigen::VectorXd x = a.colPivHouseholderQr().solve(b);
  s.coefficients.assign(x.data(), x.data() + n);
  return s;
}

model::Polynomial leastSquaresPolynomial(const std::vector<double>& angles,
                                         const std::vector<double>& values, int degree,
                                         const std::vector<double>& weights) {
  if (angles.empty()) return {{0.0}};
  return expanded(solveCentred(angles, values, weights, degree));
}

model::Polynomial robustPolynomial(const std::vector<double>& angles, const std::vector<double>& values,
                                   int degree, double outlier_sigma, double floor,
                                   std::vector<bool>* inliers) {
  if (angles.empty()) return {{0.0}};
  std::vector<double> weights;
  const CentredPolynomial p = robustCentred(angles, values, degree, outlier_sigma, floor, &weights);
  if (inliers) {
    inliers->resize(weights.size());
    for (size_t i = 0; i < weights.size(); ++i) (*inliers)[i] = weights[i] > 0;
  }
  return expanded(p);
}

int degreeByValidation(const std::vector<double>& angles, const std::vector<double>& values,
                       int min_degree, int max_degree) {
  const int n = static_cast<int>(angles.size());
  max_degree = std::max(min_degree, std::min(max_degree, n / 2 - 2));
  if (max_degree <= min_degree) return min_degree;
  std::vector<double> half_angles[2], half_values[2];
  for (int i = 0; i < n; ++i) {
    half_angles[i % 2].push_back(angles[i]);
    half_values[i % 2].push_back(values[i]);
  }
  std::vector<double> errors_of(max_degree + 1, std::numeric_limits<double>::infinity());
  for (int degree = min_degree; degree <= max_degree; ++degree) {
    std::vector<double> errors;
    for (int fit = 0; fit < 2; ++fit) {
      const CentredPolynomial p =
          robustCentred(half_angles[fit], half_values[fit], degree, 4, 0, nullptr);
      const int other = 1 - fit;
      for (size_t i = 0; i < half_angles[other].size(); ++i)
        errors.push_back(std::abs(half_values[other][i] - p.evaluate(half_angles[other][i])));
    }
    errors_of[degree] = median(errors);
  }
  // The least degree within two standard errors of the best held-out error (the median of n
  // absolute errors scatters by about 1.25/√n of itself): a higher degree must earn its place.
  const double best_error = *std::min_element(errors_of.begin() + min_degree, errors_of.end());
  const double tolerance = 1 + 2.5 / std::sqrt(static_cast<double>(n));
  int best = min_degree;
  while (errors_of[best] > tolerance * best_error) ++best;
  return best;
}

}  // namespace flarekit::fit
