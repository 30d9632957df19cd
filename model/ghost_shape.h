#pragma once
// One ghost of the data-driven flare model of Walch et al. 2018 (§3.2, Fig. 5 and 6): a shape
// made of four cubic Béziers, mirror-symmetric about the horizontal line y = My, and an intensity
// transfer function of the signed distance to that outline.
//
// Coordinates are image pixels: x to the right, y down, pixel (i, j) centred at (i + 0.5, j + 0.5)
// (docs/design.md, Conventions). All sizes and fall-off ranges are in pixels.
//
// The shape (docs/design.md, "The ghost model"):
//   centre M = (Mx, My); left point P_L = (Mx − L, My), right point P_R = (Mx + R, My),
//   top P_T = (Mx, My − h), bottom P_B = (Mx, My + h).
//   Segment 0: P_L → P_T, control points P_L + (0, −Cl·h) and P_T + (−Cl·L, 0)
//   Segment 1: P_T → P_R, control points P_T + (Cr·R, 0)  and P_R + (0, −Cr·h)
//   Segment 2: P_R → P_B, control points P_R + (0, Cr·h)  and P_B + (Cr·R, 0)
//   Segment 3: P_B → P_L, control points P_B + (−Cl·L, 0) and P_L + (0, Cl·h)
// The outline runs clockwise as displayed (y down). Segments 3 and 2 are the mirror images of
// segments 0 and 1 about y = My (with t reversed). Cl = Cr = kEllipseCurvature gives an ellipse
// (a circle for L = R = h) to within 0.03 %; smaller values flatten the sides towards the diamond
// P_L P_T P_R P_B (Cl = 0: straight lines), larger ones square them (Cl = 1: the box corners are
// control points). With 0 ≤ Cl, Cr ≤ 1 every segment is monotone in x and y and the ghost is convex.
//
// The flat parameter vector (what fitters optimise and model files store) has a fixed order:
//   index  0   1   2  3  4  5   6   7 ...            7+C ...          7+2C 8+2C 9+2C 10+2C
//   name   Mx  My  L  R  h  Cl  Cr  Ib (C channels)  Ii (C channels)  Fi   Ei   Fo   Eo
// with C = 1 (grey: "Ib", "Ii") or C = 3 (RGB: "Ib_R", "Ib_G", "Ib_B", "Ii_R", "Ii_G", "Ii_B").
// Grey ghosts have 13 parameters, RGB ghosts 17.

#include <array>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::model {

// Control-point factor for which four cubic Béziers approximate a quarter circle (ellipse):
// 4(√2 − 1)/3 ≈ 0.5523 (the paper's footnote 1, spencermortensen.com/articles/bezier-circle).
inline constexpr double kEllipseCurvature = 0.55228474983079339840;

// The parameters of one ghost (Walch 2018 §3.2). Plain data; check with isValid().
struct GhostParameters {
  // Number of colour channels of the intensity: 1 (grey, the paper's model) or 3 (R, G, B, ours).
  int channels = 1;

  // Shape (Fig. 5), pixels.
  double center_x = 0;          // Mx
  double center_y = 0;          // My: the mirror axis
  double left = 10;             // L: distance from M to the left point P_L (> 0)
  double right = 10;            // R: distance from M to the right point P_R (> 0)
  double height = 10;           // h: distance from M to the top and bottom points (> 0)
  double curvature_left = kEllipseCurvature;   // Cl in [0, 1]
  double curvature_right = kEllipseCurvature;  // Cr in [0, 1]

  // Intensity transfer function (Fig. 6), linear radiance per channel; only the first `channels`
  // entries are used (the others are ignored and stay 0 in vectors built by this library).
  std::array<double, 3> border = {1, 1, 1};  // Ib: value on the outline (d = 0)
  std::array<double, 3> inside = {0, 0, 0};  // Ii: value deep inside (d ≤ −Fi)
  double inside_falloff = 5;    // Fi: distance inside over which Ib turns into Ii, pixels (> 0)
  double inside_exponent = 1;   // Ei: slope exponent of the inside fall-off (> 0; 1 = linear)
  double outside_falloff = 2;   // Fo: distance outside over which Ib falls to 0, pixels (> 0)
  double outside_exponent = 1;  // Eo: slope exponent of the outside fall-off (> 0; 1 = linear)
};

// Indices into the flat parameter vector (see the table at the top of this file). Shape indices
// are the same for every channel count; the intensity indices depend on it.
namespace param {
inline constexpr int kMx = 0;
inline constexpr int kMy = 1;
inline constexpr int kL = 2;
inline constexpr int kR = 3;
inline constexpr int kH = 4;
inline constexpr int kCl = 5;
inline constexpr int kCr = 6;
inline constexpr int kShapeCount = 7;  // the shape parameters are indices [0, 7)
}  // namespace param

// Where each parameter sits in the flat vector for a given channel count (1 or 3).
struct ParameterLayout {
  int channels = 1;

  constexpr int ib(int channel) const { return param::kShapeCount + channel; }
  constexpr int ii(int channel) const { return param::kShapeCount + channels + channel; }
  constexpr int fi() const { return param::kShapeCount + 2 * channels; }
  constexpr int ei() const { return fi() + 1; }
  constexpr int fo() const { return fi() + 2; }
  constexpr int eo() const { return fi() + 3; }
  constexpr int count() const { return fi() + 4; }  // 13 (grey) or 17 (RGB)
};

// Number of parameters of a ghost with `channels` channels (13 or 17).
constexpr int parameterCount(int channels) { return ParameterLayout{channels}.count(); }

// The parameter's name: "Mx", "My", "L", "R", "h", "Cl", "Cr", "Ib" / "Ib_R" "Ib_G" "Ib_B",
// "Ii" / "Ii_R" ..., "Fi", "Ei", "Fo", "Eo". These are the keys of the model file.
// Throws std::out_of_range for an index outside [0, parameterCount(channels)).
std::string parameterName(int index, int channels);
// All names in vector order.
std::vector<std::string> parameterNames(int channels);
// The index of a parameter name, or -1 when the name is not one of parameterNames(channels).
int parameterIndex(std::string_view name, int channels);

// The flat vector in the documented order (size parameterCount(p.channels)).
std::vector<double> toParameterVector(const GhostParameters& p);
// The inverse of toParameterVector; `values.size()` must be parameterCount(channels)
// (std::invalid_argument otherwise). Does not check validity.
GhostParameters fromParameterVector(std::span<const double> values, int channels);

// The allowed range of every parameter: what isValid() accepts and the bounds a fitter hands to
// Ceres (SetParameterLowerBound/UpperBound). kUnbounded (= std::numeric_limits<double>::max(),
// Ceres's own default bound) marks a side without a limit. The ranges (pixels where lengths):
//   Mx, My  [−1e5, 1e5]           the centre may lie outside the image
//   L, R, h [0.5, 1e4]            half a pixel up to beyond any sensor
//   Cl, Cr  [0, 1]                convex outlines
//   Ib, Ii  [0, kUnbounded]       radiance is never negative
//   Fi, Fo  [0.1, 1e4]
//   Ei, Eo  [0.1, 10]             slope exponents
inline constexpr double kUnbounded = 1.7976931348623157e308;
struct ParameterBounds {
  double lower = 0;
  double upper = 0;
};
ParameterBounds parameterBounds(int index, int channels);

// True when `channels` is 1 or 3 and every parameter is finite and within parameterBounds().
// Otherwise false, and *error (when given) says which parameter is wrong and why, e.g.
// "L = -2 is outside [0.5, 10000]".
bool isValid(const GhostParameters& p, std::string* error = nullptr);

// Clamps every parameter into its bounds (NaN becomes the lower bound). Channels must be 1 or 3.
GhostParameters clampToBounds(const GhostParameters& p);

// A cubic Bézier B(t) = Σ b_i(t) P_i, t in [0, 1], with the Bernstein polynomials b_i.
struct CubicBezier {
  std::array<cv::Point2d, 4> p;

  cv::Point2d at(double t) const;                // B(t)
  cv::Point2d derivative(double t) const;        // B′(t)
  cv::Point2d secondDerivative(double t) const;  // B″(t)
};

// The four segments in the order documented above (0: P_L→P_T, 1: P_T→P_R, 2: P_R→P_B,
// 3: P_B→P_L), in image coordinates.
std::array<CubicBezier, 4> ghostOutline(const GhostParameters& p);

// ∂B(t)/∂q of segment `segment` for the shape parameter q in [param::kMx, param::kCr]
// (linear in the control points, so exact): what the envelope theorem needs for ∂d/∂q.
cv::Point2d outlineDerivative(const GhostParameters& p, int segment, double t, int shape_param);

// The axis-aligned box the outline spans: [Mx − L, Mx + R] × [My − h, My + h] (exact: every
// segment is monotone and its end points are the extremes).
cv::Rect2d outlineBounds(const GhostParameters& p);

}  // namespace flarekit::model
