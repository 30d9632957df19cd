#pragma once
// Internals of the nearest-point search and the inside test, shared by signed_distance.cpp and
// the renderer: the two upper-half segments in power form relative to the centre M, so the inner
// loops evaluate polynomials with fused multiply-adds. Not part of the public API.

#include <algorithm>
#include <array>
#include <cmath>

#include "model/ghost_shape.h"
#include "model/signed_distance.h"

namespace flarekit::model::detail {

inline constexpr int kMaxSamples = 65;

// A cubic in power form, relative to M: B(t) = a0 + a1·t + a2·t² + a3·t³ (per coordinate).
struct PowerCubic {
  double x0, x1, x2, x3;
  double y0, y1, y2, y3;

  double x(double t) const { return ((x3 * t + x2) * t + x1) * t + x0; }
  double y(double t) const { return ((y3 * t + y2) * t + y1) * t + y0; }
  double dx(double t) const { return (3 * x3 * t + 2 * x2) * t + x1; }
  double dy(double t) const { return (3 * y3 * t + 2 * y2) * t + y1; }
  double ddx(double t) const { return 6 * x3 * t + 2 * x2; }
  double ddy(double t) const { return 6 * y3 * t + 2 * y2; }
};

inline PowerCubic toPowerForm(const CubicBezier& b, cv::Point2d origin) {
  const cv::Point2d p0 = b.p[0] - origin, p1 = b.p[1] - origin, p2 = b.p[2] - origin,
                    p3 = b.p[3] - origin;
  PowerCubic c;
  c.x0 = p0.x;
  c.x1 = 3 * (p1.x - p0.x);
  c.x2 = 3 * (p2.x - 2 * p1.x + p0.x);
  c.x3 = p3.x - 3 * p2.x + 3 * p1.x - p0.x;
  c.y0 = p0.y;
  c.y1 = 3 * (p1.y - p0.y);
  c.y2 = 3 * (p2.y - 2 * p1.y + p0.y);
  c.y3 = p3.y - 3 * p2.y + 3 * p1.y - p0.y;
  return c;
}

// The unit tangent direction of a power-form cubic at t (B′, or B″ where B′ vanishes, as at the
// ends of Cl = 0 segments).
inline cv::Point2d tangentDirection(const PowerCubic& c, double t) {
  double x = c.dx(t), y = c.dy(t);
  double len = std::sqrt(x * x + y * y);
  if (len < 1e-12 * (1 + std::abs(c.x1) + std::abs(c.y1) + std::abs(c.x2) + std::abs(c.y2))) {
    x = c.ddx(t);
    y = c.ddy(t);
    len = std::sqrt(x * x + y * y);
  }
  return len > 0 ? cv::Point2d(x / len, y / len) : cv::Point2d(0, 0);
}

// Segments 0 (P_L→P_T) and 1 (P_T→P_R) relative to M, with their coarse samples: at least
// `samples_per_segment` evenly spaced in t, then intervals halved until the outline turns by at
// most `max_turn_deg` between neighbours (Bézier speed varies a lot on long thin shapes, and a
// sharp turn between two samples can hide a whole basin of the distance). Capped at kMaxSamples.
struct PreparedShape {
  double mx = 0, my = 0;    // M
  double left = 0, right = 0, height = 0;
  std::array<PowerCubic, 2> seg{};
  std::array<int, 2> samples{};  // samples per segment
  std::array<std::array<double, kMaxSamples>, 2> sample_t{}, sample_x{}, sample_y{};
  // Unit tangent direction at each sample (B′, or B″ where B′ vanishes).
  std::array<std::array<double, kMaxSamples>, 2> tangent_x{}, tangent_y{};
  // Bounding box of the piece between samples k and k + 1 (box of its Bézier control points).
  std::array<std::array<double, kMaxSamples>, 2> box_x0{}, box_x1{}, box_y0{}, box_y1{};

  PreparedShape() = default;
  PreparedShape(const GhostParameters& g, int samples_per_segment, double max_turn_deg = 10) {
    mx = g.center_x;
    my = g.center_y;
    left = g.left;
    right = g.right;
    height = g.height;
    const auto outline = ghostOutline(g);
    const cv::Point2d m(mx, my);
    seg[0] = toPowerForm(outline[0], m);
    seg[1] = toPowerForm(outline[1], m);
    const int uniform = std::clamp(samples_per_segment, 3, kMaxSamples);
    const double cos_max = std::cos(std::clamp(max_turn_deg, 0.1, 180.0) * 3.14159265358979323846 / 180);
    for (int s = 0; s < 2; ++s) {
      std::array<double, kMaxSamples> ts{};
      int n = uniform;
      for (int k = 0; k < n; ++k) ts[k] = static_cast<double>(k) / (n - 1);
      // Halve the interval that turns the most until every one turns by at most max_turn_deg.
      while (n < kMaxSamples) {
        int worst = -1;
        double worst_cos = cos_max;
        for (int k = 0; k + 1 < n; ++k) {
          const cv::Point2d a = tangentDirection(seg[s], ts[k]), b = tangentDirection(seg[s], ts[k + 1]);
          const double cosine = a.x * b.x + a.y * b.y;
          if (cosine < worst_cos) {
            worst_cos = cosine;
            worst = k;
          }
        }
        if (worst < 0) break;
        for (int k = n; k > worst + 1; --k) ts[k] = ts[k - 1];
        ts[worst + 1] = 0.5 * (ts[worst] + ts[worst + 2]);
        ++n;
      }
      samples[s] = n;
      for (int k = 0; k < n; ++k) {
        sample_t[s][k] = ts[k];
        sample_x[s][k] = seg[s].x(ts[k]);
        sample_y[s][k] = seg[s].y(ts[k]);
        const cv::Point2d dir = tangentDirection(seg[s], ts[k]);
        tangent_x[s][k] = dir.x;
        tangent_y[s][k] = dir.y;
      }
      for (int k = 0; k + 1 < n; ++k) {
        // The piece [a, b] as a Bézier: B(a), B(a) + (b − a)/3·B′(a), B(b) − (b − a)/3·B′(b), B(b);
        // it lies in the convex hull of these, so in their box.
        const double a = ts[k], b = ts[k + 1], third = (b - a) / 3;
        const double xs[4] = {seg[s].x(a), seg[s].x(a) + third * seg[s].dx(a),
                              seg[s].x(b) - third * seg[s].dx(b), seg[s].x(b)};
        const double ys[4] = {seg[s].y(a), seg[s].y(a) + third * seg[s].dy(a),
                              seg[s].y(b) - third * seg[s].dy(b), seg[s].y(b)};
        box_x0[s][k] = std::min({xs[0], xs[1], xs[2], xs[3]});
        box_x1[s][k] = std::max({xs[0], xs[1], xs[2], xs[3]});
        box_y0[s][k] = std::min({ys[0], ys[1], ys[2], ys[3]});
        box_y1[s][k] = std::max({ys[0], ys[1], ys[2], ys[3]});
      }
    }
  }
};

// Safeguarded Newton on f(t) = (B − p)·B′ = g′(t), g = |B − p|²/2, from t inside the bracket
// [lo, hi] that holds a local minimum of g: Newton steps that descend and stay in the bracket,
// bisection on the sign of f otherwise. Returns t; d2 receives g·2 there.
inline double refineNearest(const PowerCubic& c, double px, double py, double lo, double hi, double t,
                            int newton_steps, double& d2) {
  for (int i = 0; i < newton_steps; ++i) {
    const double bx = c.x(t) - px, by = c.y(t) - py;
    const double dx = c.dx(t), dy = c.dy(t);
    const double f = bx * dx + by * dy;
    const double fp = dx * dx + dy * dy + bx * c.ddx(t) + by * c.ddy(t);
    if (f > 0)
      hi = t;
    else if (f < 0)
      lo = t;
    else if (fp > 0)
      break;  // a minimum (f = 0 with fp ≤ 0 is a maximum, or an end where B′ = 0: go on)
    double next = (fp > 0) ? t - f / fp : lo - 1;
    if (!(next >= lo && next <= hi)) next = 0.5 * (lo + hi);  // also catches NaN
    const double moved = std::abs(next - t);
    t = next;
    if (moved < 1e-13) break;
  }
  const double bx = c.x(t) - px, by = c.y(t) - py;
  d2 = bx * bx + by * by;
  return t;
}

// The nearest point on one upper segment to the relative point (px, py): sets t and squared
// distance. Coarse samples (shared/FITTING_NOTES.md: sampling then Newton is the robust choice),
// then safeguarded Newton in every piece between two samples where the distance turns from
// falling to rising (the sign of (B − p)·T changes, T the unit tangent) unless the piece's box is
// already farther than the best point found. Every local minimum of the distance inside the
// segment lies in such a piece, unless a piece holds several, which the turn-limited sampling
// makes rare and harmless (their values differ by less than the piece's sagitta effects).
inline void nearestOnSegmentNewton(const PreparedShape& s, int which, double px, double py,
                                   int newton_steps, double& t_out, double& d2_out) {
  const PowerCubic& c = s.seg[which];
  const auto& sx = s.sample_x[which];
  const auto& sy = s.sample_y[which];
  const auto& tx = s.tangent_x[which];
  const auto& ty = s.tangent_y[which];
  const auto& st = s.sample_t[which];
  const int n = s.samples[which];
  std::array<double, kMaxSamples> slope;  // (S_k − p)·T_k: < 0 while the distance falls
  t_out = 0;
  d2_out = 1e308;
  for (int k = 0; k < n; ++k) {
    const double dx = sx[k] - px, dy = sy[k] - py;
    const double d2 = dx * dx + dy * dy;
    slope[k] = dx * tx[k] + dy * ty[k];
    if (d2 < d2_out) {
      d2_out = d2;
      t_out = st[k];
    }
  }
  for (int k = 0; k + 1 < n; ++k) {
    if (!(slope[k] < 0 && slope[k + 1] > 0)) continue;
    // Skip the piece when its box is already farther than the best point.
    const double bx = std::max({s.box_x0[which][k] - px, 0.0, px - s.box_x1[which][k]});
    const double by = std::max({s.box_y0[which][k] - py, 0.0, py - s.box_y1[which][k]});
    if (bx * bx + by * by >= d2_out) continue;
    const double start = -slope[k] < slope[k + 1] ? st[k] : st[k + 1];
    double d2 = 0;
    const double t = refineNearest(c, px, py, st[k], st[k + 1], start, newton_steps, d2);
    if (d2 < d2_out) {
      d2_out = d2;
      t_out = t;
    }
  }
}

// The paper's "binary search, 12 iterations" (Walch 2018 §3.2), read as bisection on the sign of
// (B − p)·B′ over [0, 1]; the ends are candidates too.
inline void nearestOnSegmentBisection(const PreparedShape& s, int which, double px, double py,
                                      int steps, double& t_out, double& d2_out) {
  const PowerCubic& c = s.seg[which];
  double lo = 0, hi = 1;
  for (int i = 0; i < steps; ++i) {
    const double t = 0.5 * (lo + hi);
    const double f = (c.x(t) - px) * c.dx(t) + (c.y(t) - py) * c.dy(t);
    if (f > 0)
      hi = t;
    else
      lo = t;
  }
  const double candidates[3] = {0.5 * (lo + hi), 0.0, 1.0};
  d2_out = 1e308;
  for (double t : candidates) {
    const double bx = c.x(t) - px, by = c.y(t) - py;
    const double d2 = bx * bx + by * by;
    if (d2 < d2_out) {
      d2_out = d2;
      t_out = t;
    }
  }
}

// Exact inside test on the relative, reflected point (x, y ≤ 0): pick the quarter by x, solve
// x(t) = x on that monotone segment (safeguarded Newton to full precision), compare heights.
inline bool insideRelative(const PreparedShape& s, double x, double y) {
  if (x < -s.left || x > s.right || y < -s.height) return false;
  const PowerCubic& c = s.seg[x <= 0 ? 0 : 1];
  // x(t) is non-decreasing on [0, 1] for both segments (0: −L → 0, 1: 0 → R).
  double lo = 0, hi = 1;
  double t = (x <= 0) ? 1 + x / s.left : x / s.right;  // the straight-line guess
  t = std::clamp(t, 0.0, 1.0);
  for (int i = 0; i < 60; ++i) {
    const double f = c.x(t) - x;
    if (f == 0) break;
    if (f > 0)
      hi = t;
    else
      lo = t;
    const double fp = c.dx(t);
    double next = (fp > 0) ? t - f / fp : 0.5 * (lo + hi);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (next == t || hi - lo <= 1e-15) break;
    t = next;
  }
  // y(t) is the outline's height above M at this x (negative, y down); inside below it.
  return y >= c.y(t);
}

// The full search on the reflected relative point; returns the upper segment (0 or 1), t and d².
inline void nearestUpper(const PreparedShape& s, double px, double py,
                         const SignedDistanceOptions& o, int& segment, double& t, double& d2) {
  double t0 = 0, d20 = 0, t1 = 0, d21 = 0;
  if (o.method == NearestPointMethod::kBisection12) {
    nearestOnSegmentBisection(s, 0, px, py, o.bisection_steps, t0, d20);
    nearestOnSegmentBisection(s, 1, px, py, o.bisection_steps, t1, d21);
  } else {
    nearestOnSegmentNewton(s, 0, px, py, o.newton_steps, t0, d20);
    nearestOnSegmentNewton(s, 1, px, py, o.newton_steps, t1, d21);
  }
  if (d20 <= d21) {
    segment = 0;
    t = t0;
    d2 = d20;
  } else {
    segment = 1;
    t = t1;
    d2 = d21;
  }
}

}  // namespace flarekit::model::detail
