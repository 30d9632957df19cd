#pragma once
// Renders ghosts of the Walch et al. 2018 model (§3.2) into images, with derivative images for
// fitters.
//
// Sampling: each pixel (i, j) takes the value of the continuous model at its centre
// (i + 0.5, j + 0.5) (point sampling, no anti-aliasing: the model's fall-off ranges are its blur).
// Ghosts add (§3.2: "multiple ghosts can be additively blended"). Images are CV_32FC1 (grey
// ghosts) or CV_32FC3 (R, G, B ghosts); every ghost must have the image's channel count.
//
// Point samples, not the mean over the pixel: with a fall-off exponent below 1 the slope at the
// outline is infinite (model/intensity.h), so point samples make a fit's cost rough below a pixel,
// which the mean would smooth; but with the mean a fit can shrink a ghost to a rim far thinner
// than a pixel (Ei = Eo = 0.1), which averaged pixels still show by its area.
//
// Work: a ghost touches only the pixels whose centres can be within Fo of its outline (its
// bounding box grown by Fo, see ghostPixelBounds). Inside that box, square blocks are classified
// with one exact distance at their centre (the signed distance is 1-Lipschitz): blocks wholly
// deeper than Fi get the constant Ii, blocks wholly farther than Fo are skipped, and only the rest
// are evaluated pixel by pixel. The region is split into tiles that TBB renders in parallel; each
// tile is written by one task, so results do not depend on the thread count.
//
// A ViewTransform maps image positions to model positions, for rendering a model at a roll angle
// (the sample point is rotated, not the image) or at another image size.
//
// Thread safety: all functions are pure and may be called concurrently.

#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/ghost_shape.h"
#include "model/signed_distance.h"

namespace flarekit::model {

// Where in the model an image position samples:
//   q = model_center + Rot(−roll_rad)·(p − image_center) / scale,
// so the rendered image is the model image scaled by `scale` about the centres and rotated by
// `roll_rad` counter-clockwise as displayed (y down; the same sense as OpenCV's
// getRotationMatrix2D with a positive angle). Default: the identity.
struct ViewTransform {
  double roll_rad = 0;                // roll φ, radians
  double scale = 1;                   // image pixels per model pixel (> 0)
  cv::Point2d image_center{0, 0};     // the rotation centre in the image
  cv::Point2d model_center{0, 0};     // the point of the model that lands on image_center

  // The roll φ about `center` (an image's centre (W/2, H/2)), same size.
  static ViewTransform roll(double roll_rad, cv::Point2d center);

  cv::Point2d modelFromImage(cv::Point2d p) const;
  cv::Point2d imageFromModel(cv::Point2d q) const;
  bool isIdentity() const;
  bool IsValid(std::string* error) const;
};

struct RenderOptions {
  // The nearest-point search used for every pixel (see signed_distance.h).
  SignedDistanceOptions distance;
  // Side of the square tiles rendered as parallel tasks, pixels (≥ 8).
  int tile_size = 64;
  // Side of the blocks classified by one distance evaluation, pixels (≥ 1; 1 disables it).
  int block_size = 8;
  // Render tiles in parallel with TBB (false: one thread, the same result).
  bool parallel = true;

  bool IsValid(std::string* error) const;
};

// The pixels (i, j) whose centres can receive a non-zero value (or derivative) from the ghost:
// the outline's box grown by Fo, mapped through `view` (rotated box's bounding box), rounded
// outward. Not clipped to any image; may be empty only for invalid parameters.
cv::Rect ghostPixelBounds(const GhostParameters& ghost, const ViewTransform& view = {});

// The value of one ghost at image position `p` (a pixel centre is (i + 0.5, j + 0.5)), written to
// values[0 .. channels). When `jacobian` is not null it receives ∂value_c/∂q_k at
// jacobian[c * parameterCount(channels) + k] (parameters in the flat order of ghost_shape.h),
// analytic, with the nearest point held fixed (envelope theorem). The per-pixel reference the
// renderer's images agree with.
void evaluateGhost(const GhostParameters& ghost, cv::Point2d p, double* values, double* jacobian,
                   const SignedDistanceOptions& distance = {}, const ViewTransform& view = {});

// Renders the sum of `ghosts` over the region `roi` of the image (image coordinates; need not lie
// inside any particular image). Returns a roi.size() image of type CV_32FC(channels) whose pixel
// (x, y) is image pixel (roi.x + x, roi.y + y). Throws std::invalid_argument when a ghost's
// channel count differs from `channels` or options are invalid; ghosts must be valid.
cv::Mat renderGhosts(std::span<const GhostParameters> ghosts, cv::Rect roi, int channels,
                     const RenderOptions& options = {}, const ViewTransform& view = {});

// Full frame: renderGhosts over cv::Rect(0, 0, size.width, size.height).
cv::Mat renderGhosts(std::span<const GhostParameters> ghosts, cv::Size size, int channels,
                     const RenderOptions& options = {}, const ViewTransform& view = {});

// Adds the ghosts into `image`, which covers `roi` (image.size() == roi.size(), type
// CV_32FC(channels) with channels matching the ghosts). Pixels no ghost reaches are untouched.
void addGhosts(std::span<const GhostParameters> ghosts, cv::Rect roi, cv::Mat& image,
               const RenderOptions& options = {}, const ViewTransform& view = {});

// The derivative images of one ghost: ∂image/∂q_k for every parameter k of that ghost (flat order
// of ghost_shape.h). They are zero outside `rect`, so only `rect` is stored.
struct GhostDerivativeImages {
  // Image coordinates: ghostPixelBounds(ghost, view) ∩ roi (may be empty). The image of parameter
  // k at (x, y) is the derivative at image pixel (rect.x + x, rect.y + y).
  cv::Rect rect;
  // parameterCount(channels) images of rect.size(), CV_32FC(channels). For Ib_c and Ii_c only
  // channel c is non-zero.
  std::vector<cv::Mat> images;
};

struct RenderedGhosts {
  cv::Mat image;                                   // as renderGhosts returns it
  std::vector<GhostDerivativeImages> derivatives;  // one per ghost, in input order
};

// Renders over `roi` and returns, for every ghost, its analytic derivative images (envelope
// theorem at the fixed nearest point; exact where the model is smooth: away from d = 0, d = −Fi,
// d = Fo and the medial axis). Same rules as renderGhosts.
RenderedGhosts renderGhostsWithDerivatives(std::span<const GhostParameters> ghosts, cv::Rect roi,
                                           int channels, const RenderOptions& options = {},
                                           const ViewTransform& view = {});

}  // namespace flarekit::model
