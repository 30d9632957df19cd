#pragma once
// A light-planning scene (Walch et al. 2018 §3.4.1, §3.5): a camera with its exposure settings and
// the lights whose flare is to be predicted.
//
// World coordinates are right-handed, metres, y up (as in glTF). A camera pose looks from
// `position` towards `look_at` with `up` giving the image's up direction; its frame (what
// geometry.h uses) has x to the image's right, y down the image and z along the view direction.
//
// JSON scenes (format "flarekit.scene", version 1):
//
//   {
//     "format": "flarekit.scene", "version": 1,
//     "name": "Stage, evening",                          // optional
//     "camera": {
//       "position": [0, 1.6, 0], "look_at": [0, 1.6, -10], "up": [0, 1, 0],  // up optional
//       "focal_length_mm": 24, "sensor_width_mm": 36, "sensor_height_mm": 24,
//       "f_number": 8, "iso": 400, "exposure_s": 0.01
//     },
//     "lights": [
//       { "name": "spot L", "position": [-3, 4, -12],
//         "luminance_cd_m2": 2e6, "solid_angle_sr": 1e-4,   // or "intensity_cd": 5000
//         "color": [1, 0.9, 0.8] }                          // optional, linear RGB
//     ],
//     "background": { "image": "bg.exr" },   // optional: HDR image (path relative to the scene)
//     "background": { "level": 0.02 },       //   or a uniform linear level
//     // Background values are the scene camera's linear signal as a fraction of its white level
//     // (1 = clipping), the unit of the overlay when the model records its capture's clip level.
//     "camera_path": [                        // optional: poses over time
//       { "time_s": 0, "position": [...], "look_at": [...], "up": [...] }
//     ]
//   }
//
// Background values are linear values of the scene camera's image, in the units the model's
// overlay takes after the Eq. 2 scaling (brightness.h): the paper's "rendered scene R".
//
// glTF 2.0 scenes (.gltf, .glb) are read with tinygltf: the first node with a perspective camera
// (yfov; focal length and sensor from camera.extras "focal_length_mm" (default 24) and the sensor
// height that gives yfov, width from aspectRatio; exposure from camera.extras "f_number", "iso",
// "exposure_s", all required) and every node with a KHR_lights_punctual light: point and spot
// lights carry a luminous intensity in candela (spot lights attenuated by their cone towards the
// camera), directional lights an illuminance in lux and sit at infinity along the node's +Z.

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::predict {

using Vec3 = std::array<double, 3>;

inline constexpr char kSceneFormat[] = "flarekit.scene";
inline constexpr int kSceneVersion = 1;

// Where a camera is and where it looks.
struct CameraPose {
  double time_s = 0;          // time along a camera path, seconds (0 for the main pose)
  Vec3 position{0, 0, 0};     // metres
  Vec3 look_at{0, 0, -1};     // a point the optical axis passes through, metres
  Vec3 up{0, 1, 0};           // the image's up direction (need not be orthogonal to the axis)
};

// The scene's camera: pose, optics and exposure (the paper's R in Eq. 2).
struct SceneCamera {
  CameraPose pose;
  double focal_length_mm = 24;
  double sensor_width_mm = 36;
  double sensor_height_mm = 24;
  double f_number = 8;        // N_R
  double iso = 100;           // ISO_R
  double exposure_s = 0.01;   // t_R, seconds
};

enum class LightKind {
  kLuminance,    // a source of luminance_cd_m2 seen under solid_angle_sr from the camera
  kIntensity,    // a point source of intensity_cd (illuminance at the camera = I / d²)
  kDirectional,  // a source at infinity giving illuminance_lux at the camera (glTF directional)
};

struct SceneLight {
  std::string name;
  LightKind kind = LightKind::kIntensity;
  Vec3 position{0, 0, 0};       // metres; for kDirectional the unit direction towards the light
  double luminance_cd_m2 = 0;   // kLuminance
  double solid_angle_sr = 0;    // kLuminance
  double intensity_cd = 0;      // kIntensity (after any spot-cone attenuation towards the camera)
  double illuminance_lux = 0;   // kDirectional
  Vec3 color{1, 1, 1};          // linear RGB tint, normalised by prediction to luminance 1
};

struct Scene {
  std::string name;
  std::filesystem::path file;   // where it was read from (for reports and messages)
  SceneCamera camera;
  std::vector<SceneLight> lights;
  // The background image (linear, CV_32FC1 or CV_32FC3) when the scene names one, else empty.
  cv::Mat background;
  std::filesystem::path background_file;
  // The uniform background level used when there is no image (linear, ≥ 0).
  double background_level = 0.01;
  std::vector<CameraPose> camera_path;  // empty: no path

  // The product l·α of a light at a pose: the illuminance it gives at the camera, lux
  // (luminance × solid angle, I / d², or the directional illuminance). Eq. 2's l_R·α_R.
  static double illuminanceAt(const SceneLight& light, const CameraPose& pose);
};

// Reads a scene by extension: .json (flarekit.scene), .gltf or .glb. Throws InputError
// "<file>: <key path>: <problem>" for anything wrong: unreadable file, syntax, wrong format or
// version, missing camera, missing or non-finite numbers (NaN positions), non-positive
// optics, exposure, solid angle, luminance or intensity, a camera whose look-at equals its
// position or whose up is parallel to the view, an unreadable background image, no lights.
Scene loadScene(const std::filesystem::path& path);
// Parses JSON scene text; `file` names it in messages and relative paths resolve against its folder.
Scene parseSceneJson(const std::string& text, const std::filesystem::path& file);
// Reads a glTF 2.0 scene (see above).
Scene loadGltfScene(const std::filesystem::path& path);

}  // namespace flarekit::predict
