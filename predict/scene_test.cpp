// Scenes from JSON and glTF, and the clear one-line errors for bad ones.
#include "predict/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <numbers>

#include <nlohmann/json.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"

namespace flarekit::predict {
namespace {

using nlohmann::json;
using testing::TempDir;

json goodScene() {
  return json::parse(R"({
    "format": "flarekit.scene", "version": 1, "name": "test",
    "camera": {"position": [0, 1, 0], "look_at": [0, 1, -5], "up": [0, 1, 0],
               "focal_length_mm": 35, "sensor_width_mm": 36, "sensor_height_mm": 24,
               "f_number": 4, "iso": 800, "exposure_s": 0.02},
    "lights": [
      {"name": "a", "position": [1, 2, -10], "intensity_cd": 500},
      {"name": "b", "position": [-1, 2, -10], "luminance_cd_m2": 1000, "solid_angle_sr": 0.01, "color": [1, 0.5, 0.2]}
    ],
    "camera_path": [{"time_s": 0, "position": [0, 1, 0], "look_at": [1, 1, -5]},
                    {"time_s": 1, "position": [0, 1, 0], "look_at": [-1, 1, -5]}]
  })");
}

std::filesystem::path write(const TempDir& dir, const std::string& name, const std::string& text) {
  std::ofstream(dir / name) << text;
  return dir / name;
}

// Loads a scene that must fail and returns the message.
std::string failure(const std::filesystem::path& path) {
  try {
    loadScene(path);
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Scene, ReadsAJsonScene) {
  TempDir dir;
  const Scene s = loadScene(write(dir, "s.json", goodScene().dump()));
  EXPECT_EQ(s.name, "test");
  EXPECT_DOUBLE_EQ(s.camera.focal_length_mm, 35);
  EXPECT_DOUBLE_EQ(s.camera.exposure_s, 0.02);
  ASSERT_EQ(s.lights.size(), 2u);
  EXPECT_EQ(s.lights[0].kind, LightKind::kIntensity);
  EXPECT_EQ(s.lights[1].kind, LightKind::kLuminance);
  EXPECT_DOUBLE_EQ(s.lights[1].color[1], 0.5);
  ASSERT_EQ(s.camera_path.size(), 2u);
  EXPECT_DOUBLE_EQ(s.camera_path[1].time_s, 1);
  EXPECT_TRUE(s.background.empty());
  // l·α: I / d² for the point light (d² = 1 + 1 + 100), L·α for the other.
  EXPECT_NEAR(Scene::illuminanceAt(s.lights[0], s.camera.pose), 500.0 / 102.0, 1e-12);
  EXPECT_NEAR(Scene::illuminanceAt(s.lights[1], s.camera.pose), 10.0, 1e-12);
}

TEST(Scene, ReadsABackgroundImageRelativeToTheScene) {
  TempDir dir;
  writeExr(dir / "bg.exr", cv::Mat(20, 30, CV_32FC3, cv::Scalar(0.1, 0.2, 0.3)));
  json j = goodScene();
  j["background"] = {{"image", "bg.exr"}};
  const Scene s = loadScene(write(dir, "s.json", j.dump()));
  ASSERT_FALSE(s.background.empty());
  EXPECT_EQ(s.background.size(), cv::Size(30, 20));
  j["background"] = {{"image", "missing.exr"}};
  EXPECT_NE(failure(write(dir, "s2.json", j.dump())).find("background.image"), std::string::npos);
}

struct BadCase {
  std::string what;
  std::function<void(json&)> edit;
  std::string expected;  // part of the message
};

TEST(Scene, BadScenesFailWithOneLineNamingFileAndKey) {
  const std::vector<BadCase> cases = {
      {"missing camera", [](json& j) { j.erase("camera"); }, "camera"},
      {"wrong format", [](json& j) { j["format"] = "flarekit.rig"; }, "format"},
      {"wrong version", [](json& j) { j["version"] = 2; }, "version"},
      {"zero solid angle", [](json& j) { j["lights"][1]["solid_angle_sr"] = 0; }, "lights[1].solid_angle_sr"},
      {"negative intensity", [](json& j) { j["lights"][0]["intensity_cd"] = -5; }, "lights[0].intensity_cd"},
      {"both kinds", [](json& j) { j["lights"][0]["luminance_cd_m2"] = 5; }, "lights[0]"},
      {"no lights", [](json& j) { j["lights"] = json::array(); }, "lights"},
      {"look-at at position", [](json& j) { j["camera"]["look_at"] = {0, 1, 0}; }, "camera"},
      {"up along the view", [](json& j) { j["camera"]["up"] = {0, 0, -1}; }, "camera"},
      {"zero exposure", [](json& j) { j["camera"]["exposure_s"] = 0; }, "camera.exposure_s"},
      {"short position", [](json& j) { j["lights"][0]["position"] = {1, 2}; }, "lights[0].position"},
      {"typo", [](json& j) { j["camera"]["fnumber"] = 2; }, "fnumber"},
      {"times not increasing", [](json& j) { j["camera_path"][1]["time_s"] = 0; }, "camera_path[1].time_s"},
  };
  TempDir dir;
  for (const auto& c : cases) {
    json j = goodScene();
    c.edit(j);
    const std::string message = failure(write(dir, "bad.json", j.dump()));
    EXPECT_NE(message.find("bad.json"), std::string::npos) << c.what << ": " << message;
    EXPECT_NE(message.find(c.expected), std::string::npos) << c.what << ": " << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << c.what;
  }
}

TEST(Scene, NaNAndInfinitePositionsAreRejected) {
  TempDir dir;
  std::string text = goodScene().dump();
  const std::string pos = "[1,2,-10]";
  ASSERT_NE(text.find(pos), std::string::npos);
  std::string nan_text = text, inf_text = text;
  nan_text.replace(nan_text.find(pos), pos.size(), "[NaN,2,-10]");
  inf_text.replace(inf_text.find(pos), pos.size(), "[1e999,2,-10]");
  EXPECT_NE(failure(write(dir, "nan.json", nan_text)).find("nan.json"), std::string::npos);
  const std::string inf_message = failure(write(dir, "inf.json", inf_text));
  EXPECT_NE(inf_message.find("inf.json"), std::string::npos) << inf_message;
  EXPECT_NE(failure(dir / "nowhere.json").find("nowhere.json"), std::string::npos);
}

const char* kGltf = R"({
  "asset": {"version": "2.0"},
  "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {"KHR_lights_punctual": {"lights": [
    {"type": "point", "intensity": 800, "color": [1, 0.9, 0.8], "name": "bulb"},
    {"type": "spot", "intensity": 2000, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
    {"type": "directional", "intensity": 5000}
  ]}},
  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.6, "aspectRatio": 1.5, "znear": 0.1},
               "extras": {"f_number": 5.6, "iso": 200, "exposure_s": 0.004, "focal_length_mm": 50}}],
  "nodes": [
    {"name": "cam", "camera": 0, "translation": [0, 2, 5]},
    {"name": "bulb node", "translation": [1, 3, -5], "extensions": {"KHR_lights_punctual": {"light": 0}}},
    {"name": "spot aimed at camera", "translation": [0, 2, -5], "rotation": [0, 1, 0, 0],
     "extensions": {"KHR_lights_punctual": {"light": 1}}},
    {"name": "rig", "translation": [0, 0, 0], "children": [4]},
    {"name": "sun", "rotation": [-0.2588190451, 0, 0, 0.9659258263], "extensions": {"KHR_lights_punctual": {"light": 2}}}
  ],
  "scenes": [{"nodes": [0, 1, 2, 3]}], "scene": 0
})";

TEST(Scene, ReadsGltfWithPunctualLightsAndCameraExtras) {
  TempDir dir;
  const Scene s = loadScene(write(dir, "s.gltf", kGltf));
  EXPECT_DOUBLE_EQ(s.camera.f_number, 5.6);
  EXPECT_DOUBLE_EQ(s.camera.iso, 200);
  EXPECT_DOUBLE_EQ(s.camera.exposure_s, 0.004);
  EXPECT_DOUBLE_EQ(s.camera.focal_length_mm, 50);
  EXPECT_NEAR(s.camera.sensor_height_mm, 2 * 50 * std::tan(0.3), 1e-9);
  EXPECT_NEAR(s.camera.sensor_width_mm, 1.5 * s.camera.sensor_height_mm, 1e-9);
  EXPECT_NEAR(s.camera.pose.position[2], 5, 1e-12);
  EXPECT_NEAR(s.camera.pose.look_at[2], 4, 1e-12);  // glTF cameras look down −Z
  ASSERT_EQ(s.lights.size(), 3u);
  EXPECT_EQ(s.lights[0].name, "bulb node");
  EXPECT_EQ(s.lights[0].kind, LightKind::kIntensity);
  EXPECT_DOUBLE_EQ(s.lights[0].intensity_cd, 800);
  EXPECT_NEAR(s.lights[0].position[1], 3, 1e-12);
  // The spot is turned 180° about y, so it points along +Z, straight at the camera: full intensity.
  EXPECT_NEAR(s.lights[1].intensity_cd, 2000, 1e-6);
  // The sun (child of "rig") is tilted −30° about x: its +Z turns up, so it is seen up and behind.
  EXPECT_EQ(s.lights[2].kind, LightKind::kDirectional);
  EXPECT_DOUBLE_EQ(s.lights[2].illuminance_lux, 5000);
  EXPECT_NEAR(s.lights[2].position[1], std::sin(30 * std::numbers::pi / 180), 1e-6);
  EXPECT_NEAR(s.lights[2].position[2], std::cos(30 * std::numbers::pi / 180), 1e-6);
}

TEST(Scene, SpotLightsAwayFromTheCameraAreDimmedByTheirCone) {
  TempDir dir;
  std::string text = kGltf;
  const std::string rot = R"("rotation": [0, 1, 0, 0],)";
  text.replace(text.find(rot), rot.size(), "");  // now points along −Z, away from the camera
  const Scene s = loadScene(write(dir, "s.gltf", text));
  EXPECT_DOUBLE_EQ(s.lights[1].intensity_cd, 0);
}

TEST(Scene, BadGltfFilesFailClearly) {
  TempDir dir;
  EXPECT_NE(failure(write(dir, "garbage.gltf", "this is not json")).find("garbage.gltf"), std::string::npos);
  EXPECT_NE(failure(write(dir, "garbage.glb", "glTF....")).find("garbage.glb"), std::string::npos);
  std::string no_camera = kGltf;
  no_camera.replace(no_camera.find(R"("camera": 0, )"), std::string(R"("camera": 0, )").size(), "");
  EXPECT_NE(failure(write(dir, "nocam.gltf", no_camera)).find("camera"), std::string::npos);
  std::string no_extras = kGltf;
  no_extras.replace(no_extras.find(R"("iso": 200, )"), std::string(R"("iso": 200, )").size(), "");
  EXPECT_NE(failure(write(dir, "noiso.gltf", no_extras)).find("extras.iso"), std::string::npos);
}

}  // namespace
}  // namespace flarekit::predict
