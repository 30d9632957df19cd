// Tests of the cost and the group solver: the edge filter, analytic Jacobians against
// ceres::GradientChecker, and round trips (render ghosts with known parameters, fit, recover them)
// for both optimizers.
#include "fit/cost.h"

#include <random>

#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <glog/logging.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "common/log.h"
#include "fit/group_solver.h"
#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

using model::GhostParameters;
using testing::ghost;

cv::Mat addNoise(const cv::Mat& image, double sigma, unsigned seed) {
  cv::Mat noisy = image.clone();
  cv::Mat n(image.size(), image.type());
  cv::theRNG().state = seed;
  cv::randn(n, 0, sigma);
  noisy += n;
  return noisy;
}

TEST(CostOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(CostOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(SolverOptions{}.IsValid(&error)) << error;
  CostOptions bad;
  bad.edge_sigma1_px = 0;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("sigma1"), std::string::npos);
}

// A fit's bounds stay within the model's own, so that a fit of a frame from a 24-megapixel camera
// is a valid ghost.
TEST(FitBounds, StayWithinTheModelsBounds) {
  for (const cv::Size size : {cv::Size(160, 100), cv::Size(640, 427), cv::Size(6000, 4000),
                              cv::Size(9000, 6000)}) {
    SCOPED_TRACE(size);
    for (int k = 0; k < model::parameterCount(1); ++k) {
      const auto b = fitBounds(k, 1, size, 1e6);
      const auto m = model::parameterBounds(k, 1);
      EXPECT_LE(b.lower, b.upper) << k;
      EXPECT_GE(b.lower, m.lower) << k;
      EXPECT_LE(b.upper, m.upper) << k;
    }
  }
}

TEST(EdgeFilter, IgnoresConstantsAndRespondsToEdges) {
  EdgeFilter e{CostOptions{}};
  cv::Mat flat(40, 40, CV_32F, cv::Scalar(3.0));
  cv::Mat response = e.apply(flat);
  EXPECT_LT(cv::norm(response, cv::NORM_INF), 1e-5);
  cv::Mat step = cv::Mat::zeros(40, 40, CV_32F);
  step(cv::Rect(20, 0, 20, 40)).setTo(1.0);
  response = e.apply(step);
  // A Laplacian of Gaussian crosses zero at the edge, negative on the bright side.
  EXPECT_GT(response.at<float>(20, 18), 0.02);
  EXPECT_LT(response.at<float>(20, 21), -0.02);
  EXPECT_NEAR(response.at<float>(20, 5), 0, 1e-4);
}

// A frame like the Heliar's beyond 10°: veils larger than the frame, each a plateau 20–50 σ
// above the next, cover most of it. Their steps are no noise.
TEST(EstimatePixelNoiseSigma, FrameFillingVeilsDoNotInflateIt) {
  const cv::Size size(240, 160);
  const double sigma = 1e-3;
  const std::vector<GhostParameters> veils = {ghost(40, 80, 150, 150, 150, 0.05, 0.05),
                                              ghost(-20, 80, 200, 200, 200, 0.03, 0.03),
                                              ghost(100, 80, 60, 60, 60, 0.02, 0.02)};
  const cv::Mat clean = model::renderGhosts(veils, size, 1);
  const cv::Mat frame = addNoise(clean, sigma, 5);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  EXPECT_NEAR(estimatePixelNoiseSigma(frame, valid), sigma, 0.1 * sigma);
  // Only the valid pixels count: saturated ones (here a tenth of the frame, flat) are left out.
  cv::Mat flat = frame.clone();
  flat(cv::Rect(0, 0, 24, 160)).setTo(1.0);
  valid(cv::Rect(0, 0, 24, 160)).setTo(0);
  EXPECT_NEAR(estimatePixelNoiseSigma(flat, valid), sigma, 0.1 * sigma);
}

// Over 4 px blocks the noise of an RGGB mosaic demosaiced is the photosites' again, where per
// pixel the demosaic halves it; a mono frame's is its σ either way, veils and all.
TEST(EstimatePixelNoiseSigma, OverBlocksADemosaicDoesNotLowerIt) {
  const cv::Size size(320, 240);
  const double sigma = 1e-4;
  cv::Mat white(size, CV_32F);
  cv::RNG(11).fill(white, cv::RNG::NORMAL, 0, sigma);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  const cv::Mat demosaiced = testing::bayerLuminance(white);
  EXPECT_LT(estimatePixelNoiseSigma(demosaiced, valid), 0.6 * sigma);
  EXPECT_NEAR(estimatePixelNoiseSigma(demosaiced, valid, kNoiseBlockPx), sigma, 0.1 * sigma);
  EXPECT_NEAR(estimatePixelNoiseSigma(white, valid, kNoiseBlockPx), sigma, 0.1 * sigma);
  const std::vector<GhostParameters> veils = {ghost(40, 120, 250, 250, 250, 0.005, 0.005),
                                              ghost(200, 120, 90, 90, 90, 0.002, 0.002)};
  const cv::Mat veiled = model::renderGhosts(veils, size, 1) + white;
  EXPECT_NEAR(estimatePixelNoiseSigma(veiled, valid, kNoiseBlockPx), sigma, 0.15 * sigma);
  // Blocks with an invalid pixel are left out: a saturated, flat stripe changes nothing.
  cv::Mat flat = white.clone(), part = valid.clone();
  flat(cv::Rect(0, 0, 30, 240)).setTo(1.0);
  part(cv::Rect(0, 0, 30, 240)).setTo(0);
  EXPECT_NEAR(estimatePixelNoiseSigma(flat, part, kNoiseBlockPx), sigma, 0.1 * sigma);
}

TEST(GroupCost, AnalyticJacobianMatchesGradientChecker) {
  const cv::Size size(96, 72);
  const std::vector<GhostParameters> truth = {ghost(44, 36, 18, 22, 15, 1.0, 0.4),
                                              ghost(62, 38, 14, 13, 13, 0.5, 0.7)};
  cv::Mat frame = model::renderGhosts(truth, size, 1);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  options.loss_scale = 0;
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  // Evaluate away from the truth so that residuals are not zero, and with no pixel centre exactly
  // on a kink of the model (e.g. at Mx + R + Fo, where the derivative is one-sided).
  std::vector<GhostParameters> at = {ghost(45.3, 35.2, 17, 23.5, 14.2, 0.9, 0.45),
                                     ghost(61.2, 38.7, 14.6, 12.45, 13.4, 0.55, 0.6)};
  GroupCost cost(data, edge, {}, at, options);
  auto function = makeGroupCostFunction(cost);
  ceres::NumericDiffOptions numeric;
  // Small steps: the fall-off ends (d = −Fi, d = Fo) are kinks, and a larger step averages across
  // them on every pixel it straddles.
  numeric.relative_step_size = 1e-5;
  const std::vector<const ceres::Manifold*>* no_manifolds = nullptr;
  ceres::GradientChecker checker(function.get(), no_manifolds, numeric);
  std::vector<std::vector<double>> blocks;
  for (const auto& g : at) blocks.push_back(model::toParameterVector(g));
  std::vector<const double*> pointers = {blocks[0].data(), blocks[1].data()};
  ceres::GradientChecker::ProbeResults results;
  checker.Probe(pointers.data(), 1e-2, &results);
  ASSERT_TRUE(results.return_value);
  // Pixels that straddle the model's kinks (d = 0, −Fi, Fo) differ in a few entries; every
  // parameter's Jacobian column must agree as a whole.
  for (int g = 0; g < 2; ++g) {
    const auto& analytic = results.jacobians[g];
    const auto& numeric_j = results.numeric_jacobians[g];
    for (int k = 0; k < analytic.cols(); ++k) {
      const double diff = (analytic.col(k) - numeric_j.col(k)).norm();
      const double norm = numeric_j.col(k).norm();
      EXPECT_LT(diff, 0.05 * norm + 1e-6)
          << "ghost " << g << " parameter " << model::parameterName(k, 1) << ": |analytic| "
          << analytic.col(k).norm() << " |numeric| " << norm;
    }
  }
}

// The solver sums the samples' rows with the loss per pixel in them (GroupCost::robustSample,
// fit/normal_equations.h). Summed over the samples, the weighted residuals and their rests must
// give the cost exactly, and the weighted Jacobians times the weighted residuals its gradient, here
// with pixels far in the Cauchy loss's outlier range (an unmodelled blob beside the ghost).
TEST(GroupCost, RobustSamplesGiveTheCostAndItsGradient) {
  const cv::Size size(96, 72);
  cv::Mat frame = model::renderGhosts(std::vector{ghost(44, 36, 18, 22, 15, 1.0, 0.4)}, size, 1);
  cv::circle(frame, {70, 36}, 6, cv::Scalar(3.0), cv::FILLED);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  options.prior_fraction = 0;  // the prior is its own residual block
  ASSERT_GT(options.loss_scale, 0);
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  const std::vector<GhostParameters> at = {ghost(45.3, 35.2, 17, 23.5, 14.2, 0.9, 0.45)};
  GroupCost cost(data, edge, {}, at, options);
  const double total = cost.evaluate(at, true);
  const int m = cost.residualsPerSample(), n = cost.parametersPerGhost();
  std::vector<double> r(m), J(static_cast<size_t>(m) * n), gradient(n, 0.0);
  double* jacobians[] = {J.data()};
  double sum = 0;
  int outliers = 0;
  for (size_t i = 0; i < cost.samples().size(); ++i) {
    const double rest = cost.robustSample(static_cast<int>(i), r.data(), jacobians);
    double weighted = 0;
    for (double v : r) weighted += v * v;
    outliers += rest > weighted;
    sum += 0.5 * (weighted + rest);
    for (int row = 0; row < m; ++row)
      for (int k = 0; k < n; ++k) gradient[k] += J[row * n + k] * r[row];
  }
  EXPECT_GT(outliers, 20);
  EXPECT_NEAR(sum, total, 1e-9 * total);
  // Central differences of the cost; the fall-off ends are kinks, so small steps.
  auto p = model::toParameterVector(at[0]);
  for (int k = 0; k < n; ++k) {
    const double h = 1e-5 * std::max(1.0, std::abs(p[k]));
    auto plus = p, minus = p;
    plus[k] += h;
    minus[k] -= h;
    const double numeric = (cost.evaluate(std::vector{model::fromParameterVector(plus, 1)}, false) -
                            cost.evaluate(std::vector{model::fromParameterVector(minus, 1)}, false)) /
                           (2 * h);
    EXPECT_NEAR(gradient[k], numeric, 0.02 * std::abs(numeric) + 1e-6) << model::parameterName(k, 1);
  }
}

struct RoundTrip {
  double center_error_px = 0;
  double size_error_px = 0;
  double intensity_error = 0;  // relative
  GroupFitResult result;
};

RoundTrip roundTrip(Optimizer optimizer, int channels, int gd_iterations = 400) {
  const cv::Size size(120, 90);
  std::vector<GhostParameters> truth = {ghost(50, 45, 20, 26, 17, 1.0, 0.35),
                                        ghost(72, 45, 12, 10, 11, 0.6, 0.9)};
  if (channels == 3)
    for (auto& g : truth) {
      g.channels = 3;
      g.border = {g.border[0], 0.8 * g.border[0], 0.5 * g.border[0]};
      g.inside = {g.inside[0], 1.1 * g.inside[0], 0.7 * g.inside[0]};
    }
  cv::Mat clean = model::renderGhosts(truth, size, channels);
  cv::Mat frame = addNoise(clean, 0.01, 7);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  std::vector<GhostParameters> seeds = truth;
  seeds[0].center_x += 2.5;
  seeds[0].left *= 0.85;
  seeds[0].height *= 1.15;
  seeds[1].center_x -= 2;
  seeds[1].center_y += 1;
  seeds[1].right *= 1.2;
  for (auto& s : seeds)
    for (int c = 0; c < channels; ++c) {
      s.border[c] *= 0.7;
      s.inside[c] *= 1.3;
    }
  GroupCost cost(data, edge, {}, seeds, options);
  SolverOptions solver;
  solver.optimizer = optimizer;
  solver.gd_max_iterations = gd_iterations;
  // Seeds 15–30 % off take more steps than the tracker's per-frame budget.
  solver.max_iterations = 50;
  RoundTrip out;
  out.result = solveGroup(cost, seeds, solver);
  for (size_t g = 0; g < truth.size(); ++g) {
    const auto& a = out.result.ghosts[g];
    const auto& t = truth[g];
    out.center_error_px = std::max({out.center_error_px, std::abs(a.center_x - t.center_x),
                                    std::abs(a.center_y - t.center_y)});
    out.size_error_px = std::max({out.size_error_px, std::abs(a.left - t.left),
                                  std::abs(a.right - t.right), std::abs(a.height - t.height)});
    for (int c = 0; c < channels; ++c)
      out.intensity_error = std::max(out.intensity_error, std::abs(a.border[c] / t.border[c] - 1));
  }
  return out;
}

TEST(SolveGroup, CeresRecoversOverlappingGhosts) {
  RoundTrip r = roundTrip(Optimizer::kCeres, 1);
  EXPECT_LT(r.center_error_px, 0.1);
  EXPECT_LT(r.size_error_px, 0.2);
  EXPECT_LT(r.intensity_error, 0.03);
  EXPECT_LT(r.result.final_cost, 0.05 * r.result.initial_cost);
}

TEST(SolveGroup, CeresRecoversRgbGhosts) {
  RoundTrip r = roundTrip(Optimizer::kCeres, 3);
  EXPECT_LT(r.center_error_px, 0.1);
  EXPECT_LT(r.size_error_px, 0.2);
  EXPECT_LT(r.intensity_error, 0.03);
}

TEST(SolveGroup, WalchGradientDescentLowersTheCost) {
  // The baseline moves in steps of lr × 0.5 px: it gets close, not exact (that is the point of
  // the comparison with Ceres in `flarekit bench fit`).
  RoundTrip r = roundTrip(Optimizer::kWalchGd, 1, 60);
  EXPECT_LT(r.result.final_cost, 0.5 * r.result.initial_cost);
  EXPECT_LT(r.center_error_px, 2.0);
}

TEST(SolveGroup, IgnoresSaturatedPixels) {
  const cv::Size size(100, 80);
  std::vector<GhostParameters> truth = {ghost(50, 40, 20, 20, 16, 1.0, 0.5)};
  cv::Mat frame = model::renderGhosts(truth, size, 1);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  // A clipped, wrong-valued patch across the ghost's border: masked, it must not bias the fit.
  frame(cv::Rect(25, 30, 12, 20)).setTo(50.0);
  valid(cv::Rect(25, 30, 12, 20)).setTo(0);
  CostOptions options;
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  std::vector<GhostParameters> seeds = truth;
  seeds[0].center_x += 2;
  seeds[0].left += 3;
  GroupCost cost(data, edge, {}, seeds, options);
  auto r = solveGroup(cost, seeds, SolverOptions{});
  EXPECT_NEAR(r.ghosts[0].center_x, 50, 0.1);
  EXPECT_NEAR(r.ghosts[0].left, 20, 0.2);
}

TEST(SolveGroup, ShapePriorHoldsWhatTheFrameDoesNotShow) {
  // A ghost whose right part lies beyond the frame's edge: its R is not in the data. The fit must
  // find what is seen (left edge Mx − L, h) from a seed 3–4 px off, and keep R near its seed
  // instead of letting it wander.
  const cv::Size size(100, 80);
  std::vector<GhostParameters> truth = {ghost(88, 40, 24, 24, 18, 1.0, 0.5)};
  cv::Mat frame = addNoise(model::renderGhosts(truth, size, 1), 0.01, 3);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  CostOptions options;
  EdgeFilter edge(options);
  FramePyramid data(frame, valid, edge);
  std::vector<GhostParameters> seeds = truth;
  seeds[0].center_x += 3;
  seeds[0].left += 4;
  seeds[0].right = 30;
  seeds[0].height -= 3;
  options.prior_fraction = 1.0;
  SolverOptions solver;
  solver.max_iterations = 50;
  GroupCost cost(data, edge, {}, seeds, options);
  auto r = solveGroup(cost, seeds, solver);
  const auto& g = r.ghosts[0];
  EXPECT_NEAR(g.center_x - g.left, 64, 0.2);
  EXPECT_NEAR(g.height, 18, 0.2);
  EXPECT_NEAR(g.center_x + g.right, seeds[0].center_x + seeds[0].right, 0.25 * 30);
}

// Ceres's warnings (e.g. its Levenberg–Marquardt's failed Cholesky steps, which it recovers from)
// go to FlareKit's log at debug level, so --quiet and the default level print none of them.
TEST(SolveGroup, CeresWarningsGoToTheLogAtDebugLevel) {
  routeSolverLogging();
  const LogLevel level = logLevel();
  setLogLevel(LogLevel::kInfo);
  ::testing::internal::CaptureStderr();
  LOG(WARNING) << "a Ceres warning";
  const std::string at_info = ::testing::internal::GetCapturedStderr();
  setLogLevel(LogLevel::kDebug);
  ::testing::internal::CaptureStderr();
  LOG(WARNING) << "a Ceres warning";
  LOG(ERROR) << "a Ceres error";
  const std::string at_debug = ::testing::internal::GetCapturedStderr();
  setLogLevel(level);
  EXPECT_EQ(at_info, "");
  EXPECT_NE(at_debug.find("debug: Ceres (cost_test.cpp:"), std::string::npos) << at_debug;
  EXPECT_NE(at_debug.find("a Ceres warning"), std::string::npos) << at_debug;
  EXPECT_NE(at_debug.find("flarekit: warning: Ceres (cost_test.cpp:"), std::string::npos)
      << at_debug;
  EXPECT_EQ(at_debug.find("Logging before InitGoogleLogging"), std::string::npos) << at_debug;
}

}  // namespace
}  // namespace flarekit::fit
