// Tests of ghost detection in a residual: the light's own image, the search for veils that fill
// the frame, and veiling glare.
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

// Two discs on the axis at 30 σ: both found, or, under a floor that stands above the left one (the
// light's residue there, FitOptions::pixel_noise), only the right one.
TEST(DetectGhosts, KeepsBelowTheFloorOutAndFindsTheRest) {
  const cv::Size size(320, 214);
  const double sigma = 1e-3;
  const cv::Mat residual =
      noisy({disc(80, 107, 20, 30 * sigma), disc(240, 107, 20, 30 * sigma)}, size, sigma);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  const auto both = detectGhosts(residual, valid, sigma, kNoLight, DetectionOptions{});
  ASSERT_EQ(both.size(), 2u);
  cv::Mat floor(size, CV_32F, cv::Scalar(0));
  floor(cv::Rect(0, 0, 160, size.height)).setTo(40 * sigma);
  const auto right = detectGhosts(residual, valid, sigma, kNoLight, DetectionOptions{}, floor);
  ASSERT_EQ(right.size(), 1u);
  EXPECT_NEAR(right[0].seed.center_x, 240, 3);
}

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

// The glare's seed lies within the bounds its fit keeps it in (fit/cost.h fitBounds), for a
// small frame and for a 12-megapixel one, where 2 × (W + H) would be beyond the model's own
// bounds. A pedestal of 4σ all over the frame.
TEST(DetectGlare, SeedsWithinTheGlaresBoundsAtAnyFrameSize) {
  for (const cv::Size size : {cv::Size(320, 214), cv::Size(4000, 3000)}) {
    SCOPED_TRACE(size);
    const double sigma = 1e-3;
    const cv::Mat valid(size, CV_8U, cv::Scalar(255));
    cv::Mat residual(size, CV_32F);
    cv::theRNG().state = 7;
    cv::randn(residual, 4 * sigma, sigma);
    const auto glare = detectGlare(residual, valid, sigma, kNoLight, DetectionOptions{});
    ASSERT_TRUE(glare.has_value());
    ASSERT_TRUE(isGlare(glare->seed, size));
    const std::vector<double> v = model::toParameterVector(glare->seed);
    for (int k = 0; k < static_cast<int>(v.size()); ++k) {
      const auto b = fitBounds(k, 1, size, 1.0, true);
      EXPECT_GE(v[k], b.lower) << "parameter " << k;
      EXPECT_LE(v[k], b.upper) << "parameter " << k;
    }
  }
}

// A light 20 px from the frame's left border: its halo and the starburst's spikes reach 100 px into
// the frame, where the mirror points lie outside it. They are taken away there as well (the light
// is the same in every direction), the ghost beside them is kept.
TEST(EstimateLightImage, TakesTheLightAwayWhereItsMirrorIsOutsideTheFrame) {
  const cv::Size size(240, 160);
  const double sigma = 1e-3;
  LightImage light;
  light.found = true;
  light.center = {20, 80};
  light.core_radius_px = 4;
  light.zone_radius_px = 100;
  const GhostParameters ghost = disc(170, 80, 15, 30 * sigma);
  cv::Mat frame = noisy({ghost}, size, sigma);
  cv::Mat valid(size, CV_8U, cv::Scalar(255));
  // A radial halo and six spikes 3 px wide (a hexagonal aperture's), one of them upright: two
  // point into the frame from the light at ±30°, their mirror images out of it.
  auto light_at = [&](double dx, double dy) {
    const double rho = std::hypot(dx, dy);
    double spikes = 0;
    for (int k = 0; k < 6; ++k) {
      const double phi = CV_PI / 6 + k * CV_PI / 3;
      const double along = dx * std::cos(phi) + dy * std::sin(phi);
      const double across = -dx * std::sin(phi) + dy * std::cos(phi);
      if (along > 0) spikes += std::exp(-across * across / (3.0 * 3.0));
    }
    return sigma * std::exp(-rho / 15) * (2000 + 4000 * spikes);
  };
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double dx = x + 0.5 - light.center.x, dy = y + 0.5 - light.center.y;
      if (std::hypot(dx, dy) < light.core_radius_px) {
        valid.at<uchar>(y, x) = 0;
        frame.at<float>(y, x) = 1;
      } else {
        frame.at<float>(y, x) += static_cast<float>(light_at(dx, dy));
      }
    }
  const DetectionOptions options;
  const cv::Mat rest = frame - estimateLightImage(frame, valid, light, sigma, options);
  // Beyond the mirror's reach (x > 40), over the light's own region (the halo above
  // light_zone_sigma = 50 σ out to ρ = 55 px; ρ < 50 px here): a halo of 70–490 σ is left within
  // the noise, and spikes of up to 1500 σ within 10 σ (their centres lie at other offsets from the
  // pixel grid than the upright spike's, by which the rings measure them).
  std::vector<double> left_over;
  for (int y = 0; y < size.height; ++y)
    for (int x = 41; x < 70; ++x) {
      const double rho = std::hypot(x + 0.5 - light.center.x, y + 0.5 - light.center.y);
      if (rho < 50) left_over.push_back(std::abs(rest.at<float>(y, x)));
    }
  std::sort(left_over.begin(), left_over.end());
  EXPECT_LT(left_over[left_over.size() / 2], 1.5 * sigma);
  EXPECT_LT(left_over[left_over.size() * 99 / 100], 10 * sigma);
  // The ghost (where the halo is below 0.1 σ) keeps its brightness.
  EXPECT_NEAR(cv::mean(rest(cv::Rect(162, 72, 16, 16)))[0], 30 * sigma, 1 * sigma);
}

// A light leaving the frame as the rig turns (50 px per degree, core 35 px, zone 90 px): where the
// core touches the border, findLight's centroid of the visible clipped pixels stays near the edge
// and strays off the axis. Followed, the centre moves on with the frames before, until the zone
// misses the image; frames clear of the border are left as found.
TEST(FollowLight, CarriesTheCentreAcrossTheBorderOnTheLineOfTheFramesBefore) {
  const cv::Size size(640, 427);
  std::vector<LightImage> found;
  std::vector<double> angles, true_x;
  for (int i = 0; i <= 50; ++i) {
    const double theta = 0.2 * i, x = 321 - 50 * theta;
    angles.push_back(theta);
    true_x.push_back(x);
    LightImage l;
    if (x - 35 > 2) {
      l.found = true;
      l.center = {x, 213.5};
      l.core_radius_px = 35;
      l.zone_radius_px = 90;
    } else if (x > -35) {
      l.found = true;
      l.center = {std::max(x, 15.0), 213.5 + (i % 2 ? 25 : -20)};  // a spike's clipped piece
      l.core_radius_px = 10;
      l.zone_radius_px = 50;
    }
    found.push_back(l);
  }
  const std::vector<LightImage> lights = followLight(found, angles, size);
  ASSERT_EQ(lights.size(), found.size());
  int predicted = 0;
  for (size_t i = 0; i < lights.size(); ++i) {
    SCOPED_TRACE(angles[i]);
    if (true_x[i] - 35 > 2) {
      EXPECT_FALSE(lights[i].predicted);
      EXPECT_EQ(lights[i].center, found[i].center);
    } else if (true_x[i] > -90) {
      ASSERT_TRUE(lights[i].predicted);
      ++predicted;
      EXPECT_NEAR(lights[i].center.x, true_x[i], 1e-6);
      EXPECT_NEAR(lights[i].center.y, 213.5, 1e-6);
      EXPECT_NEAR(lights[i].core_radius_px, 35, 1e-9);
      EXPECT_NEAR(lights[i].zone_radius_px, 90, 1e-9);
    } else {
      EXPECT_FALSE(lights[i].predicted);  // its zone misses the image: as found (not at all)
      EXPECT_FALSE(lights[i].found);
    }
  }
  EXPECT_GE(predicted, 10);
}

// Beside a followed light, the pixels of its zone whose mirror point about it is outside the frame
// are left out; those whose mirror is inside, those beyond the zone, and any beside a light that
// was found stay.
TEST(ValidBesideLight, LeavesOutTheZoneWhereTheMirrorIsOutsideTheFrame) {
  const cv::Mat valid(200, 200, CV_8U, cv::Scalar(255));
  LightImage light;
  light.found = true;
  light.center = {30, 100};
  light.zone_radius_px = 50;
  light.core_radius_px = 20;
  EXPECT_EQ(cv::countNonZero(validBesideLight(valid, light)), 200 * 200);  // found, not predicted
  light.predicted = true;
  cv::Mat v = validBesideLight(valid, light);
  EXPECT_EQ(v.at<uchar>(100, 40), 255);  // mirror at x = 19.5
  EXPECT_EQ(v.at<uchar>(100, 70), 0);    // 40.5 px from the light, mirror at x = −10.5
  EXPECT_EQ(v.at<uchar>(100, 85), 255);  // beyond the zone
  light.center = {-10, 100};
  v = validBesideLight(valid, light);
  EXPECT_EQ(v.at<uchar>(100, 20), 0);
  EXPECT_EQ(v.at<uchar>(100, 45), 255);  // 55.5 px away
}

}  // namespace
}  // namespace flarekit::fit
