// The horizon, the light and the optical zero, measured on pan captures of known geometry.
#include "fit/horizon.h"

#include <gtest/gtest.h>

#include "fit/testing.h"

namespace flarekit::fit {
namespace {

using testing::anglesFrom;
using testing::PanScene;

TEST(HorizonOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(HorizonOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(OpticalZeroOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(LightPatternOptions{}.IsValid(&error)) << error;
  HorizonOptions bad;
  bad.frame_stride = 0;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("frame_stride"), std::string::npos);
}

TEST(Horizon, IsTheRowTheFlareIsSymmetricAbout) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 4, 0.2));
  const Horizon h = measureHorizon(stack);
  EXPECT_NEAR(h.y_px, scene.horizon_y, 0.3);
  ASSERT_EQ(h.lights.size(), stack.frames.size());
  EXPECT_EQ(h.lights_found, static_cast<int>(stack.frames.size()));
  // The centroid of a clipped core 4 px across is quantised to about a tenth of a pixel.
  for (size_t i = 0; i < stack.frames.size(); ++i) {
    EXPECT_NEAR(h.lights[i].center.x, scene.lightX(stack.frames[i].angle_deg), 0.15) << i;
    EXPECT_NEAR(h.lights[i].center.y, scene.horizon_y, 0.15) << i;
  }
}

TEST(Horizon, AGhostIsNoLight) {
  // Without a clipped core, the brightest ghost does not stand far enough above the frame's
  // brightest part to be taken for the light.
  PanScene scene;
  scene.light_radius_px = 0;
  const Horizon h = measureHorizon(scene.stack(anglesFrom(0, 2, 0.2)));
  EXPECT_EQ(h.lights_found, 0);
}

TEST(OpticalZero, IsWhereEveryGhostsCentreMeetsTheLight) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  std::vector<CentreSamples> centres(scene.ghosts.size());
  for (size_t g = 0; g < scene.ghosts.size(); ++g)
    for (const auto& f : stack.frames) {
      const auto p = scene.ghostAt(g, f.angle_deg);
      if (p.center_x < 0 || p.center_x > stack.size.width) continue;
      centres[g].angles_deg.push_back(f.angle_deg);
      centres[g].centre_x_px.push_back(p.center_x);
    }
  const OpticalZero zero = measureOpticalZero(stack, h, centres);
  ASSERT_TRUE(zero.measured);
  EXPECT_EQ(zero.ghosts_used, 2);
  EXPECT_NEAR(zero.angle_zero_deg, scene.angle_zero_deg, 0.02);
  EXPECT_NEAR(zero.axis_x_px, scene.axis_x, 0.3);
  EXPECT_NEAR(zero.lightX(3), scene.lightX(3), 0.2);
}

TEST(OpticalZero, AWanderingTraceDoesNotMoveIt) {
  // A trace taken for a ghost's centre that is none: a hot spot 30 px beside the centre that
  // wanders by ±25 px from frame to frame. Each ghost's centres are weighed by their own spread,
  // so its many samples count for little beside a true ghost's few.
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  std::vector<CentreSamples> centres(2);
  for (size_t i = 0; i < stack.frames.size(); ++i) {
    const double angle = stack.frames[i].angle_deg;
    const auto g = scene.ghostAt(0, angle);
    if (angle < 2) {
      centres[0].angles_deg.push_back(angle);
      centres[0].centre_x_px.push_back(g.center_x);
    }
    centres[1].angles_deg.push_back(angle);
    centres[1].centre_x_px.push_back(g.center_x + 30 + (i % 2 ? 25 : -25));
  }
  const OpticalZero zero = measureOpticalZero(stack, h, centres);
  ASSERT_TRUE(zero.measured);
  EXPECT_NEAR(zero.angle_zero_deg, scene.angle_zero_deg, 0.02);
  EXPECT_NEAR(zero.axis_x_px, scene.axis_x, 0.3);
}

TEST(OpticalZero, WithoutGhostsTheZeroIsNotMeasured) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 3, 0.2));
  const OpticalZero zero = measureOpticalZero(stack, measureHorizon(stack), {});
  EXPECT_FALSE(zero.measured);
  EXPECT_EQ(zero.angle_zero_deg, 0);
}

TEST(LightPattern, TakesTheLightOutAndMasksItsCore) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 4, 0.2));
  const Horizon h = measureHorizon(stack);
  const LightPattern pattern = measureLightPattern(stack, h);
  ASSERT_FALSE(pattern.image.empty());
  cv::Mat image = stack.frames[5].image.clone(), valid = stack.frames[5].valid.clone();
  pattern.takeOut(h.lights[5], image, valid);
  // The core stays masked; far from the light nothing changes.
  const cv::Point core(static_cast<int>(h.lights[5].center.x), static_cast<int>(h.lights[5].center.y));
  EXPECT_EQ(valid.at<uchar>(core), 0);
  EXPECT_EQ(image.at<float>(10, 10), stack.frames[5].image.at<float>(10, 10));
}

}  // namespace
}  // namespace flarekit::fit
