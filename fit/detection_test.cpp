// Tests of ghost detection in a residual: the search for veils that fill the frame.
#include "fit/detection.h"

#include <gtest/gtest.h>

#include "fit/cost.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

using model::GhostParameters;

GhostParameters disc(double x, double y, double radius, double intensity) {
  GhostParameters g;
  g.center_x = x;
  g.center_y = y;
  g.left = g.right = g.height = radius;
  g.curvature_left = g.curvature_right = model::kEllipseCurvature;
  g.border = {intensity, 0, 0};
  g.inside = {intensity, 0, 0};
  g.inside_falloff = 10;
  g.inside_exponent = 1;
  g.outside_falloff = 1;
  g.outside_exponent = 1;
  return g;
}

cv::Mat noisy(const std::vector<GhostParameters>& ghosts, cv::Size size, double sigma) {
  cv::Mat image = model::renderGhosts(ghosts, size, 1);
  cv::Mat n(size, CV_32F);
  cv::theRNG().state = 7;
  cv::randn(n, 0, sigma);
  return image + n;
}

// The light outside the frame (θ beyond the field): the flare axis is the horizontal line
// through the image centre.
const LightImage kNoLight;

// A disc far larger than the frame, centred off its left side, shows one arc crossing the frame
// at 15 σ on a pedestal of a second, fainter veil: one candidate, whose seed crosses the axis at
// the arc and reaches to the left (where the veil is).
TEST(DetectVeilEdges, FindsTheArcOfAVeilLargerThanTheFrame) {
  const cv::Size size(320, 214);
  const double sigma = 1e-3;
  const GhostParameters veil = disc(-150, 107, 330, 15 * sigma);   // its arc at x = 180
  const GhostParameters pedestal = disc(-400, 107, 700, 4 * sigma);  // covers the whole frame
  const cv::Mat residual = noisy({veil, pedestal}, size, sigma);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  const auto found = detectVeilEdges(residual, valid, sigma, kNoLight, DetectionOptions{});
  ASSERT_EQ(found.size(), 1u);
  const GhostParameters& g = found[0].seed;
  EXPECT_NEAR(g.center_y, 107, 1);
  EXPECT_NEAR(g.center_x + g.right, 180, 3);  // the seed's outline crosses the axis at the arc
  EXPECT_LT(g.center_x, 0);                   // and the seed lies on the bright side
  EXPECT_NEAR(g.border[0], 15 * sigma, 3 * sigma);
  // The blob is the band on the bright side, from the arc to the frame's left border.
  EXPECT_EQ(found[0].blob.x, 0);
  EXPECT_NEAR(found[0].blob.br().x, 180, 3);
}

// A ghost wholly inside the frame rises and falls again along the axis: that is a blob for
// detectGhosts, not a veil. Neither it nor noise alone gives a candidate; nor does a step below
// the threshold.
TEST(DetectVeilEdges, IgnoresGhostsInsideTheFrameNoiseAndFaintSteps) {
  const cv::Size size(320, 214);
  const double sigma = 1e-3;
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  const DetectionOptions options;
  EXPECT_TRUE(detectVeilEdges(noisy({disc(160, 107, 60, 30 * sigma)}, size, sigma), valid, sigma, kNoLight, options).empty());
  EXPECT_TRUE(detectVeilEdges(noisy({}, size, sigma), valid, sigma, kNoLight, options).empty());
  EXPECT_TRUE(detectVeilEdges(noisy({disc(-150, 107, 330, 3 * sigma)}, size, sigma), valid, sigma, kNoLight, options).empty());
}

// Many veils, each too faint to see, sum to a pedestal over the frame: one glare seed (a ghost
// with a long outside fall-off, fit/cost.h isGlare) at its level. Noise alone, or a bright ghost
// inside the frame on a dark background, gives none.
TEST(DetectGlare, SeedsGlareOnAPedestalAndNothingOnNoiseOrAGhost) {
  const cv::Size size(320, 214);
  const double sigma = 1e-3;
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  const DetectionOptions options;
  const auto glare = detectGlare(noisy({disc(-400, 107, 700, 4 * sigma)}, size, sigma), valid, sigma, kNoLight, options);
  ASSERT_TRUE(glare.has_value());
  EXPECT_TRUE(isGlare(glare->seed, size));
  EXPECT_NEAR(glare->seed.border[0], 4 * sigma, 0.5 * sigma);
  EXPECT_NEAR(glare->seed.center_y, 107, 1);
  EXPECT_FALSE(detectGlare(noisy({}, size, sigma), valid, sigma, kNoLight, options).has_value());
  EXPECT_FALSE(detectGlare(noisy({disc(160, 107, 60, 30 * sigma)}, size, sigma), valid, sigma, kNoLight, options).has_value());
}

}  // namespace
}  // namespace flarekit::fit
