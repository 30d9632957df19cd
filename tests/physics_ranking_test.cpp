// Against physics (issue 7): for the simulated Heliar Tronnier and 20 light positions in one
// scene, the severity ranking from the fitted flare model agrees with the ranking from the
// physical renderer directly (Spearman ρ ≥ 0.9). This is the one place where the fitted model
// (fit/ → model/) and the renderer that made its capture (render/) meet.
//
// The model is tests/data/physics/heliar_tronnier_fitted.json, fitted by FlareKit from the committed
// synthetic capture; regenerate it with
//   build/bin/flarekit fit data_synthetic/heliar_tronnier_0-20 --out tests/data/physics/heliar_tronnier_fitted.json
// To rate another fit of the capture without replacing the fixture, name it in
// FLAREKIT_PHYSICS_MODEL (set but empty, as `FLAREKIT_PHYSICS_MODEL= ctest` leaves it, it names
// none and the fixture is rated).
// The physical renders use the capture rig's settings (rigs/sim-heliar.toml: 36×24 mm sensor at
// 320×214, f/4, a 48² grid, mono = luminance), ghosts only: the model describes ghosts, not the
// light's own image.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>

#include "common/image.h"
#include "model/flare_model.h"
#include "predict/estimators.h"
#include "predict/geometry.h"
#include "predict/prediction.h"
#include "predict/scene.h"
#include "render/flare_renderer.h"
#include "render/lens.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;

TEST(PhysicsRanking, FittedModelRanksTwentyLightsLikeThePhysicalRenderer) {
  const fs::path source = FLAREKIT_SOURCE_DIR;
  const char* other = std::getenv("FLAREKIT_PHYSICS_MODEL");
  const model::FlareModel flare_model = model::FlareModel::load(
      other && *other ? fs::path(other) : source / "tests/data/physics/heliar_tronnier_fitted.json");
  const render::Lens lens = render::loadLens(source / "lenses/heliar_tronnier.json");
  const cv::Size size = flare_model.capture.image_size;
  const predict::AngleRange range = predict::sampledRange(flare_model);
  ASSERT_GE(range.max_deg, 15.0) << "the fixture model should cover the capture's 0–20°";

  // One scene: the rig's camera (100 mm on 36×24 mm, f/4) and 20 equally bright point lights at
  // known directions spread over the model's range and all round in roll. Equal intensities keep
  // the brightness scale B out of the ranking: it ranks the flare itself.
  predict::Scene scene;
  scene.name = "twenty lights";
  scene.camera.focal_length_mm = 100;
  scene.camera.f_number = 4;
  const predict::CameraFrame frame = predict::CameraFrame::fromPose(scene.camera.pose);
  const int kLights = 20;
  std::vector<double> angles_deg, rolls_deg;
  for (int i = 0; i < kLights; ++i) {
    angles_deg.push_back(range.min_deg + 0.25 +
                         (range.max_deg - range.min_deg - 0.5) * i / (kLights - 1));
    rolls_deg.push_back(std::fmod(137.5 * i, 360.0));  // golden-angle spread
    const predict::Vec3 d = predict::cameraDirectionFromAngles(angles_deg[i], rolls_deg[i]);
    predict::SceneLight light;
    light.name = "light " + std::to_string(i);
    light.kind = predict::LightKind::kIntensity;
    light.intensity_cd = 1000;
    for (int k = 0; k < 3; ++k)  // 10 m away along the direction, in world coordinates
      light.position[k] = 10.0 * (frame.right[k] * d[0] + frame.down[k] * d[1] + frame.forward[k] * d[2]);
    scene.lights.push_back(light);
  }

  render::FlareRenderOptions physical;
  physical.width_px = size.width;
  physical.height_px = size.height;
  physical.f_number = 4;
  physical.grid_size = 48;
  physical.light_source = false;  // ghosts only

  std::vector<double> severity_model, severity_physical;
  for (int i = 0; i < kLights; ++i) {
    const predict::LightGeometry g = predict::lightGeometry(scene.lights[i], scene.camera.pose,
                                                            scene.camera, range, size);
    ASSERT_EQ(g.status, predict::LightStatus::kInRange) << i;
    EXPECT_NEAR(g.angle_deg, angles_deg[i], 1e-6) << i;
    EXPECT_NEAR(std::remainder(g.roll_deg - rolls_deg[i], 360.0), 0.0, 1e-6) << i;

    const cv::Mat from_model = predict::renderLight(flare_model, g.model_angle_deg, g.model_roll_deg,
                                                    1.0, {1, 1, 1}, size, model::RenderOptions{});
    const render::FlareImage from_physics =
        render::renderFlare(lens, render::LightDirection{g.angle_deg, g.roll_deg}, physical);
    severity_model.push_back(predict::computeEstimators(luminance(from_model), 0.0).mean);
    severity_physical.push_back(
        predict::computeEstimators(luminance(from_physics.radiance), 0.0).mean);
  }
  for (int i = 0; i < kLights; ++i)
    std::cout << "  θ " << angles_deg[i] << "°  φ " << rolls_deg[i] << "°  model " << severity_model[i]
              << "  physical " << severity_physical[i] << "\n";
  const double rho = predict::spearmanCorrelation(severity_model, severity_physical);
  RecordProperty("spearman", std::to_string(rho));
  std::cout << "Spearman rank correlation, fitted model vs physical renderer, 20 lights: " << rho
            << "\n";
  EXPECT_GE(rho, 0.9);
}

}  // namespace
}  // namespace flarekit
