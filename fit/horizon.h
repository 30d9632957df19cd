#pragma once
// Stage 2 of the fit (docs/fitting.md): the capture's geometry, measured from the frames rather
// than assumed.
//
//  - The horizon: the rig turns about a vertical axis, so the light's image and every ghost lie
//    on one image row, the optical axis's y, and every ghost is mirror-symmetric about it. It is
//    the row about which the frames are most nearly mirror-symmetric.
//  - The light's image in every frame: its core (the clipped pixels, or the pixels above half the
//    peak, connected to the brightest one), and where it is.
//  - The optical zero (measureOpticalZero): the rig angle θ0 at which the light lies on the optical
//    axis, and the axis's x. A rotationally symmetric lens images a light at field angle −t as
//    the mirror image of the light at +t, so the light's curve and the centre of every ghost are
//    odd functions of tan(θ − θ0) about the axis: they all pass through one point of the sweep,
//    (θ0, axis x). The light's curve alone cannot tell θ0 from the axis's x (both shift it
//    almost alike); the ghosts, which move at other rates, can.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "fit/frames.h"

namespace flarekit::fit {

struct HorizonOptions {
  // The horizon is searched this far from the row through the light's cores (or the image's
  // middle when no frame shows the light), pixels (> 0).
  double search_px = 6;
  // Every n-th frame enters the symmetry measure (≥ 1).
  int frame_stride = 3;
  // Rows compared on each side of a candidate horizon, as a fraction of the image height
  // (0, 0.5].
  double band_fraction = 0.25;
  // The light is in a frame when it clips, or (unclipped, behind a filter) its brightest pixel
  // stands this many times above the frame's 99th percentile, its brightest ghosts (> 1).
  double light_contrast = 50;

  bool IsValid(std::string* error) const;
};

// The light's own image in one frame.
struct LightImage {
  bool found = false;         // false: the light is outside the frame
  cv::Point2d center;         // centroid of the core, image pixels
  double core_radius_px = 0;  // radius of a disc of the core's area

  // Whether the edge of a frame `width_px` wide cuts its core: the centroid is then pulled
  // inwards, not the light's centre.
  bool cutByEdge(int width_px) const {
    return center.x < 2 * core_radius_px || center.x > width_px - 2 * core_radius_px;
  }
};

struct Horizon {
  double y_px = 0;                 // the symmetry row (the optical axis's y), image pixels
  double symmetry_rms = 0;         // RMS log-difference of the mirrored rows at y_px
  std::vector<LightImage> lights;  // one per frame of the stack, in stack order
  int lights_found = 0;
};

// The light's own image (core, halo, starburst): the same in every frame that shows it, moved
// with the light. Its percentile over those frames at each offset from the light's centre keeps it
// and drops the ghosts (which move at other rates); less what lies at the window's edge (the veils
// under it).
struct LightPattern {
  cv::Mat image;       // CV_32F, (2 r + 1)², centred on the light's centre; empty without one
  int radius_px = 0;   // r

  // Takes the light's image out of a frame whose light is `light`: `image` less the pattern
  // (luminance scaled per channel alike), and `valid` cleared where the light outshines what
  // lies under it (its core and the bright part of its starburst). Nothing without a light.
  void takeOut(const LightImage& light, cv::Mat& image, cv::Mat& valid) const;
};

struct LightPatternOptions {
  int radius_px = 80;          // half-size of the pattern, pixels (≥ 1)
  double percentile = 0.2;     // of the frames that show the light, at each offset (0, 1)
  int min_frames = 5;          // fewer frames with the light: no pattern (≥ 1)

  bool IsValid(std::string* error) const;
};

LightPattern measureLightPattern(const FrameStack& stack, const Horizon& horizon,
                                 const LightPatternOptions& options = {});

// Measures the horizon and the light's image in every frame. Works on any stack; a stack that
// shows no light gets the symmetry row alone.
Horizon measureHorizon(const FrameStack& stack, const HorizonOptions& options = {});

// A curve in the sweep (θ, x) that is odd about the optical zero: x(θ) − axis_x = Σ a_k t^(2k+1),
// t = tan(θ − θ0). The light's curve and every ghost's centre are of this form.
struct OpticalZero {
  bool measured = false;       // false: too little to measure; the values are the defaults
  double axis_x_px = 0;        // the optical axis's x, image pixels
  double angle_zero_deg = 0;   // θ0: rig angle with the light on the optical axis, degrees
  double light_rms_px = 0;     // RMS of the light's measured centres about its fitted curve
  double centre_rms_px = 0;    // RMS of the ghosts' centres about theirs
  int ghosts_used = 0;         // ghost centre curves that took part
  std::vector<double> light_coefficients;  // the light's curve: a_1, a_3, ... (px per tanᵏ)

  // The light's x at rig angle θ (degrees) from the fitted curve.
  double lightX(double angle_deg) const;
};

// One ghost's centre over the angles where both of its borders are seen: (θ, (x_L + x_R) / 2).
struct CentreSamples {
  std::vector<double> angles_deg;
  std::vector<double> centre_x_px;
};

struct OpticalZeroOptions {
  int light_terms = 3;   // odd terms of the light's curve (t, t³, t⁵) (1–4)
  int ghost_terms = 2;   // odd terms of each ghost's centre curve (1–4)
  int min_samples = 8;   // a ghost takes part with at least this many centre samples (≥ 3)
  // θ0 is searched within ±this, degrees; a best fit on the bound is no measurement (> 0).
  double max_zero_deg = 3;

  bool IsValid(std::string* error) const;
};

// Fits the light's centres (from `horizon`, at the stack's angles) and the ghosts' centre curves
// together, with one common zero (θ0, axis x). Falls back to the image's middle column and θ0 = 0
// (measured = false) when the light is in fewer than four frames, and to θ0 = 0 with the axis on
// the light's curve there when no ghost takes part or their centres agree on no zero within
// ±max_zero_deg.
OpticalZero measureOpticalZero(const FrameStack& stack, const Horizon& horizon,
                               const std::vector<CentreSamples>& ghosts,
                               const OpticalZeroOptions& options = {});

}  // namespace flarekit::fit
