// Light geometry: lights placed at known angles give the expected θ and φ (docs/design.md
// conventions), behind-camera and out-of-range lights are recognised.
#include "predict/geometry.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "common/error.h"

namespace flarekit::predict {
namespace {

constexpr double kRad = std::numbers::pi / 180.0;

// A camera at the origin looking down −z with y up (the glTF default): image right is +x.
SceneCamera defaultCamera() {
  SceneCamera c;
  c.pose.position = {0, 0, 0};
  c.pose.look_at = {0, 0, -1};
  c.pose.up = {0, 1, 0};
  c.focal_length_mm = 24;
  c.sensor_width_mm = 36;
  c.sensor_height_mm = 24;
  return c;
}

// A light at `distance` seen `azimuth_deg` to the right of the axis and `elevation_deg` above it.
SceneLight lightAt(double azimuth_deg, double elevation_deg, double distance = 10) {
  SceneLight l;
  l.kind = LightKind::kIntensity;
  l.intensity_cd = 100;
  const double a = azimuth_deg * kRad, e = elevation_deg * kRad;
  l.position = {distance * std::sin(a) * std::cos(e), distance * std::sin(e), -distance * std::cos(a) * std::cos(e)};
  return l;
}

const AngleRange kRange{-30, 30};
const cv::Size kSize{600, 400};

TEST(CameraFrame, AxesOfTheDefaultCamera) {
  const CameraFrame f = CameraFrame::fromPose(defaultCamera().pose);
  EXPECT_NEAR(f.right[0], 1, 1e-12);
  EXPECT_NEAR(f.down[1], -1, 1e-12);
  EXPECT_NEAR(f.forward[2], -1, 1e-12);
}

TEST(CameraFrame, RejectsDegeneratePoses) {
  CameraPose p;
  p.position = {1, 2, 3};
  p.look_at = {1, 2, 3};
  EXPECT_THROW(CameraFrame::fromPose(p), InputError);
  p.look_at = {1, 5, 3};
  p.up = {0, 1, 0};  // parallel to the view
  EXPECT_THROW(CameraFrame::fromPose(p), InputError);
}

TEST(LightGeometry, OnAxisLightHasZeroAngle) {
  const auto g = lightGeometry(lightAt(0, 0), defaultCamera().pose, defaultCamera(), kRange, kSize);
  EXPECT_EQ(g.status, LightStatus::kInRange);
  EXPECT_NEAR(g.angle_deg, 0, 1e-9);
  EXPECT_NEAR(g.image_px.x, 300, 1e-9);
  EXPECT_NEAR(g.image_px.y, 200, 1e-9);
  EXPECT_TRUE(g.in_frame);
}

TEST(LightGeometry, HorizontalLightsGiveThetaAndRollZeroOr180) {
  const SceneCamera cam = defaultCamera();
  // Left of the axis: the light's image is at −x, which is roll 0 for positive θ.
  auto left = lightGeometry(lightAt(-20, 0), cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(left.angle_deg, 20, 1e-9);
  EXPECT_NEAR(left.roll_deg, 0, 1e-9);
  EXPECT_NEAR(left.model_angle_deg, 20, 1e-9);
  // Image position: f_px · tan θ left of the centre, f_px = 24 / 36 · 600 = 400.
  EXPECT_NEAR(left.image_px.x, 300 - 400 * std::tan(20 * kRad), 1e-9);
  EXPECT_NEAR(left.image_px.y, 200, 1e-9);
  auto right = lightGeometry(lightAt(20, 0), cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(right.angle_deg, 20, 1e-9);
  EXPECT_NEAR(right.roll_deg, 180, 1e-9);
}

TEST(LightGeometry, VerticalLightsRollCounterClockwiseAsDisplayed) {
  const SceneCamera cam = defaultCamera();
  // Above the axis: image up (−y): rotating the left direction counter-clockwise on screen by 270°.
  auto up = lightGeometry(lightAt(0, 12), cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(up.angle_deg, 12, 1e-9);
  EXPECT_NEAR(up.roll_deg, 270, 1e-9);
  EXPECT_LT(up.image_px.y, 200);
  auto down = lightGeometry(lightAt(0, -12), cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(down.roll_deg, 90, 1e-9);
}

TEST(LightGeometry, DiagonalLightAngleFromTheDotProduct) {
  const SceneCamera cam = defaultCamera();
  auto g = lightGeometry(lightAt(10, 10), cam.pose, cam, kRange, kSize);
  // cos θ = cos(az)·cos(el) for this placement.
  EXPECT_NEAR(g.angle_deg, std::acos(std::cos(10 * kRad) * std::cos(10 * kRad)) / kRad, 1e-9);
  EXPECT_GT(g.roll_deg, 180);
  EXPECT_LT(g.roll_deg, 270);
}

TEST(LightGeometry, CameraPoseIsRespected) {
  // The camera turned 90° to the left (looking down −x): a light at −x is on its axis.
  SceneCamera cam = defaultCamera();
  cam.pose.position = {5, 1, 2};
  cam.pose.look_at = {4, 1, 2};
  SceneLight l;
  l.position = {-10, 1, 2};
  auto g = lightGeometry(l, cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(g.angle_deg, 0, 1e-9);
  // And a light towards −z is now to the camera's right.
  l.position = {5 - 10, 1, 2 - 10 * std::tan(15 * kRad)};
  g = lightGeometry(l, cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(g.angle_deg, 15, 1e-9);
  EXPECT_NEAR(g.roll_deg, 180, 1e-9);
}

TEST(LightGeometry, BehindCameraAndOutOfRange) {
  const SceneCamera cam = defaultCamera();
  auto behind = lightGeometry(lightAt(150, 0), cam.pose, cam, kRange, kSize);
  EXPECT_EQ(behind.status, LightStatus::kBehindCamera);
  EXPECT_NEAR(behind.angle_deg, 150, 1e-9);
  EXPECT_FALSE(behind.in_frame);
  auto side = lightGeometry(lightAt(90.5, 0), cam.pose, cam, kRange, kSize);
  EXPECT_EQ(side.status, LightStatus::kBehindCamera);
  auto far = lightGeometry(lightAt(35, 0), cam.pose, cam, kRange, kSize);
  EXPECT_EQ(far.status, LightStatus::kOutOfRange);
  EXPECT_NEAR(far.angle_deg, 35, 1e-9);
  // Just inside the range.
  EXPECT_EQ(lightGeometry(lightAt(29.9, 0), cam.pose, cam, kRange, kSize).status, LightStatus::kInRange);
  // Out of the frame but in range: still flares.
  // (The frame spans ±atan(12/24) = ±26.6° vertically.)
  auto outside = lightGeometry(lightAt(0, 28), cam.pose, cam, kRange, kSize);
  EXPECT_EQ(outside.status, LightStatus::kInRange);
  EXPECT_FALSE(outside.in_frame);
}

TEST(LightGeometry, NegativeOnlyModelIsUsedThroughItsMirror) {
  const SceneCamera cam = defaultCamera();
  const AngleRange negative{-30, 0};
  auto g = lightGeometry(lightAt(-20, 0), cam.pose, cam, negative, kSize);
  EXPECT_EQ(g.status, LightStatus::kInRange);
  EXPECT_NEAR(g.model_angle_deg, -20, 1e-9);
  EXPECT_NEAR(g.model_roll_deg, 180, 1e-9);
  EXPECT_NEAR(g.roll_deg, 0, 1e-9);
}

TEST(LightGeometry, DirectionalLightsUseTheirDirection) {
  const SceneCamera cam = defaultCamera();
  SceneLight sun;
  sun.kind = LightKind::kDirectional;
  sun.illuminance_lux = 1000;
  sun.position = {0, std::sin(20 * kRad), -std::cos(20 * kRad)};
  auto g = lightGeometry(sun, cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(g.angle_deg, 20, 1e-9);
  EXPECT_NEAR(g.roll_deg, 270, 1e-9);
}

TEST(LightGeometry, FarAwayLightsKeepFiniteAngles) {
  const SceneCamera cam = defaultCamera();
  auto g = lightGeometry(lightAt(-20, 0, 1e307), cam.pose, cam, kRange, kSize);
  EXPECT_NEAR(g.angle_deg, 20, 1e-9);
  EXPECT_NEAR(g.roll_deg, 0, 1e-9);
  SceneLight same;
  same.position = cam.pose.position;
  EXPECT_THROW(lightGeometry(same, cam.pose, cam, kRange, kSize), InputError);
}

TEST(LightGeometry, AnglesRoundTrip) {
  for (double theta : {1.0, 7.5, 25.0, 60.0})
    for (double phi : {0.0, 33.0, 90.0, 181.0, 300.0}) {
      const auto g = geometryFromCameraDirection(cameraDirectionFromAngles(theta, phi), {-90, 90}, defaultCamera(), kSize);
      EXPECT_NEAR(g.angle_deg, theta, 1e-9);
      EXPECT_NEAR(g.roll_deg, phi, 1e-9);
    }
}

}  // namespace
}  // namespace flarekit::predict
