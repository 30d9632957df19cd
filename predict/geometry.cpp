#include "predict/geometry.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/error.h"

namespace flarekit::predict {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double norm(const Vec3& v) { return std::sqrt(dot(v, v)); }
Vec3 scaled(const Vec3& v, double s) { return {v[0] * s, v[1] * s, v[2] * s}; }

}  // namespace

CameraFrame CameraFrame::fromPose(const CameraPose& pose) {
  const Vec3 f{pose.look_at[0] - pose.position[0], pose.look_at[1] - pose.position[1],
               pose.look_at[2] - pose.position[2]};
  const double fl = norm(f);
  if (!std::isfinite(fl) || !(fl > 0)) throw InputError("look_at must differ from position");
  CameraFrame c;
  c.forward = scaled(f, 1.0 / fl);
  const double ul = norm(pose.up);
  if (!std::isfinite(ul) || !(ul > 0)) throw InputError("up must be a non-zero vector");
  // right = forward × up; the image's down = forward × right (x right, y down, z forward).
  const Vec3 r = cross(c.forward, pose.up);
  const double rl = norm(r);
  if (!(rl > 1e-9 * ul)) throw InputError("up is parallel to the viewing direction");
  c.right = scaled(r, 1.0 / rl);
  c.down = cross(c.forward, c.right);
  return c;
}

Vec3 CameraFrame::cameraFromWorld(const Vec3& d) const { return {dot(d, right), dot(d, down), dot(d, forward)}; }

std::string toString(LightStatus status) {
  switch (status) {
    case LightStatus::kInRange: return "in range";
    case LightStatus::kOutOfRange: return "out of range";
    case LightStatus::kBehindCamera: return "behind camera";
  }
  return "?";
}

LightGeometry geometryFromCameraDirection(const Vec3& direction, const AngleRange& range,
                                          const SceneCamera& camera, cv::Size image_size) {
  LightGeometry g;
  // Scale by the largest component first so huge coordinates cannot overflow the norm.
  const double big = std::max({std::abs(direction[0]), std::abs(direction[1]), std::abs(direction[2])});
  if (!std::isfinite(big) || !(big > 0)) throw InputError("a light direction must be finite and non-zero");
  const Vec3 d{direction[0] / big, direction[1] / big, direction[2] / big};
  const double len = norm(d);
  const double x = d[0] / len, y = d[1] / len, z = d[2] / len;
  g.angle_deg = std::acos(std::clamp(z, -1.0, 1.0)) * kDeg;
  const double radial = std::hypot(x, y);
  // On the axis the roll is undefined; 0 is as good as any (the model is symmetric there).
  double roll = radial > 0 ? std::atan2(y, -x) * kDeg : 0.0;
  if (roll < 0) roll += 360.0;
  if (roll >= 360.0) roll -= 360.0;
  g.roll_deg = roll;

  if (z > 0) {
    const double f_px = camera.focal_length_mm / camera.sensor_width_mm * image_size.width;
    g.image_px = {0.5 * image_size.width + f_px * x / z, 0.5 * image_size.height + f_px * y / z};
    g.in_frame = g.image_px.x >= 0 && g.image_px.x < image_size.width && g.image_px.y >= 0 &&
                 g.image_px.y < image_size.height;
  }
  if (g.angle_deg >= 90.0) {
    g.status = LightStatus::kBehindCamera;
    return g;
  }
  // Prefer the model's positive side; use the mirror (−θ, φ + 180°) when only it covers θ.
  if (range.contains(g.angle_deg)) {
    g.model_angle_deg = g.angle_deg;
    g.model_roll_deg = g.roll_deg;
  } else if (range.contains(-g.angle_deg)) {
    g.model_angle_deg = -g.angle_deg;
    g.model_roll_deg = std::fmod(g.roll_deg + 180.0, 360.0);
  } else {
    g.status = LightStatus::kOutOfRange;
    return g;
  }
  g.status = LightStatus::kInRange;
  return g;
}

LightGeometry lightGeometry(const SceneLight& light, const CameraPose& pose, const SceneCamera& camera,
                            const AngleRange& range, cv::Size image_size) {
  const CameraFrame frame = CameraFrame::fromPose(pose);
  Vec3 d = light.position;
  if (light.kind != LightKind::kDirectional)
    d = {light.position[0] - pose.position[0], light.position[1] - pose.position[1],
         light.position[2] - pose.position[2]};
  if (!(std::max({std::abs(d[0]), std::abs(d[1]), std::abs(d[2])}) > 0))
    throw InputError("light \"" + light.name + "\" sits at the camera's position");
  if (!std::isfinite(d[0]) || !std::isfinite(d[1]) || !std::isfinite(d[2]))
    throw InputError("light \"" + light.name + "\" is too far from the camera to compute its direction");
  return geometryFromCameraDirection(frame.cameraFromWorld(d), range, camera, image_size);
}

Vec3 cameraDirectionFromAngles(double angle_deg, double roll_deg) {
  const double t = angle_deg / kDeg, p = roll_deg / kDeg;
  // Image direction u = (−cos φ, sin φ) (see the header), tilted by θ from the axis.
  return {-std::sin(t) * std::cos(p), std::sin(t) * std::sin(p), std::cos(t)};
}

}  // namespace flarekit::predict
