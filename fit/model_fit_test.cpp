// The model fit: every ghost's parameters as polynomials over θ that draw the frames they were
// fitted from, overlapping ghosts and ghosts that fade out included.
#include "fit/model_fit.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

// Two nested ghosts moving with the light: the outer one fades out and is dark over the last third
// of the range (its shade is 0 there, as a ghost's cut off by an aperture is), the inner one
// brightens. Their frame fits have the true outlines, and shades traded between the two from frame
// to frame, as overlapping ghosts' fits do.
struct NestedScene {
  cv::Size size{200, 120};
  std::vector<double> angles = testing::anglesFrom(0, 8, 0.25);

  model::GhostParameters ghost(int g, double angle) const {
    const double fade = std::max(0.0, 1 - angle / 5.5);
    return g == 0 ? testing::ghost(70 + 8 * angle, 60.3, 40, 44, 38, 0.02 * fade, 0.012 * fade)
                  : testing::ghost(75 + 7 * angle, 60.3, 24, 26, 22, 0.006 + 0.001 * angle, 0.01);
  }
  FrameStack stack() const {
    FrameStack s;
    s.size = size;
    s.channels = 1;
    s.info.image_size = size;
    s.info.angle_step_deg = angles[1] - angles[0];
    s.info.f_number = 4;
    s.info.iso = 100;
    s.info.exposure_s = 0.01;
    s.info.pixel_pitch_um = 4;
    cv::RNG rng(3);
    for (size_t i = 0; i < angles.size(); ++i) {
      Frame f;
      f.index = static_cast<int>(i);
      f.angle_deg = angles[i];
      f.image = truth(angles[i]);
      cv::Mat noise(size, CV_32F);
      rng.fill(noise, cv::RNG::NORMAL, 0, 1e-4);
      f.image += noise;
      f.valid = cv::Mat(size, CV_8U, cv::Scalar(255));
      s.frames.push_back(std::move(f));
    }
    return s;
  }
  cv::Mat truth(double angle) const {
    const std::vector<model::GhostParameters> both = {ghost(0, angle), ghost(1, angle)};
    return model::renderGhosts(both, size, 1);
  }
};

double psnr(const cv::Mat& truth, const cv::Mat& image) {
  double peak = 0;
  cv::minMaxLoc(truth, nullptr, &peak);
  const double mse = cv::norm(truth, image, cv::NORM_L2SQR) / static_cast<double>(truth.total());
  return 10 * std::log10(peak * peak / mse);
}

// The scene's two ghosts as candidates over every frame and their frame fits at every other frame,
// shades traded between the two; `phantom` adds a third candidate where the frames have no light
// (a border trace of no ghost), fitted there with the inner ghost's shades.
struct SceneFits {
  std::vector<GhostCandidate> candidates;
  std::vector<FrameFit> fits;
};
SceneFits sceneFits(const NestedScene& scene, const FrameStack& stack, bool phantom) {
  const int n = static_cast<int>(stack.frames.size());
  SceneFits out;
  const int ghosts = phantom ? 3 : 2;
  out.candidates.resize(ghosts);
  for (int g = 0; g < ghosts; ++g) {
    out.candidates[g].id = g;
    out.candidates[g].first_row = 0;
    out.candidates[g].last_row = n - 1;
    out.candidates[g].left_seen.assign(n, true);
    out.candidates[g].right_seen.assign(n, true);
  }
  for (int i = 0; i < n; i += 2) {
    FrameFit f;
    f.frame = i;
    f.angle_deg = stack.frames[i].angle_deg;
    f.noise_sigma = 1e-4;
    f.ghost_ids = {0, 1};
    model::GhostParameters outer = scene.ghost(0, f.angle_deg), inner = scene.ghost(1, f.angle_deg);
    const double traded = (i / 2) % 2 ? 0.8 * inner.inside[0] : -0.8 * outer.inside[0];
    outer.inside[0] = std::max(0.0, outer.inside[0] + traded);
    inner.inside[0] = std::max(0.0, inner.inside[0] - traded);
    f.ghosts = {outer, inner};
    if (phantom) {
      model::GhostParameters none = inner;
      none.center_x = 165;
      none.left = none.right = 12;
      none.height = 10;
      f.ghost_ids.push_back(2);
      f.ghosts.push_back(none);
    }
    out.fits.push_back(f);
  }
  return out;
}

model::FlareModel fitScene(const NestedScene& scene, const FrameStack& stack, bool phantom,
                           const ModelFitOptions& options) {
  Horizon horizon;
  horizon.y_px = 60.3;
  horizon.lights.resize(stack.frames.size());  // no light in these frames
  const SceneFits s = sceneFits(scene, stack, phantom);
  OpticalZero zero;
  zero.axis_x_px = 100;
  return fitModel(stack, horizon, LightPattern{}, s.candidates, s.fits, zero, options);
}

model::FlareModel fitScene(const NestedScene& scene, const FrameStack& stack, bool phantom) {
  ModelFitOptions options;
  options.pedestal = false;
  return fitScene(scene, stack, phantom, options);
}

TEST(ModelFit, DrawsNestedGhostsWhoseFramesTradedTheirShades) {
  const NestedScene scene;
  const FrameStack stack = scene.stack();
  const model::FlareModel m = fitScene(scene, stack, false);
  std::string error;
  EXPECT_TRUE(m.IsValid(&error)) << error;  // the faded ghost's shade stays ≥ 0 over its range
  ASSERT_EQ(m.ghosts.size(), 2u);
  // Against the noise-free frames: close everywhere, and closest away from the kink where the
  // outer ghost's fade reaches 0 (which a polynomial rounds).
  std::vector<double> scores;
  for (double angle : scene.angles) {
    std::vector<model::GhostParameters> drawn;
    for (const auto& g : m.ghostsAt(angle)) drawn.push_back(g.parameters);
    scores.push_back(psnr(scene.truth(angle), model::renderGhosts(drawn, scene.size, 1)));
    EXPECT_GT(scores.back(), 26) << angle << " deg";
  }
  std::nth_element(scores.begin(), scores.begin() + scores.size() / 2, scores.end());
  EXPECT_GT(scores[scores.size() / 2], 40);
}

// Refined against the frames, the model still draws them: the ghosts are refined against the
// frames less the veil under them (the pedestal the shades find), which they do not draw.
TEST(ModelFit, RefinedGhostsDoNotDrawTheVeilUnderThem) {
  const NestedScene scene;
  FrameStack stack = scene.stack();
  model::Pedestal veil;
  veil.coefficients = {0.004, 0.003, 0, 0, 0, 0};  // brighter to the right, a fifth of the ghosts' peak
  for (auto& f : stack.frames) f.image += veil.image(scene.size);
  ModelFitOptions options;
  options.refine = true;
  const model::FlareModel m = fitScene(scene, stack, false, options);
  ASSERT_EQ(m.ghosts.size(), 2u);
  std::vector<double> ghosts, frames;
  for (double angle : scene.angles) {
    std::vector<model::GhostParameters> drawn;
    for (const auto& g : m.ghostsAt(angle)) drawn.push_back(g.parameters);
    cv::Mat image = model::renderGhosts(drawn, scene.size, 1);
    ghosts.push_back(psnr(scene.truth(angle), image));
    m.pedestalAt(angle).addTo(image, scene.size);
    frames.push_back(psnr(scene.truth(angle) + veil.image(scene.size), image));
  }
  for (auto* scores : {&ghosts, &frames})
    std::nth_element(scores->begin(), scores->begin() + scores->size() / 2, scores->end());
  EXPECT_GT(ghosts[ghosts.size() / 2], 35);
  EXPECT_GT(frames[frames.size() / 2], 40);
}

// A ghost is in the model where it draws light: a candidate the frames show no light for is none.
TEST(ModelFit, ACandidateWithoutLightIsNoGhost) {
  const NestedScene scene;
  const FrameStack stack = scene.stack();
  const model::FlareModel m = fitScene(scene, stack, true);
  ASSERT_EQ(m.ghosts.size(), 2u);
  EXPECT_EQ(m.ghosts[0].id, 0);
  EXPECT_EQ(m.ghosts[1].id, 1);
}

}  // namespace
}  // namespace flarekit::fit
