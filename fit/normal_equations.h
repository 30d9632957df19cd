#pragma once
// The Gauss–Newton terms of a GroupCost's samples at its last evaluation point, A = JᵀJ, b = Jᵀr
// and c = Σ ρ(u) (twice the cost, without the prior), each sample's rows weighted by its loss
// (GroupCost::robustSample), and a square-root form of them for Ceres: a residual block of N + 1
// rows (N = ghosts × parameters per ghost) with the same normal equations, gradient and cost as
// one block of rows per sample.
//
// Why: Ceres runs on one thread here (group_solver.h), and with the samples' rows as its residuals
// it would copy, check, scale and multiply every row of the Jacobian there while the other cores
// wait. Here the products run tile by tile on every thread, and Ceres's own work is N + 1 rows.
//
// The square-root form: with S = diag(A)^-½ (1 where a parameter reaches no sample), the scaled
// Â = S A S = Pᵀ L D Lᵀ P (LDLᵀ with pivoting: Â may be singular), J̃ = D^½ Lᵀ P S⁻¹ and
// r̃ = D^-½ L⁻¹ P S b. Then J̃ᵀJ̃ = A and J̃ᵀr̃ = b, so the Levenberg–Marquardt step, the model's
// cost change, Ceres's Jacobi scaling (diag A) and the gradient are those of the samples' rows;
// one more row, √(c − ‖r̃‖²) with a zero Jacobian, keeps the cost ½c. Directions with D ≈ 0 (a
// parameter combination no sample sees) carry neither curvature nor gradient and are left out.
//
// Deterministic: tiles are summed in chunks of a fixed count, each in order, the chunks in
// order, so A, b, c do not depend on the thread count.

#include <vector>

#include <Eigen/Core>

#include "fit/cost.h"

namespace flarekit::fit {

// The square-root form of normal equations (A, b, c) (see above): J̃ (N × N), r̃ (N) and the
// rest √(c − ‖r̃‖²), so that J̃ᵀJ̃ = A, J̃ᵀr̃ = b and ‖r̃‖² + rest² = c. A must be symmetric
// positive semi-definite.
struct SquareRootForm {
  Eigen::MatrixXd jacobian;
  Eigen::VectorXd residuals;
  double rest = 0;
};
SquareRootForm squareRootForm(const Eigen::MatrixXd& a, const Eigen::VectorXd& b, double c);

class NormalEquations {
 public:
  // Square tiles of kTilePx level pixels: the ghosts a tile's samples reach, not all of the
  // group's, enter its products.
  static constexpr int kTilePx = 16;

  explicit NormalEquations(const GroupCost& cost);

  // Reads the cost's images at its last evaluation point: c always, A, b and the square-root
  // form when `with_jacobians` (the cost must then hold derivatives).
  void fill(bool with_jacobians);

  int parameterCount() const { return static_cast<int>(b_.size()); }  // N
  const Eigen::MatrixXd& jtj() const { return a_; }                      // A (N × N)
  const Eigen::VectorXd& jtr() const { return b_; }                      // b (N)
  double squaredNorm() const { return c_; }                              // c

  // The square-root form at the last fill: residuals [N + 1] and, where not null, the Jacobian of
  // ghost g, row-major [(N + 1) × parameters per ghost]. After a fill without derivatives the
  // residuals are √c and zeros, and no Jacobian may be asked for.
  int squareRootRows() const { return parameterCount() + 1; }
  void squareRoot(double* residuals, double* const* jacobians) const;

 private:
  const GroupCost& cost_;
  int m_, n_, ghosts_;         // residuals per sample, parameters per ghost, ghosts
  std::vector<int> order_;     // sample indices, tile after tile
  std::vector<int> first_;     // tile t holds order_[first_[t]] .. order_[first_[t + 1] − 1]
  std::vector<int> chunk_first_;  // chunk k holds tiles chunk_first_[k] .. chunk_first_[k + 1] − 1
  struct Sums {
    Eigen::MatrixXd a;  // lower triangle
    Eigen::VectorXd b;
    double c = 0;
  };
  std::vector<Sums> chunks_;
  Eigen::MatrixXd a_;
  Eigen::VectorXd b_;
  double c_ = 0;
  bool with_jacobians_ = false;
  SquareRootForm root_;
};

}  // namespace flarekit::fit
