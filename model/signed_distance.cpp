#include "model/signed_distance.h"

#include <cmath>

#include "model/detail/outline_search.h"

namespace flarekit::model {

bool SignedDistanceOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* message) {
    if (error) *error = message;
    return false;
  };
  if (samples_per_segment < 3 || samples_per_segment > detail::kMaxSamples)
    return fail("samples_per_segment must be in [3, 65]");
  if (!(max_sample_turn_deg > 0 && max_sample_turn_deg <= 180))
    return fail("max_sample_turn_deg must be in (0, 180]");
  if (newton_steps < 1 || newton_steps > 100) return fail("newton_steps must be in [1, 100]");
  if (bisection_steps < 1 || bisection_steps > 60) return fail("bisection_steps must be in [1, 60]");
  if (method != NearestPointMethod::kSampledNewton && method != NearestPointMethod::kBisection12)
    return fail("unknown nearest-point method");
  return true;
}

NearestPoint nearestPoint(const GhostParameters& shape, cv::Point2d p,
                          const SignedDistanceOptions& options) {
  const detail::PreparedShape s(shape, options.samples_per_segment, options.max_sample_turn_deg);
  // Reflect into the upper half (y ≤ My), where the nearest point lies on segment 0 or 1.
  const double rx = p.x - s.mx;
  const bool lower = p.y > s.my;
  const double ry = -std::abs(p.y - s.my);
  int segment = 0;
  double t = 0, d2 = 0;
  detail::nearestUpper(s, rx, ry, options, segment, t, d2);
  NearestPoint n;
  n.inside = detail::insideRelative(s, rx, ry);
  const double d = std::sqrt(d2);
  n.distance = n.inside ? -d : d;
  const detail::PowerCubic& c = s.seg[segment];
  const double bx = c.x(t), by = c.y(t);
  if (lower) {  // segments 3 and 2 mirror segments 0 and 1 with t reversed
    n.segment = 3 - segment;
    n.t = 1 - t;
    n.point = cv::Point2d(s.mx + bx, s.my - by);
  } else {
    n.segment = segment;
    n.t = t;
    n.point = cv::Point2d(s.mx + bx, s.my + by);
  }
  return n;
}

double signedDistance(const GhostParameters& shape, cv::Point2d p,
                      const SignedDistanceOptions& options) {
  return nearestPoint(shape, p, options).distance;
}

bool isInside(const GhostParameters& shape, cv::Point2d p) {
  const detail::PreparedShape s(shape, 3);
  return detail::insideRelative(s, p.x - s.mx, -std::abs(p.y - s.my));
}

std::array<double, param::kShapeCount> signedDistanceGradient(const GhostParameters& shape,
                                                               cv::Point2d p,
                                                               const NearestPoint& nearest) {
  // d = σ|p − B(t*)|; by the envelope theorem ∂d/∂q = −σ u·∂B/∂q(t*) with u the unit vector from
  // B(t*) to p. On the outline u is undefined: use the outward normal,
  // which σu equals wherever the nearest point is not a corner.
  cv::Point2d n = p - nearest.point;
  const double len = std::hypot(n.x, n.y);
  if (len > 1e-12) {
    n *= (nearest.inside ? -1.0 : 1.0) / len;  // σu: the outward direction
  } else {
    const auto outline = ghostOutline(shape);
    const cv::Point2d tangent = outline[nearest.segment].derivative(nearest.t);
    const double tl = std::hypot(tangent.x, tangent.y);
    // The outline runs clockwise as displayed (y down), so the outward normal is the tangent
    // turned by −90° in these coordinates: (t.y, −t.x)... checked: top segment 1 has tangent +x
    // and outward −y.
    n = tl > 0 ? cv::Point2d(tangent.y, -tangent.x) * (1 / tl) : cv::Point2d(0, 0);
  }
  std::array<double, param::kShapeCount> g{};
  for (int q = 0; q < param::kShapeCount; ++q) {
    const cv::Point2d db = outlineDerivative(shape, nearest.segment, nearest.t, q);
    g[q] = -(n.x * db.x + n.y * db.y);
  }
  return g;
}

}  // namespace flarekit::model
