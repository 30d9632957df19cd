// Tests of the normal equations the Ceres solve sees: they must be those of the samples' own rows
// (sums of GroupCost::robustSample), and their square-root form must give Ceres the same normal
// equations, gradient and cost, whatever the thread count.
#include "fit/normal_equations.h"

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <tbb/task_arena.h>

#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

using model::GhostParameters;
using testing::ghost;

struct Direct {
  Eigen::MatrixXd a;
  Eigen::VectorXd b;
  double c = 0;
};

// JᵀJ, Jᵀr and Σ ρ from every sample's own rows.
Direct directSums(const GroupCost& cost) {
  const int m = cost.residualsPerSample(), n = cost.parametersPerGhost(), g_count = cost.ghostCount();
  const int total = g_count * n;
  Direct d{Eigen::MatrixXd::Zero(total, total), Eigen::VectorXd::Zero(total), 0};
  std::vector<double> r(m);
  std::vector<std::vector<double>> J(g_count, std::vector<double>(static_cast<size_t>(m) * n));
  std::vector<double*> pointers;
  for (auto& j : J) pointers.push_back(j.data());
  Eigen::MatrixXd rows(m, total);
  for (size_t i = 0; i < cost.samples().size(); ++i) {
    const double rest = cost.robustSample(static_cast<int>(i), r.data(), pointers.data());
    for (int g = 0; g < g_count; ++g)
      for (int row = 0; row < m; ++row)
        for (int k = 0; k < n; ++k) rows(row, g * n + k) = J[g][row * n + k];
    const Eigen::Map<const Eigen::VectorXd> rv(r.data(), m);
    d.a += rows.transpose() * rows;
    d.b += rows.transpose() * rv;
    d.c += rv.squaredNorm() + rest;
  }
  return d;
}

class NormalEquationsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const cv::Size size(120, 90);
    frame_ = model::renderGhosts(std::vector{ghost(50, 45, 20, 26, 17, 1.0, 0.35),
                                             ghost(72, 45, 12, 10, 11, 0.6, 0.9)},
                                 size, 1);
    cv::circle(frame_, {100, 20}, 5, cv::Scalar(3.0), cv::FILLED);  // outliers for the loss
    valid_ = cv::Mat(size, CV_8U, cv::Scalar(255));
    options_.prior_fraction = 0;
    // Away from the truth; the third ghost is too faint to matter and lies at the region's corner,
    // reaching few tiles, so whole tiles leave it out.
    at_ = {ghost(51.2, 44.1, 19, 27.5, 16.2, 0.9, 0.4), ghost(71.3, 46.2, 12.6, 9.4, 11.5, 0.55, 0.8),
           ghost(18, 20, 5, 5, 5, 0.01, 0.01)};
  }
  cv::Mat frame_, valid_;
  CostOptions options_;
  std::vector<GhostParameters> at_;
};

TEST_F(NormalEquationsTest, AreThoseOfTheSamplesRowsAndSoIsTheirSquareRoot) {
  EdgeFilter edge(options_);
  FramePyramid data(frame_, valid_, edge);
  GroupCost cost(data, edge, {}, at_, options_);
  const double total = cost.evaluate(at_, true);
  const Direct direct = directSums(cost);
  NormalEquations normal(cost);
  normal.fill(true);
  const int n = cost.parametersPerGhost(), N = normal.parameterCount();
  ASSERT_EQ(N, 3 * n);
  EXPECT_NEAR(normal.squaredNorm(), direct.c, 1e-12 * direct.c);
  EXPECT_NEAR(0.5 * normal.squaredNorm(), total, 1e-9 * total);
  EXPECT_LT((normal.jtj() - direct.a).norm(), 1e-12 * direct.a.norm());
  EXPECT_LT((normal.jtr() - direct.b).norm(), 1e-12 * direct.b.norm());

  // The square-root form as Ceres reads it: N + 1 residuals, one Jacobian block per ghost.
  std::vector<double> residuals(normal.squareRootRows());
  std::vector<std::vector<double>> blocks(3, std::vector<double>(static_cast<size_t>(N + 1) * n));
  std::vector<double*> pointers;
  for (auto& b : blocks) pointers.push_back(b.data());
  normal.squareRoot(residuals.data(), pointers.data());
  Eigen::MatrixXd J(N + 1, N);
  for (int g = 0; g < 3; ++g)
    for (int row = 0; row <= N; ++row)
      for (int k = 0; k < n; ++k) J(row, g * n + k) = blocks[g][row * n + k];
  const Eigen::Map<const Eigen::VectorXd> r(residuals.data(), N + 1);
  EXPECT_LT((J.transpose() * J - direct.a).norm(), 1e-9 * direct.a.norm());
  EXPECT_LT((J.transpose() * r - direct.b).norm(), 1e-9 * direct.b.norm());
  EXPECT_NEAR(r.squaredNorm(), direct.c, 1e-9 * direct.c);
  EXPECT_EQ(J.row(N).norm(), 0.0);  // the rest is constant

  // Without derivatives: the cost only.
  cost.evaluate(at_, false);
  normal.fill(false);
  normal.squareRoot(residuals.data(), nullptr);
  EXPECT_NEAR(r.squaredNorm(), direct.c, 1e-12 * direct.c);
}

TEST_F(NormalEquationsTest, DoNotDependOnTheThreadCount) {
  EdgeFilter edge(options_);
  FramePyramid data(frame_, valid_, edge);
  GroupCost cost(data, edge, {}, at_, options_);
  cost.evaluate(at_, true);
  NormalEquations many(cost), one(cost);
  many.fill(true);
  tbb::task_arena(1).execute([&] { one.fill(true); });
  EXPECT_EQ(many.squaredNorm(), one.squaredNorm());
  EXPECT_TRUE(many.jtj() == one.jtj());
  EXPECT_TRUE(many.jtr() == one.jtr());
}

}  // namespace
}  // namespace flarekit::fit
