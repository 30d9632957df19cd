#include "model/ghost_shape.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace flarekit::model {
namespace {

constexpr const char* kChannelSuffix[3] = {"_R", "_G", "_B"};

void checkChannels(int channels) {
  if (channels != 1 && channels != 3)
    throw std::invalid_argument("ghost channels must be 1 or 3, got " + std::to_string(channels));
}

std::string formatNumber(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

}  // namespace

std::string parameterName(int index, int channels) {
  checkChannels(channels);
  static constexpr const char* kShape[] = {"Mx", "My", "L", "R", "h", "Cl", "Cr"};
  const ParameterLayout layout{channels};
  if (index < 0 || index >= layout.count())
    throw std::out_of_range("ghost parameter index " + std::to_string(index) + " out of range");
  if (index < param::kShapeCount) return kShape[index];
  if (index < layout.fi()) {
    const bool is_border = index < layout.ii(0);
    const int c = is_border ? index - layout.ib(0) : index - layout.ii(0);
    std::string name = is_border ? "Ib" : "Ii";
    if (channels == 3) name += kChannelSuffix[c];
    return name;
  }
  static constexpr const char* kFalloff[] = {"Fi", "Ei", "Fo", "Eo"};
  return kFalloff[index - layout.fi()];
}

std::vector<std::string> parameterNames(int channels) {
  std::vector<std::string> names;
  for (int k = 0; k < parameterCount(channels); ++k) names.push_back(parameterName(k, channels));
  return names;
}

int parameterIndex(std::string_view name, int channels) {
  if (channels != 1 && channels != 3) return -1;
  for (int k = 0; k < parameterCount(channels); ++k)
    if (parameterName(k, channels) == name) return k;
  return -1;
}

std::vector<double> toParameterVector(const GhostParameters& p) {
  checkChannels(p.channels);
  const ParameterLayout layout{p.channels};
  std::vector<double> v(layout.count());
  v[param::kMx] = p.center_x;
  v[param::kMy] = p.center_y;
  v[param::kL] = p.left;
  v[param::kR] = p.right;
  v[param::kH] = p.height;
  v[param::kCl] = p.curvature_left;
  v[param::kCr] = p.curvature_right;
  for (int c = 0; c < p.channels; ++c) {
    v[layout.ib(c)] = p.border[c];
    v[layout.ii(c)] = p.inside[c];
  }
  v[layout.fi()] = p.inside_falloff;
  v[layout.ei()] = p.inside_exponent;
  v[layout.fo()] = p.outside_falloff;
  v[layout.eo()] = p.outside_exponent;
  return v;
}

GhostParameters fromParameterVector(std::span<const double> v, int channels) {
  checkChannels(channels);
  const ParameterLayout layout{channels};
  if (static_cast<int>(v.size()) != layout.count())
    throw std::invalid_argument("ghost parameter vector has " + std::to_string(v.size()) +
                                " values, expected " + std::to_string(layout.count()));
  GhostParameters p;
  p.channels = channels;
  p.center_x = v[param::kMx];
  p.center_y = v[param::kMy];
  p.left = v[param::kL];
  p.right = v[param::kR];
  p.height = v[param::kH];
  p.curvature_left = v[param::kCl];
  p.curvature_right = v[param::kCr];
  p.border = {0, 0, 0};
  p.inside = {0, 0, 0};
  for (int c = 0; c < channels; ++c) {
    p.border[c] = v[layout.ib(c)];
    p.inside[c] = v[layout.ii(c)];
  }
  p.inside_falloff = v[layout.fi()];
  p.inside_exponent = v[layout.ei()];
  p.outside_falloff = v[layout.fo()];
  p.outside_exponent = v[layout.eo()];
  return p;
}

ParameterBounds parameterBounds(int index, int channels) {
  checkChannels(channels);
  const ParameterLayout layout{channels};
  if (index < 0 || index >= layout.count())
    throw std::out_of_range("ghost parameter index " + std::to_string(index) + " out of range");
  switch (index) {
    case param::kMx:
    case param::kMy: return {-1e5, 1e5};
    case param::kL:
    case param::kR:
    case param::kH: return {0.5, 1e4};
    case param::kCl:
    case param::kCr: return {0.0, 1.0};
    default: break;
  }
  if (index < layout.fi()) return {0.0, kUnbounded};  // Ib, Ii
  if (index == layout.fi() || index == layout.fo()) return {0.1, 1e4};
  return {0.1, 10.0};  // Ei, Eo
}

bool isValid(const GhostParameters& p, std::string* error) {
  auto fail = [&](const std::string& message) {
    if (error) *error = message;
    return false;
  };
  if (p.channels != 1 && p.channels != 3)
    return fail("channels = " + std::to_string(p.channels) + " (must be 1 or 3)");
  const std::vector<double> v = toParameterVector(p);
  for (int k = 0; k < static_cast<int>(v.size()); ++k) {
    const ParameterBounds b = parameterBounds(k, p.channels);
    const std::string name = parameterName(k, p.channels);
    if (!std::isfinite(v[k])) return fail(name + " is not finite");
    if (v[k] < b.lower || v[k] > b.upper) {
      // Built by appends: GCC 12 reports a false -Wrestrict for "[" + std::string temporaries.
      std::string range = "[";
      range.append(formatNumber(b.lower))
          .append(", ")
          .append(b.upper == kUnbounded ? std::string("inf") : formatNumber(b.upper))
          .append("]");
      return fail(name + " = " + formatNumber(v[k]) + " is outside " + range);
    }
  }
  return true;
}

GhostParameters clampToBounds(const GhostParameters& p) {
  std::vector<double> v = toParameterVector(p);
  for (int k = 0; k < static_cast<int>(v.size()); ++k) {
    const ParameterBounds b = parameterBounds(k, p.channels);
    v[k] = std::isnan(v[k]) ? b.lower : std::clamp(v[k], b.lower, b.upper);
  }
  return fromParameterVector(v, p.channels);
}

cv::Point2d CubicBezier::at(double t) const {
  const double s = 1 - t;
  const double b0 = s * s * s, b1 = 3 * s * s * t, b2 = 3 * s * t * t, b3 = t * t * t;
  return b0 * p[0] + b1 * p[1] + b2 * p[2] + b3 * p[3];
}

cv::Point2d CubicBezier::derivative(double t) const {
  const double s = 1 - t;
  return 3 * s * s * (p[1] - p[0]) + 6 * s * t * (p[2] - p[1]) + 3 * t * t * (p[3] - p[2]);
}

cv::Point2d CubicBezier::secondDerivative(double t) const {
  return 6 * (1 - t) * (p[2] - 2 * p[1] + p[0]) + 6 * t * (p[3] - 2 * p[2] + p[1]);
}

std::array<CubicBezier, 4> ghostOutline(const GhostParameters& g) {
  const double mx = g.center_x, my = g.center_y, l = g.left, r = g.right, h = g.height;
  const double cl = g.curvature_left, cr = g.curvature_right;
  const cv::Point2d pl(mx - l, my), pt(mx, my - h), pr(mx + r, my), pb(mx, my + h);
  std::array<CubicBezier, 4> s;
  s[0].p = {pl, pl + cv::Point2d(0, -cl * h), pt + cv::Point2d(-cl * l, 0), pt};
  s[1].p = {pt, pt + cv::Point2d(cr * r, 0), pr + cv::Point2d(0, -cr * h), pr};
  s[2].p = {pr, pr + cv::Point2d(0, cr * h), pb + cv::Point2d(cr * r, 0), pb};
  s[3].p = {pb, pb + cv::Point2d(-cl * l, 0), pl + cv::Point2d(0, cl * h), pl};
  return s;
}

cv::Point2d outlineDerivative(const GhostParameters& g, int segment, double t, int q) {
  if (segment < 0 || segment > 3) throw std::out_of_range("segment must be 0..3");
  if (q < 0 || q >= param::kShapeCount) throw std::out_of_range("not a shape parameter");
  if (q == param::kMx) return {1, 0};
  if (q == param::kMy) return {0, 1};
  // Control points relative to M; their derivatives are constant (the outline is linear in Mx,
  // My, and in L, R, h for fixed Cl, Cr, bilinear in (L, Cl), (h, Cl), (R, Cr), (h, Cr)).
  const double l = g.left, r = g.right, h = g.height;
  const double cl = g.curvature_left, cr = g.curvature_right;
  // Upper-half segments 0 and 1; the lower ones mirror them (y → −y) with t reversed.
  const bool lower = segment >= 2;
  const bool left_side = segment == 0 || segment == 3;
  const double tt = lower ? 1 - t : t;
  std::array<cv::Point2d, 4> dp{};
  if (left_side) {  // segment 0: (−L, 0), (−L, −Cl·h), (−Cl·L, −h), (0, −h)
    if (q == param::kL) dp = {cv::Point2d(-1, 0), cv::Point2d(-1, 0), cv::Point2d(-cl, 0), cv::Point2d(0, 0)};
    if (q == param::kH) dp = {cv::Point2d(0, 0), cv::Point2d(0, -cl), cv::Point2d(0, -1), cv::Point2d(0, -1)};
    if (q == param::kCl) dp = {cv::Point2d(0, 0), cv::Point2d(0, -h), cv::Point2d(-l, 0), cv::Point2d(0, 0)};
  } else {  // segment 1: (0, −h), (Cr·R, −h), (R, −Cr·h), (R, 0)
    if (q == param::kR) dp = {cv::Point2d(0, 0), cv::Point2d(cr, 0), cv::Point2d(1, 0), cv::Point2d(1, 0)};
    if (q == param::kH) dp = {cv::Point2d(0, -1), cv::Point2d(0, -1), cv::Point2d(0, -cr), cv::Point2d(0, 0)};
    if (q == param::kCr) dp = {cv::Point2d(0, 0), cv::Point2d(r, 0), cv::Point2d(0, -h), cv::Point2d(0, 0)};
  }
  CubicBezier b;
  b.p = dp;
  cv::Point2d d = b.at(tt);
  if (lower) d.y = -d.y;
  return d;
}

cv::Rect2d outlineBounds(const GhostParameters& g) {
  return {g.center_x - g.left, g.center_y - g.height, g.left + g.right, 2 * g.height};
}

}  // namespace flarekit::model
