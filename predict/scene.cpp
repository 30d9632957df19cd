#include "predict/scene.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <tiny_gltf.h>

#include "common/input_file.h"
#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "predict/geometry.h"

namespace flarekit::predict {
namespace {

double norm(const Vec3& v) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); }
Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }

Vec3 readVec3(const ConfigNode& node) {
  if (!node.isArray() || node.size() != 3) node.fail("must be an array of 3 numbers");
  const std::vector<double> v = node.numbers();  // fails on NaN, infinities and non-numbers
  return {v[0], v[1], v[2]};
}

double positive(const ConfigNode& parent, std::string_view key) {
  const ConfigNode n = parent[key];
  const double v = n.number();
  if (!(v > 0)) n.fail("must be positive, got " + jsonText(n.json(), -1));
  return v;
}

// Validates a pose: distinct position and look-at, up not along the view.
void checkPose(const CameraPose& pose, const ConfigNode& node) {
  try {
    (void)CameraFrame::fromPose(pose);
  } catch (const InputError& e) {
    node.fail(e.what());
  }
}

CameraPose readPose(const ConfigNode& node) {
  if (!node.isObject()) node.fail("must be an object");
  CameraPose pose;
  pose.position = readVec3(node["position"]);
  pose.look_at = readVec3(node["look_at"]);
  if (auto up = node.find("up")) pose.up = readVec3(*up);
  checkPose(pose, node);
  return pose;
}

cv::Mat readBackground(const std::filesystem::path& image, const ConfigNode& node) {
  cv::Mat m;
  try {
    m = readExrLayer(image, "", {.allow_nonfinite = false});
  } catch (const InputError& e) {
    node.fail(std::string("cannot use background: ") + e.what());
  }
  double lo = 0;
  cv::minMaxLoc(m.reshape(1), &lo);
  if (lo < 0) node.fail("background image " + image.string() + " has negative values");
  return m;
}

}  // namespace

double Scene::illuminanceAt(const SceneLight& light, const CameraPose& pose) {
  switch (light.kind) {
    case LightKind::kLuminance:
      return light.luminance_cd_m2 * light.solid_angle_sr;
    case LightKind::kIntensity: {
      const double d = norm(sub(light.position, pose.position));
      return d > 0 ? light.intensity_cd / (d * d) : 0.0;
    }
    case LightKind::kDirectional:
      return light.illuminance_lux;
  }
  return 0;
}

Scene parseSceneJson(const std::string& text, const std::filesystem::path& file) {
  std::optional<ConfigNode> parsed;
  try {
    parsed = parseJson(text, file.string());
  } catch (const nlohmann::json::exception& e) {
    // common's parseJson turns syntax errors into InputError; numbers that overflow (1e999) come
    // through as nlohmann's out_of_range.
    throw InputError(file.string(), std::string("not a valid JSON scene: ") + e.what());
  }
  const ConfigNode root = *parsed;
  if (!root.isObject()) root.fail("a scene must be a JSON object");
  checkFormat(root, kSceneFormat, kSceneVersion);
  root.checkKnownKeys({"format", "version", "name", "camera", "lights", "background", "camera_path"});
  Scene s;
  s.file = file;
  s.name = root.string("name", file.stem().string());

  const auto camera_node = root.find("camera");
  if (!camera_node) root.fail("missing key \"camera\": a scene needs a camera");
  const ConfigNode cam = *camera_node;
  if (!cam.isObject()) cam.fail("must be an object");
  cam.checkKnownKeys({"position", "look_at", "up", "focal_length_mm", "sensor_width_mm",
                      "sensor_height_mm", "f_number", "iso", "exposure_s"});
  s.camera.pose = readPose(cam);
  s.camera.focal_length_mm = positive(cam, "focal_length_mm");
  s.camera.sensor_width_mm = positive(cam, "sensor_width_mm");
  s.camera.sensor_height_mm = positive(cam, "sensor_height_mm");
  s.camera.f_number = positive(cam, "f_number");
  s.camera.iso = positive(cam, "iso");
  s.camera.exposure_s = positive(cam, "exposure_s");

  const ConfigNode lights = root["lights"];
  if (!lights.isArray()) lights.fail("must be an array");
  if (lights.size() == 0) lights.fail("a scene needs at least one light");
  for (size_t i = 0; i < lights.size(); ++i) {
    const ConfigNode l = lights[i];
    if (!l.isObject()) l.fail("must be an object");
    l.checkKnownKeys({"name", "position", "luminance_cd_m2", "solid_angle_sr", "intensity_cd", "color"});
    SceneLight light;
    light.name = l.string("name", "light " + std::to_string(i + 1));
    light.position = readVec3(l["position"]);
    const bool has_luminance = l.has("luminance_cd_m2") || l.has("solid_angle_sr");
    const bool has_intensity = l.has("intensity_cd");
    if (has_luminance == has_intensity)
      l.fail("give either luminance_cd_m2 with solid_angle_sr, or intensity_cd");
    if (has_luminance) {
      light.kind = LightKind::kLuminance;
      light.luminance_cd_m2 = positive(l, "luminance_cd_m2");
      light.solid_angle_sr = positive(l, "solid_angle_sr");
      if (light.solid_angle_sr > 4 * std::numbers::pi)
        l["solid_angle_sr"].fail("must be at most 4π sr");
    } else {
      light.kind = LightKind::kIntensity;
      light.intensity_cd = positive(l, "intensity_cd");
    }
    if (auto c = l.find("color")) {
      light.color = readVec3(*c);
      if (*std::min_element(light.color.begin(), light.color.end()) < 0 ||
          *std::max_element(light.color.begin(), light.color.end()) <= 0)
        c->fail("must be non-negative and not all zero");
    }
    if (norm(sub(light.position, s.camera.pose.position)) == 0)
      l["position"].fail("the light sits at the camera's position");
    s.lights.push_back(light);
  }

  if (auto bg = root.find("background")) {
    if (!bg->isObject()) bg->fail("must be an object");
    bg->checkKnownKeys({"image", "level"});
    if (bg->has("image")) {
      std::filesystem::path p = (*bg)["image"].string();
      if (p.is_relative()) p = file.parent_path() / p;
      s.background_file = p;
      s.background = readBackground(p, (*bg)["image"]);
    }
    if (auto level = bg->find("level")) {
      s.background_level = level->number();
      if (!(s.background_level >= 0)) level->fail("must be non-negative");
    }
  }

  if (auto path = root.find("camera_path")) {
    if (!path->isArray()) path->fail("must be an array");
    double last = -std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < path->size(); ++i) {
      const ConfigNode p = (*path)[i];
      if (!p.isObject()) p.fail("must be an object");
      p.checkKnownKeys({"time_s", "position", "look_at", "up"});
      CameraPose pose = readPose(p);
      pose.time_s = p["time_s"].number();
      if (!(pose.time_s > last)) p["time_s"].fail("times must increase along the path");
      for (const SceneLight& light : s.lights)
        if (norm(sub(light.position, pose.position)) == 0)
          p["position"].fail("the camera passes through light \"" + light.name + "\"");
      last = pose.time_s;
      s.camera_path.push_back(pose);
    }
  }
  return s;
}

namespace {

// glTF node transforms (column-major 4×4, glTF 2.0 §3.5.3).
using Mat4 = std::array<double, 16>;

Mat4 identity() { return {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}; }

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double v = 0;
      for (int k = 0; k < 4; ++k) v += a[k * 4 + row] * b[c * 4 + k];
      r[c * 4 + row] = v;
    }
  return r;
}

Mat4 localMatrix(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) {
    Mat4 m;
    std::copy(n.matrix.begin(), n.matrix.end(), m.begin());
    return m;
  }
  Mat4 t = identity(), r = identity(), s = identity();
  if (n.translation.size() == 3) {
    t[12] = n.translation[0];
    t[13] = n.translation[1];
    t[14] = n.translation[2];
  }
  if (n.rotation.size() == 4) {
    const double x = n.rotation[0], y = n.rotation[1], z = n.rotation[2], w = n.rotation[3];
    r = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),     0,
         2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),     0,
         2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y), 0,
         0,                       0,                       0,                       1};
  }
  if (n.scale.size() == 3) {
    s[0] = n.scale[0];
    s[5] = n.scale[1];
    s[10] = n.scale[2];
  }
  return multiply(t, multiply(r, s));
}

Vec3 transformPoint(const Mat4& m, const Vec3& p) {
  return {m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12], m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13],
          m[2] * p[0] + m[6] * p[1] + m[10] * p[2] + m[14]};
}
Vec3 transformDirection(const Mat4& m, const Vec3& d) {
  return {m[0] * d[0] + m[4] * d[1] + m[8] * d[2], m[1] * d[0] + m[5] * d[1] + m[9] * d[2],
          m[2] * d[0] + m[6] * d[1] + m[10] * d[2]};
}

bool allFinite(const Mat4& m) {
  return std::all_of(m.begin(), m.end(), [](double v) { return std::isfinite(v); });
}

double extraNumber(const tinygltf::Value& extras, const std::string& key, const std::string& file,
                   const std::string& where, std::optional<double> fallback = std::nullopt) {
  if (!extras.IsObject() || !extras.Has(key)) {
    if (fallback) return *fallback;
    throw InputError(file, where + ".extras." + key + ": missing (glTF cameras carry f_number, iso "
                                   "and exposure_s in extras)");
  }
  const tinygltf::Value& v = extras.Get(key);
  if (!v.IsNumber() || !std::isfinite(v.GetNumberAsDouble()) || !(v.GetNumberAsDouble() > 0))
    throw InputError(file, where + ".extras." + key + ": must be a positive number");
  return v.GetNumberAsDouble();
}

// tinygltf reads the buffers and images a glTF file names through this, so they obey the rules of
// every input (regular files of bounded size).
bool readReferencedFile(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
  try {
    const std::string bytes = readInputFile(path);
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const InputError& e) {
    if (err) *err += e.what();
    return false;
  }
}

}  // namespace

Scene loadGltfScene(const std::filesystem::path& path) {
  const std::string file = path.string();
  const std::string bytes = readInputFile(path);
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks({&tinygltf::FileExists, &tinygltf::ExpandFilePath, &readReferencedFile,
                         &tinygltf::WriteWholeFile, nullptr});
  tinygltf::Model m;
  std::string err, warn;
  const std::string base_dir = path.parent_path().string();
  bool ok = false;
  if (path.extension() == ".glb") {
    ok = loader.LoadBinaryFromMemory(&m, &err, &warn, reinterpret_cast<const unsigned char*>(bytes.data()),
                                     static_cast<unsigned int>(bytes.size()), base_dir);
  } else {
    checkJsonDepth(bytes, file);
    ok = loader.LoadASCIIFromString(&m, &err, &warn, bytes.data(), static_cast<unsigned int>(bytes.size()),
                                    base_dir);
  }
  if (!ok) throw InputError(file, "not a readable glTF 2.0 file: " + (err.empty() ? warn : err));

  // World matrices of every node reachable from the scene's roots (all roots when no scene).
  std::vector<std::optional<Mat4>> world(m.nodes.size());
  std::vector<int> roots;
  const int scene_index = m.defaultScene >= 0 ? m.defaultScene : (m.scenes.empty() ? -1 : 0);
  if (scene_index >= 0 && scene_index < static_cast<int>(m.scenes.size())) {
    roots = m.scenes[static_cast<size_t>(scene_index)].nodes;
  } else {
    for (size_t i = 0; i < m.nodes.size(); ++i) roots.push_back(static_cast<int>(i));
  }
  std::vector<std::pair<int, Mat4>> stack;
  for (int r : roots) stack.push_back({r, identity()});
  size_t visits = 0;
  while (!stack.empty()) {
    auto [index, parent] = stack.back();
    stack.pop_back();
    if (index < 0 || index >= static_cast<int>(m.nodes.size()) || world[static_cast<size_t>(index)])
      continue;
    if (++visits > 4 * m.nodes.size() + 16) break;  // cycles (invalid files)
    const tinygltf::Node& n = m.nodes[static_cast<size_t>(index)];
    const Mat4 w = multiply(parent, localMatrix(n));
    if (!allFinite(w)) throw InputError(file, "nodes[" + std::to_string(index) + "]: non-finite transform");
    world[static_cast<size_t>(index)] = w;
    for (int c : n.children) stack.push_back({c, w});
  }

  Scene s;
  s.file = path;
  s.name = path.stem().string();
  bool have_camera = false;
  for (size_t i = 0; i < m.nodes.size() && !have_camera; ++i) {
    const tinygltf::Node& n = m.nodes[i];
    if (n.camera < 0 || !world[i]) continue;
    if (n.camera >= static_cast<int>(m.cameras.size()))
      throw InputError(file, "nodes[" + std::to_string(i) + "].camera: no such camera");
    const tinygltf::Camera& c = m.cameras[static_cast<size_t>(n.camera)];
    const std::string where = "cameras[" + std::to_string(n.camera) + "]";
    if (c.type != "perspective") throw InputError(file, where + ": only perspective cameras are supported");
    const double yfov = c.perspective.yfov;
    if (!(yfov > 0) || !(yfov < std::numbers::pi)) throw InputError(file, where + ".perspective.yfov: must be in (0, π)");
    const double aspect = c.perspective.aspectRatio > 0 ? c.perspective.aspectRatio : 1.5;
    s.camera.focal_length_mm = extraNumber(c.extras, "focal_length_mm", file, where, 24.0);
    s.camera.sensor_height_mm = 2 * s.camera.focal_length_mm * std::tan(0.5 * yfov);
    s.camera.sensor_width_mm = s.camera.sensor_height_mm * aspect;
    s.camera.f_number = extraNumber(c.extras, "f_number", file, where);
    s.camera.iso = extraNumber(c.extras, "iso", file, where);
    s.camera.exposure_s = extraNumber(c.extras, "exposure_s", file, where);
    const Mat4& w = *world[i];
    // glTF cameras look along their local −Z with +Y up.
    s.camera.pose.position = transformPoint(w, {0, 0, 0});
    const Vec3 forward = transformDirection(w, {0, 0, -1});
    s.camera.pose.look_at = {s.camera.pose.position[0] + forward[0], s.camera.pose.position[1] + forward[1],
                             s.camera.pose.position[2] + forward[2]};
    s.camera.pose.up = transformDirection(w, {0, 1, 0});
    try {
      (void)CameraFrame::fromPose(s.camera.pose);
    } catch (const InputError& e) {
      throw InputError(file, "nodes[" + std::to_string(i) + "]: " + e.what());
    }
    if (c.name.size()) s.name = s.name + " (" + c.name + ")";
    have_camera = true;
  }
  if (!have_camera) throw InputError(file, "no node with a camera: a scene needs a camera");

  for (size_t i = 0; i < m.nodes.size(); ++i) {
    const tinygltf::Node& n = m.nodes[i];
    auto ext = n.extensions.find("KHR_lights_punctual");
    if (ext == n.extensions.end() || !world[i]) continue;
    const std::string where = "nodes[" + std::to_string(i) + "].extensions.KHR_lights_punctual";
    if (!ext->second.IsObject() || !ext->second.Has("light") || !ext->second.Get("light").IsInt())
      throw InputError(file, where + ".light: missing light index");
    const int li = ext->second.Get("light").Get<int>();
    if (li < 0 || li >= static_cast<int>(m.lights.size()))
      throw InputError(file, where + ".light: no such light " + std::to_string(li));
    const tinygltf::Light& gl = m.lights[static_cast<size_t>(li)];
    const std::string lwhere = "extensions.KHR_lights_punctual.lights[" + std::to_string(li) + "]";
    if (!std::isfinite(gl.intensity) || !(gl.intensity > 0))
      throw InputError(file, lwhere + ".intensity: must be positive");
    SceneLight light;
    light.name = !n.name.empty() ? n.name : (!gl.name.empty() ? gl.name : "light " + std::to_string(s.lights.size() + 1));
    if (gl.color.size() == 3) light.color = {gl.color[0], gl.color[1], gl.color[2]};
    if (!std::all_of(light.color.begin(), light.color.end(), [](double v) { return std::isfinite(v) && v >= 0; }) ||
        (light.color[0] + light.color[1] + light.color[2]) <= 0)
      throw InputError(file, lwhere + ".color: must be non-negative and not all zero");
    const Mat4& w = *world[i];
    if (gl.type == "directional") {
      light.kind = LightKind::kDirectional;
      // The light travels along the node's −Z, so it is seen towards +Z.
      Vec3 d = transformDirection(w, {0, 0, 1});
      const double len = norm(d);
      if (!(len > 0)) throw InputError(file, "nodes[" + std::to_string(i) + "]: degenerate transform");
      light.position = {d[0] / len, d[1] / len, d[2] / len};
      light.illuminance_lux = gl.intensity;
    } else if (gl.type == "point" || gl.type == "spot") {
      light.kind = LightKind::kIntensity;
      light.position = transformPoint(w, {0, 0, 0});
      light.intensity_cd = gl.intensity;
      if (gl.type == "spot") {
        // KHR_lights_punctual's smooth cone attenuation towards the camera.
        const Vec3 axis = transformDirection(w, {0, 0, -1});
        const Vec3 to_camera = sub(s.camera.pose.position, light.position);
        const double denom = norm(axis) * norm(to_camera);
        const double cd = denom > 0 ? (axis[0] * to_camera[0] + axis[1] * to_camera[1] + axis[2] * to_camera[2]) / denom : -1;
        const double inner = std::cos(gl.spot.innerConeAngle), outer = std::cos(gl.spot.outerConeAngle);
        const double scale = 1.0 / std::max(1e-4, inner - outer);
        const double t = std::clamp((cd - outer) * scale, 0.0, 1.0);
        light.intensity_cd *= t * t;
      }
      if (norm(sub(light.position, s.camera.pose.position)) == 0)
        throw InputError(file, "nodes[" + std::to_string(i) + "]: the light sits at the camera's position");
    } else {
      throw InputError(file, lwhere + ".type: unknown light type \"" + gl.type + "\"");
    }
    s.lights.push_back(light);
  }
  if (s.lights.empty()) throw InputError(file, "no KHR_lights_punctual light on any node");
  return s;
}

Scene loadScene(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".gltf" || ext == ".glb") return loadGltfScene(path);
  return parseSceneJson(readInputFile(path), path);
}

}  // namespace flarekit::predict
