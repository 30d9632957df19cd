// The shades of overlapping ghosts and the pedestal by linear least squares, and the canonical
// shade that makes Fi, Ii and Ei well posed.
#include "fit/shade.h"

#include <gtest/gtest.h>

#include "fit/frame_fit.h"
#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

TEST(Shade, SolvesOverlappingGhostsAndThePedestalTogether) {
  const cv::Size size(160, 100);
  std::vector<model::GhostParameters> truth = {testing::ghost(60, 50, 30, 35, 28, 0.02, 0.01),
                                               testing::ghost(85, 50, 20, 20, 20, 0.012, 0.03)};
  model::Pedestal pedestal{1, {0.004, 0.001, 0.0, -0.002, 0.0, 0.001}};
  cv::Mat image = model::renderGhosts(truth, size, 1) + pedestal.image(size);
  cv::Mat noise(size, CV_32F);
  cv::RNG(5).fill(noise, cv::RNG::NORMAL, 0, 1e-4);
  image += noise;
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  std::vector<model::GhostParameters> ghosts = truth;
  for (auto& g : ghosts) g.border[0] = g.inside[0] = 0.05;  // far off
  model::Pedestal found;
  ShadeOptions options;
  options.level = 1;
  fitShades(image, valid, 1e-4, ghosts, &found, options);
  for (size_t g = 0; g < ghosts.size(); ++g) {
    EXPECT_NEAR(ghosts[g].border[0], truth[g].border[0], 0.02 * truth[g].border[0]) << g;
    EXPECT_NEAR(ghosts[g].inside[0], truth[g].inside[0], 0.02 * truth[g].inside[0]) << g;
  }
  ASSERT_EQ(found.coefficients.size(), 6u);
  EXPECT_NEAR(found.coefficients[0], 0.004, 2e-4);
}

// While the outlines are still being fitted they are a little off, and the misfit along their
// borders lies far above the noise: it is the model's error, not outliers to drop, and the shades
// stay those of the frame's light.
TEST(Shade, AnOutlineALittleOffKeepsTheFramesShades) {
  const cv::Size size(160, 100);
  const std::vector<model::GhostParameters> truth = {testing::ghost(60, 50, 30, 35, 28, 0.02, 0.01),
                                                     testing::ghost(85, 50, 20, 20, 20, 0.012, 0.03)};
  cv::Mat image = model::renderGhosts(truth, size, 1);
  cv::Mat noise(size, CV_32F);
  cv::RNG(5).fill(noise, cv::RNG::NORMAL, 0, 1e-6);
  image += noise + 0.001;
  std::vector<model::GhostParameters> ghosts = truth;
  for (auto& g : ghosts) {
    g.left *= 0.94;
    g.right *= 1.05;
    g.height *= 0.95;
  }
  model::Pedestal found;
  ShadeOptions options;
  options.level = 1;
  fitShades(image, cv::Mat(size, CV_8U, cv::Scalar(255)), 1e-6, ghosts, &found, options);
  for (size_t g = 0; g < ghosts.size(); ++g) {
    const double drawn = cv::sum(model::renderGhosts(std::vector{ghosts[g]}, size, 1))[0];
    const double light = cv::sum(model::renderGhosts(std::vector{truth[g]}, size, 1))[0];
    EXPECT_NEAR(drawn, light, 0.1 * light) << g;
  }
  EXPECT_NEAR(found.coefficients[0], 0.001, 2e-4);
}

TEST(Shade, OutlineValuesAreNeverNegative) {
  const cv::Size size(80, 60);
  const cv::Mat image = cv::Mat::zeros(size, CV_32F) + 0.001f;
  std::vector<model::GhostParameters> ghosts = {testing::ghost(40, 30, 10, 10, 10, 0.01, 0.01)};
  model::Pedestal pedestal;
  fitShades(image, cv::Mat(size, CV_8U, cv::Scalar(255)), 1e-4, ghosts, &pedestal);
  EXPECT_GE(ghosts[0].border[0], 0);
  EXPECT_GE(ghosts[0].inside[0], 0);
}

TEST(CanonicalShade, DrawsTheSameImageWithTheFallOffWithinTheOutline) {
  model::GhostParameters g = testing::ghost(50, 40, 20, 24, 18, 0.02, 0.005);
  g.inside_falloff = 60;  // far deeper than any point of the outline lies
  g.inside_exponent = 1.7;
  const model::GhostParameters c = canonicalShade(g);
  EXPECT_LE(c.inside_falloff, std::min(g.height, 0.5 * (g.left + g.right)) + 1e-12);
  const cv::Mat a = model::renderGhosts(std::vector{g}, cv::Size(100, 80), 1);
  const cv::Mat b = model::renderGhosts(std::vector{c}, cv::Size(100, 80), 1);
  EXPECT_LT(cv::norm(a, b, cv::NORM_INF), 1e-7);
  // Already canonical: unchanged.
  EXPECT_EQ(model::toParameterVector(canonicalShade(c)), model::toParameterVector(c));
}

}  // namespace
}  // namespace flarekit::fit
