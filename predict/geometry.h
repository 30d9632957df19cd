#pragma once
// Where each light sits relative to the camera, in the model's angles (Walch et al. 2018 §3.4.1:
// "the virtual constellation angle between the camera and the light source is directly used to
// evaluate the polynomials ... the lens flare rendering can be rotated around its image center to
// match the roll angle").
//
// Conventions (docs/design.md): θ is the angle between the optical axis and the direction to the
// light; positive θ puts the light's image left of the centre (−x) at roll φ = 0; a roll φ rotates
// the flare counter-clockwise as displayed (y down) about the optical axis, as model/
// ViewTransform does. So a light whose image direction from the centre is u = (ux, uy) (y down)
// has φ = atan2(uy, −ux), in [0, 360).
//
// A model sampled only over negative θ (or further on the negative side) is used through its
// mirror image: θ_model = −θ with φ + 180°, the same flare for a rotationally symmetric lens.

#include <string>

#include <opencv2/core.hpp>

#include "predict/scene.h"

namespace flarekit::predict {

// The angles a model was sampled over: the union of its ghosts' ranges, degrees.
struct AngleRange {
  double min_deg = 0;
  double max_deg = 0;
  bool contains(double angle_deg) const { return angle_deg >= min_deg && angle_deg <= max_deg; }
};

// The camera frame of a pose: x right, y down the image, z along the view (unit vectors in world
// coordinates). Throws InputError when look_at == position or up is parallel to the view.
struct CameraFrame {
  Vec3 right{1, 0, 0};
  Vec3 down{0, -1, 0};
  Vec3 forward{0, 0, -1};

  static CameraFrame fromPose(const CameraPose& pose);
  // World direction → camera frame.
  Vec3 cameraFromWorld(const Vec3& direction) const;
};

enum class LightStatus {
  kInRange,       // in front of the camera and within the model's sampled range: renders ghosts
  kOutOfRange,    // in front, but θ beyond the model's sampled range: no ghosts
  kBehindCamera,  // θ ≥ 90°: no ghosts
};
std::string toString(LightStatus status);  // "in range", "out of range", "behind camera"

struct LightGeometry {
  LightStatus status = LightStatus::kInRange;
  double angle_deg = 0;        // θ ≥ 0: off-axis angle of the light, degrees
  double roll_deg = 0;         // φ in [0, 360): roll of the flare, degrees
  double model_angle_deg = 0;  // the θ the model is evaluated at (θ or −θ, see above)
  double model_roll_deg = 0;   // the roll the model is rendered at
  // Where the light's own image falls on the sensor (pixels of an image of `image_size`; may lie
  // outside it; meaningless when behind the camera) and whether it is inside the frame.
  cv::Point2d image_px{0, 0};
  bool in_frame = false;
};

// The geometry of a light direction given in the camera frame (x right, y down, z forward; need not
// be unit length, must be finite and non-zero).
LightGeometry geometryFromCameraDirection(const Vec3& direction, const AngleRange& range,
                                          const SceneCamera& camera, cv::Size image_size);

// The geometry of a scene light seen from `pose` with `camera`'s optics.
LightGeometry lightGeometry(const SceneLight& light, const CameraPose& pose, const SceneCamera& camera,
                            const AngleRange& range, cv::Size image_size);

// The camera-frame direction of the light at (θ, φ): the inverse of the above (for severity maps).
Vec3 cameraDirectionFromAngles(double angle_deg, double roll_deg);

}  // namespace flarekit::predict
