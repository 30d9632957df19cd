#include "fit/normal_equations.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <tbb/parallel_for.h>

namespace flarekit::fit {

namespace {

// Tiles are summed in this many chunks (fewer for small regions), whatever the thread count.
constexpr int kChunks = 16;
// Pivots of the scaled Â (unit diagonal) below this are directions no sample sees.
constexpr double kMinPivot = 1e-14;

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

}  // namespace

SquareRootForm squareRootForm(const Eigen::MatrixXd& a, const Eigen::VectorXd& b, double c) {
  const int n = static_cast<int>(b.size());
  const Eigen::VectorXd diagonal = a.diagonal();
  Eigen::VectorXd s(n);
  for (int i = 0; i < n; ++i) s[i] = diagonal[i] > 0 ? 1 / std::sqrt(diagonal[i]) : 1.0;
  const Eigen::MatrixXd scaled = s.asDiagonal() * a * s.asDiagonal();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(scaled);
  const Eigen::VectorXd d = ldlt.vectorD();
  const Eigen::VectorXd y = ldlt.matrixL().solve(ldlt.transpositionsP() * s.cwiseProduct(b));
  SquareRootForm root;
  Eigen::VectorXd row_scale(n);
  root.residuals.resize(n);
  for (int i = 0; i < n; ++i) {
    const bool seen = d[i] > kMinPivot;
    row_scale[i] = seen ? std::sqrt(d[i]) : 0.0;
    root.residuals[i] = seen ? y[i] / row_scale[i] : 0.0;
  }
  // P as a matrix, as LDLT::reconstructedMatrix builds it (a product Matrix × Transpositions
  // applies the swaps in the other order: Pᵀ).
  const Eigen::MatrixXd p = ldlt.transpositionsP() * Eigen::MatrixXd::Identity(n, n);
  const Eigen::MatrixXd upper = ldlt.matrixU();
  root.jacobian = row_scale.asDiagonal() * upper * p * s.cwiseInverse().asDiagonal();
  root.rest = std::sqrt(std::max(0.0, c - root.residuals.squaredNorm()));
  return root;
}

NormalEquations::NormalEquations(const GroupCost& cost)
    : cost_(cost),
      m_(cost.residualsPerSample()),
      n_(cost.parametersPerGhost()),
      ghosts_(cost.ghostCount()) {
  const auto& samples = cost.samples();
  const int columns = (cost.region().width + kTilePx - 1) / kTilePx;
  const int rows = (cost.region().height + kTilePx - 1) / kTilePx;
  std::vector<std::vector<int>> tiles(static_cast<size_t>(columns) * rows);
  for (size_t i = 0; i < samples.size(); ++i)
    tiles[(samples[i].y / kTilePx) * columns + samples[i].x / kTilePx].push_back(static_cast<int>(i));
  first_.push_back(0);
  for (const auto& tile : tiles) {
    if (tile.empty()) continue;
    order_.insert(order_.end(), tile.begin(), tile.end());
    first_.push_back(static_cast<int>(order_.size()));
  }
  // Chunks of about equal sample counts, in tile order.
  const int tile_count = static_cast<int>(first_.size()) - 1;
  const int chunk_count = std::min(kChunks, tile_count);
  chunk_first_.push_back(0);
  for (int k = 1; k < chunk_count; ++k) {
    const size_t target = order_.size() * k / chunk_count;
    int t = chunk_first_.back() + 1;
    while (t < tile_count - (chunk_count - k) && static_cast<size_t>(first_[t]) < target) ++t;
    chunk_first_.push_back(t);
  }
  chunk_first_.push_back(tile_count);
  chunks_.resize(chunk_first_.size() - 1);
  const int n_total = ghosts_ * n_;
  a_ = Eigen::MatrixXd::Zero(n_total, n_total);
  b_ = Eigen::VectorXd::Zero(n_total);
}

void NormalEquations::fill(bool with_jacobians) {
  const int n_total = ghosts_ * n_;
  tbb::parallel_for(0, static_cast<int>(chunks_.size()), [&](int k) {
    Sums& sums = chunks_[k];
    sums.c = 0;
    if (with_jacobians) {
      sums.a.setZero(n_total, n_total);
      sums.b.setZero(n_total);
    }
    std::vector<double> residuals, jacobian_rows;  // the tile's rows; per ghost rows × n_
    std::vector<double*> jacobians(ghosts_);
    std::vector<char> reached_tile(ghosts_);
    std::unique_ptr<bool[]> reached(new bool[ghosts_]);
    for (int t = chunk_first_[k]; t < chunk_first_[k + 1]; ++t) {
      const int count = first_[t + 1] - first_[t];
      const size_t rows = static_cast<size_t>(count) * m_;
      residuals.resize(rows);
      if (with_jacobians) {
        jacobian_rows.resize(ghosts_ * rows * n_);
        std::fill(reached_tile.begin(), reached_tile.end(), 0);
      }
      double rest = 0;
      for (int i = 0; i < count; ++i) {
        if (with_jacobians)
          for (int g = 0; g < ghosts_; ++g)
            jacobians[g] = jacobian_rows.data() + (g * rows + static_cast<size_t>(i) * m_) * n_;
        rest += cost_.robustSample(order_[first_[t] + i], residuals.data() + static_cast<size_t>(i) * m_,
                                   with_jacobians ? jacobians.data() : nullptr, reached.get());
        if (with_jacobians)
          for (int g = 0; g < ghosts_; ++g) reached_tile[g] |= reached[g];
      }
      const Eigen::Map<const Eigen::VectorXd> r(residuals.data(), static_cast<Eigen::Index>(rows));
      sums.c += r.squaredNorm() + rest;
      if (!with_jacobians) continue;
      auto block = [&](int g) {
        return Eigen::Map<const RowMajor>(jacobian_rows.data() + g * rows * n_,
                                          static_cast<Eigen::Index>(rows), n_);
      };
      for (int g = 0; g < ghosts_; ++g) {
        if (!reached_tile[g]) continue;
        const auto jg = block(g);
        sums.b.segment(g * n_, n_).noalias() += jg.transpose() * r;
        for (int h = 0; h <= g; ++h)
          if (reached_tile[h]) sums.a.block(g * n_, h * n_, n_, n_).noalias() += jg.transpose() * block(h);
      }
    }
  });
  c_ = 0;
  for (const Sums& s : chunks_) c_ += s.c;
  with_jacobians_ = with_jacobians;
  if (!with_jacobians) return;
  a_.setZero();
  b_.setZero();
  for (const Sums& s : chunks_) {
    a_ += s.a;
    b_ += s.b;
  }
  Eigen::MatrixXd full = a_.selfadjointView<Eigen::Lower>();
  a_.swap(full);

  root_ = squareRootForm(a_, b_, c_);
}

void NormalEquations::squareRoot(double* residuals, double* const* jacobians) const {
  const int n_total = parameterCount();
  if (!with_jacobians_) {
    if (jacobians != nullptr)
      for (int g = 0; g < ghosts_; ++g)
        if (jacobians[g] != nullptr)
          throw std::logic_error("NormalEquations: Jacobian asked of a fill without derivatives");
    residuals[0] = std::sqrt(c_);
    std::fill(residuals + 1, residuals + n_total + 1, 0.0);
    return;
  }
  std::copy_n(root_.residuals.data(), n_total, residuals);
  residuals[n_total] = root_.rest;
  if (jacobians == nullptr) return;
  for (int g = 0; g < ghosts_; ++g) {
    if (jacobians[g] == nullptr) continue;
    Eigen::Map<RowMajor> block(jacobians[g], n_total + 1, n_);
    block.topRows(n_total) = root_.jacobian.middleCols(g * n_, n_);
    block.row(n_total).setZero();
  }
}

}  // namespace flarekit::fit
