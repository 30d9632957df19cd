// Tests of describeCeresEnd, which `flarekit bench fit` uses to say why Ceres ended above the
// gradient descent's cost: a stall on a slope, or a basin of the GD's own.
#include "fit/optimizer_bench.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "fit/group_solver.h"
#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

using model::GhostParameters;
using testing::ghost;

TEST(DescribeCeresEnd, AnotherGhostOfTheFrameIsABasinOfItsOwn) {
  // Two equal ghosts: Ceres, seeded beside the left one, fits it; the right one is as good an end.
  // Between them the model leaves both, so the cost rises before it falls: not a stall.
  const cv::Size size(160, 80);
  const GhostParameters left = ghost(40, 40, 14, 14, 12, 1.0, 0.5), right = ghost(120, 40, 14, 14, 12, 1.0, 0.5);
  const std::vector<GhostParameters> both = {left, right};
  const cv::Mat frame = model::renderGhosts(both, size, 1);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  options.prior_fraction = 0;  // the region is the whole frame; no pull towards the seed
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  GhostParameters seed = left;
  seed.center_x += 2;
  seed.left += 1;
  // A seed as wide as the frame, so that the cost's region covers both ghosts.
  GhostParameters wide = seed;
  wide.outside_falloff = 80;
  wide.outside_exponent = 1;
  const std::vector<GhostParameters> seeds = {wide};
  GroupCost cost(data, edge, {}, seeds, options);
  std::vector<GhostParameters> start = {seed};
  const GroupFitResult r = solveGroup(cost, start, SolverOptions{});
  ASSERT_NEAR(r.ghosts[0].center_x, 40, 0.2);
  const CeresEnd end = describeCeresEnd(cost, r.ghosts[0], right);
  ASSERT_EQ(end.path_costs.size(), 11u);
  EXPECT_NEAR(end.path_costs.front(), r.final_cost, 1e-9 * r.final_cost);
  EXPECT_FALSE(end.stalled);
  const double highest = *std::max_element(end.path_costs.begin(), end.path_costs.end());
  EXPECT_GT(highest, 2 * end.path_costs.front());  // the other ghost unmodelled either way
  EXPECT_NEAR(end.path_costs.back(), end.path_costs.front(), 0.2 * end.path_costs.front());
  EXPECT_TRUE(end.on_bounds.empty());
}

TEST(DescribeCeresEnd, ASlopeTowardsTheOtherEndIsAStallAndTheBoundIsNamed) {
  // Ceres's end taken 3 px left of the ghost with its outside fall-off on its bound; the other end
  // is the ghost itself. The cost falls from the first towards the second: a stall, on Fo's bound.
  const cv::Size size(100, 80);
  const GhostParameters truth = ghost(50, 40, 20, 20, 16, 1.0, 0.5);
  const std::vector<GhostParameters> one = {truth};
  const cv::Mat frame = model::renderGhosts(one, size, 1);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  GhostParameters stuck = truth;
  stuck.center_x -= 3;
  stuck.outside_falloff = kSharpOutsideFalloffFraction * std::hypot(size.width, size.height);
  const std::vector<GhostParameters> seeds = {stuck};
  GroupCost cost(data, edge, {}, seeds, options);
  const CeresEnd end = describeCeresEnd(cost, stuck, truth);
  EXPECT_TRUE(end.stalled);
  EXPECT_LT(end.path_costs.back(), end.path_costs.front());
  EXPECT_EQ(end.on_bounds, std::vector<std::string>{"Fo"});
}

}  // namespace
}  // namespace flarekit::fit
