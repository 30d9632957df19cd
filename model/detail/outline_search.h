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

// Two doubles (x, y) operated on together (GCC/Clang vector extension: one SSE2 instruction for
// both on x86-64, plain scalar code elsewhere). Each lane's arithmetic is the scalar one, so
// results are identical bit for bit to the scalar expressions.
typedef double Pair __attribute__((vector_size(16)));

// A cubic in power form, relative to M: B(t) = a0 + a1·t + a2·t² + a3·t³ (per coordinate).
struct PowerCubic {
  double x0, x1, x2, x3;
  double y0, y1, y2, y3;
  // The same coefficients as (x, y) pairs for the renderer's Newton iteration, with the factors
  // of the derivatives applied: (3·a3), (2·a2), (6·a3) are the products the scalar expressions
  // below form first, so B, B′ and B″ from pairs equal x(t) … ddy(t) exactly. Set by finish().
  Pair p0, p1, p2, p3, dp2, dp3, ddp3;

  double x(double t) const { return ((x3 * t + x2) * t + x1) * t + x0; }
  double y(double t) const { return ((y3 * t + y2) * t + y1) * t + y0; }
  double dx(double t) const { return (3 * x3 * t + 2 * x2) * t + x1; }
  double dy(double t) const { return (3 * y3 * t + 2 * y2) * t + y1; }
  double ddx(double t) const { return 6 * x3 * t + 2 * x2; }
  double ddy(double t) const { return 6 * y3 * t + 2 * y2; }

  // (x(t), y(t)), (dx(t), dy(t)), (ddx(t), ddy(t)) from the pairs.
  Pair point(Pair t) const { return ((p3 * t + p2) * t + p1) * t + p0; }
  Pair tangent(Pair t) const { return (dp3 * t + dp2) * t + p1; }
  Pair second(Pair t) const { return ddp3 * t + dp2; }

  // The terms of a Newton step on g(t) = |B(t) − p|²/2 for the nearest point to p: f = g′ =
  // (B − p)·B′, fp = g″ = |B′|² + (B − p)·B″, and speed2 = |B′|², from the pairs (the same bits
  // as the scalar expressions).
  struct NewtonTerms {
    double f, fp, speed2;
  };
  NewtonTerms newtonTerms(double t, Pair p) const {
    const Pair tt = {t, t};
    const Pair b = point(tt) - p, d = tangent(tt);
    const Pair bd = b * d, dd = d * d, bdd = b * second(tt);
    const double speed2 = dd[0] + dd[1];
    return {bd[0] + bd[1], speed2 + bdd[0] + bdd[1], speed2};
  }

  void finish() {
    p0 = Pair{x0, y0};
    p1 = Pair{x1, y1};
    p2 = Pair{x2, y2};
    p3 = Pair{x3, y3};
    dp2 = Pair{2 * x2, 2 * y2};
    dp3 = Pair{3 * x3, 3 * y3};
    ddp3 = Pair{6 * x3, 6 * y3};
  }
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
  c.finish();
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

// The smallest radius of curvature |B′|³/|B′ × B″| over [a, b], from 17 evaluations, times 0.9
// for what lies between them (it varies slowly within a piece that turns by a few degrees).
inline double curvatureRadius(const PowerCubic& c, double a, double b) {
  double r = 1e308;
  for (int i = 0; i <= 16; ++i) {
    const double t = a + (b - a) * i / 16;
    const double dx = c.dx(t), dy = c.dy(t);
    const double cross = std::abs(dx * c.ddy(t) - dy * c.ddx(t));
    const double speed = std::sqrt(dx * dx + dy * dy);
    if (speed > 0 && cross > 0) r = std::min(r, speed * speed * speed / cross);
  }
  return 0.9 * r;
}

// Segments 0 (P_L→P_T) and 1 (P_T→P_R) relative to M, with their coarse samples: at least
// `samples_per_segment` evenly spaced in t, then intervals halved until the outline turns by at
// most `max_turn_deg` between neighbours (Bézier speed varies a lot on long thin shapes, and a
// sharp turn between two samples can hide a whole basin of the distance). Capped at kMaxSamples.
struct PreparedShape {
  double mx = 0, my = 0;    // M
  double left = 0, right = 0, height = 0;
  double size2 = 0;  // (L + R + h)²: the scale of B′², pixels²
  double speed2_floor = 0;  // 1e-12·size2: B′² below this counts as B′ = 0 (a corner)
  std::array<PowerCubic, 2> seg{};
  std::array<int, 2> samples{};  // samples per segment
  std::array<std::array<double, kMaxSamples>, 2> sample_t{}, sample_x{}, sample_y{};
  // Unit tangent direction at each sample (B′, or B″ where B′ vanishes).
  std::array<std::array<double, kMaxSamples>, 2> tangent_x{}, tangent_y{};
  // Bounding box of the piece between samples k and k + 1 (box of its Bézier control points).
  std::array<std::array<double, kMaxSamples>, 2> box_x0{}, box_x1{}, box_y0{}, box_y1{};
  // A lower estimate of the radius of curvature ρ over each piece. g(t) = |B(t) − p|²/2 has
  // g″ = |B′|²(1 − D/ρ) at a stationary point at distance D on the concave side (else > 0), so
  // two minima in a piece need a maximum between them with D ≥ ρ: while every point of the piece
  // is closer to p than ρ, the piece holds at most one local minimum.
  std::array<std::array<double, kMaxSamples>, 2> curvature_radius{};
  // A lower bound of the radius of curvature over the whole closed outline (the smallest of the
  // pieces' estimates), or 0 where the outline has corners (Cl = 0 or Cr = 0, where B′ vanishes at
  // a joint). By Blaschke's rolling theorem (a convex curve whose radius of curvature is ≥ ρ
  // everywhere lets a disc of radius ρ roll freely inside it), the disc of this radius tangent
  // from inside at any outline point lies inside the ghost: what certifies inside distances in
  // certifiedNearest().
  double min_curvature_radius = 0;
  // The edges of the sample polygon (consecutive samples of each segment): outward unit normal n
  // and offset c = n·(sample), so that c − n·p is p's distance below the edge's line. The samples
  // lie on the convex outline, so their polygon lies inside the ghost (see depthLowerBound).
  std::array<std::array<double, kMaxSamples>, 2> edge_nx{}, edge_ny{}, edge_c{};

  PreparedShape() = default;
  PreparedShape(const GhostParameters& g, int samples_per_segment, double max_turn_deg = 10) {
    mx = g.center_x;
    my = g.center_y;
    left = g.left;
    right = g.right;
    height = g.height;
    size2 = (left + right + height) * (left + right + height);
    speed2_floor = 1e-12 * size2;
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
        curvature_radius[s][k] = curvatureRadius(seg[s], a, b);
      }
    }
    // Corners (B′ = 0 at a joint) have no curvature bound: no inside certificate there.
    const double smallest_curvature = std::min(g.curvature_left, g.curvature_right);
    min_curvature_radius = 1e308;
    for (int s = 0; s < 2; ++s)
      for (int k = 0; k + 1 < samples[s]; ++k)
        min_curvature_radius = std::min(min_curvature_radius, curvature_radius[s][k]);
    if (!(smallest_curvature > 1e-6) || !(min_curvature_radius < 1e300)) min_curvature_radius = 0;
    for (int w = 0; w < 2; ++w)
      for (int k = 0; k + 1 < samples[w]; ++k) {
        const double ex = sample_x[w][k + 1] - sample_x[w][k], ey = sample_y[w][k + 1] - sample_y[w][k];
        const double len = std::sqrt(ex * ex + ey * ey);
        // Outward: the edge direction turned by −90° (clockwise outline as displayed, y down); a
        // degenerate edge bounds nothing.
        edge_nx[w][k] = len > 0 ? ey / len : 0;
        edge_ny[w][k] = len > 0 ? -ex / len : 0;
        edge_c[w][k] = len > 0 ? edge_nx[w][k] * sample_x[w][k] + edge_ny[w][k] * sample_y[w][k] : 1e308;
      }
  }
};

// Safeguarded Newton on f(t) = (B − p)·B′ = g′(t), g = |B − p|²/2, from t inside the bracket
// [lo, hi] that holds a local minimum of g: Newton steps that descend and stay in the bracket,
// bisection on the sign of f otherwise. Returns t; d2 receives g·2 there.
inline double refineNearest(const PowerCubic& c, double px, double py, double lo, double hi, double t,
                            int newton_steps, double& d2) {
  const Pair p = {px, py};
  for (int i = 0; i < newton_steps; ++i) {
    const auto [f, fp, speed2] = c.newtonTerms(t, p);
    if (f > 0)
      hi = t;
    else if (f < 0)
      lo = t;
    else if (fp > 0)
      break;  // a minimum (f = 0 with fp ≤ 0 is a maximum, or an end where B′ = 0: go on)
    double next = (fp > 0) ? t - f / fp : lo - 1;
    const bool newton = next >= lo && next <= hi;
    if (!newton) next = 0.5 * (lo + hi);  // also catches NaN
    const double moved = next - t;
    t = next;
    // A Newton step that moves the point by less than 1e-5 px leaves an error of the order of
    // its square (quadratic convergence): done.
    if (newton && moved * moved * speed2 < 1e-10) break;
    if (std::abs(moved) < 1e-15) break;
  }
  const Pair tt = {t, t};
  const Pair b = c.point(tt) - p, bb = b * b;
  d2 = bb[0] + bb[1];
  return t;
}

// Best point so far of a search.
struct Candidate {
  int segment = 0;
  double t = 0;
  double d2 = 1e308;
};

// Distances below this need no further search for a nearer point (pixels): a piece whose box is
// at most this much nearer than the best point cannot improve it by more.
inline constexpr double kDistanceTolerance = 1e-4;

// Searches the piece [a, b] of segment `which` for a point nearer than `best`, given the piece's
// box and a lower bound of its radius of curvature:
//  - a piece whose box is farther than the best point (or than the cutoff) is skipped;
//  - where the slope (B − p)·T turns from falling to rising between the ends, a safeguarded
//    Newton finds the minimum inside;
//  - the piece is done when it can hold no other minimum: every point of its box is closer to p
//    than the radius of curvature (two minima need a maximum between them at a distance ≥ ρ,
//    where g″ = |B′|²(1 − D/ρ) ≤ 0), or g″ > 0 over the whole piece (convexityLowerBound: the
//    case of points farther than ρ), or its box is within kDistanceTolerance of the best point;
//  - otherwise it is split in four and searched again (depth ≤ 6).
// The ends are the caller's candidates.
inline void splitPiece(const PowerCubic& c, int which, double px, double py,
                                         double a, double b, double slope_a, double slope_b,
                                         double curvature_radius, int depth, int newton_steps,
                                         double cutoff2, Candidate& best);

inline double boxGap2(double px, double py, double x0, double x1, double y0, double y1) {
  const double gx = std::max(std::max(x0 - px, px - x1), 0.0);
  const double gy = std::max(std::max(y0 - py, py - y1), 0.0);
  return gx * gx + gy * gy;
}

// A lower bound of g″(t) = |B′(t)|² + (B(t) − p)·B″(t) over the piece [a, b] whose box is
// [x0, x1] × [y0, y1], by interval arithmetic: B − p lies in the box less p, B″ is linear in t
// and B′ quadratic. Where it is positive, g is convex over the piece, so the piece holds at most
// one minimum of the distance: inside it where the slope turns from falling to rising, else at
// an end. Points far outside a ghost (the fall-off of a glow reaches hundreds of pixels) are
// farther than the radius of curvature, where the test in searchPiece cannot tell, while g is
// convex about their nearest point (B″ points away from p there); without this bound their
// search split the pieces next to the minimum down to the last depth.
inline double convexityLowerBound(const PowerCubic& c, double px, double py, double a, double b,
                                  double x0, double x1, double y0, double y1) {
  // The range of q(t) = q0 + q1·t + q2·t² over [a, b]: its ends and its vertex.
  auto quadratic = [a, b](double q0, double q1, double q2, double& lo, double& hi) {
    const double qa = (q2 * a + q1) * a + q0, qb = (q2 * b + q1) * b + q0;
    lo = std::min(qa, qb);
    hi = std::max(qa, qb);
    if (q2 != 0) {
      const double tv = -q1 / (2 * q2);
      if (tv > a && tv < b) {
        const double qv = (q2 * tv + q1) * tv + q0;
        lo = std::min(lo, qv);
        hi = std::max(hi, qv);
      }
    }
  };
  auto least_square = [](double lo, double hi) { return lo > 0 ? lo * lo : hi < 0 ? hi * hi : 0.0; };
  auto least_product = [](double u0, double u1, double v0, double v1) {
    return std::min({u0 * v0, u0 * v1, u1 * v0, u1 * v1});
  };
  double dx0, dx1, dy0, dy1;
  quadratic(c.x1, 2 * c.x2, 3 * c.x3, dx0, dx1);
  quadratic(c.y1, 2 * c.y2, 3 * c.y3, dy0, dy1);
  const double ddxa = c.ddx(a), ddxb = c.ddx(b), ddya = c.ddy(a), ddyb = c.ddy(b);
  const double speed2 = least_square(dx0, dx1) + least_square(dy0, dy1);
  const double bend = least_product(x0 - px, x1 - px, std::min(ddxa, ddxb), std::max(ddxa, ddxb)) +
                      least_product(y0 - py, y1 - py, std::min(ddya, ddyb), std::max(ddya, ddyb));
  // Rounding: each term is within a few ulps of its magnitude; demand a margin well above that.
  const double sum = speed2 + bend;
  return sum > 1e-9 * (speed2 + std::abs(bend)) ? sum : 0.0;
}

inline void searchPiece(const PowerCubic& c, int which, double px, double py, double a, double b,
                        double slope_a, double slope_b, double box_x0, double box_x1, double box_y0,
                        double box_y1, double curvature_radius, int depth, int newton_steps,
                        double cutoff2, Candidate& best, double hint = -1) {
  const double lower2 = boxGap2(px, py, box_x0, box_x1, box_y0, box_y1);
  if (lower2 >= std::min(best.d2, cutoff2)) return;
  if (slope_a < 0 && slope_b > 0) {
    double d2 = 0;
    const double start = (hint > a && hint < b) ? hint : (-slope_a < slope_b ? a : b);
    const double t = refineNearest(c, px, py, a, b, start, newton_steps, d2);
    if (d2 < best.d2) best = {which, t, d2};
  }
  const double fx = std::max(std::abs(box_x0 - px), std::abs(box_x1 - px));
  const double fy = std::max(std::abs(box_y0 - py), std::abs(box_y1 - py));
  if (fx * fx + fy * fy < curvature_radius * curvature_radius) return;  // at most one minimum
  if (convexityLowerBound(c, px, py, a, b, box_x0, box_x1, box_y0, box_y1) > 0) return;  // the same
  if (std::sqrt(lower2) >= std::sqrt(std::min(best.d2, cutoff2)) - kDistanceTolerance) return;
  if (depth >= 6) return;
  splitPiece(c, which, px, py, a, b, slope_a, slope_b, curvature_radius, depth, newton_steps,
             cutoff2, best);
}

// Splits a piece in four (samples, slopes, boxes) and searches the parts (rarely needed, so kept
// out of line).
inline void splitPiece(const PowerCubic& c, int which, double px, double py,
                                         double a, double b, double slope_a, double slope_b,
                                         double curvature_radius, int depth, int newton_steps,
                                         double cutoff2, Candidate& best) {
  constexpr int kParts = 4;
  // The points and tangents at the part ends, each evaluated once (neighbouring parts share an
  // end).
  double ts[kParts + 1], slopes[kParts + 1], x[kParts + 1], y[kParts + 1], dx[kParts + 1], dy[kParts + 1];
  for (int i = 0; i <= kParts; ++i) {
    ts[i] = a + (b - a) * i / kParts;
    const double t = ts[i];
    x[i] = c.x(t);
    y[i] = c.y(t);
    dx[i] = c.dx(t);
    dy[i] = c.dy(t);
    if (i == 0) {
      slopes[i] = slope_a;
    } else if (i == kParts) {
      slopes[i] = slope_b;
    } else {
      const double bx = x[i] - px, by = y[i] - py;
      const double d2 = bx * bx + by * by;
      if (d2 < best.d2) best = {which, t, d2};
      const cv::Point2d dir = tangentDirection(c, t);
      slopes[i] = bx * dir.x + by * dir.y;
    }
  }
  for (int i = 0; i < kParts; ++i) {
    const double u = ts[i], v = ts[i + 1], third = (v - u) / 3;
    const double xs[4] = {x[i], x[i] + third * dx[i], x[i + 1] - third * dx[i + 1], x[i + 1]};
    const double ys[4] = {y[i], y[i] + third * dy[i], y[i + 1] - third * dy[i + 1], y[i + 1]};
    searchPiece(c, which, px, py, u, v, slopes[i], slopes[i + 1],
                std::min({xs[0], xs[1], xs[2], xs[3]}), std::max({xs[0], xs[1], xs[2], xs[3]}),
                std::min({ys[0], ys[1], ys[2], ys[3]}), std::max({ys[0], ys[1], ys[2], ys[3]}),
                curvature_radius, depth + 1, newton_steps, cutoff2, best);
  }
}

// The nearest point of the upper segments 0 and 1 to the relative point (px, py). Coarse samples
// (a plain Newton or bisection from one start misses basins), then every piece between two
// samples that could hold a nearer point (by its box) is searched (searchPiece), so no basin
// of the distance hides between samples, even deep inside long thin shapes. The segment holding
// the best sample is searched first, so its result prunes the other.
//
// With a finite `cutoff` the search only guarantees the exact distance when it is below the
// cutoff; otherwise the result is a point at least `cutoff` away (what a renderer needs where the
// transfer function has saturated).
inline Candidate nearestUpperNewton(const PreparedShape& s, double px, double py, int newton_steps,
                                    double cutoff) {
  const double cutoff2 = cutoff < 1e150 ? cutoff * cutoff : 1e308;
  std::array<std::array<double, kMaxSamples>, 2> d2s, slopes;
  Candidate best;
  for (int w = 0; w < 2; ++w) {
    const int n = s.samples[w];
    const double* sx = s.sample_x[w].data();
    const double* sy = s.sample_y[w].data();
    const double* tx = s.tangent_x[w].data();
    const double* ty = s.tangent_y[w].data();
    double* d2 = d2s[w].data();
    double* slope = slopes[w].data();
    for (int k = 0; k < n; ++k) {  // vectorizable
      const double dx = sx[k] - px, dy = sy[k] - py;
      d2[k] = dx * dx + dy * dy;
      slope[k] = dx * tx[k] + dy * ty[k];  // < 0 while the distance falls
    }
    for (int k = 0; k < n; ++k)
      if (d2[k] < best.d2) best = {w, s.sample_t[w][k], d2[k]};
  }
  const int first = best.segment;
  for (int w : {first, 1 - first}) {
    const int n = s.samples[w];
    const auto& st = s.sample_t[w];
    for (int k = 0; k + 1 < n; ++k)
      searchPiece(s.seg[w], w, px, py, st[k], st[k + 1], slopes[w][k], slopes[w][k + 1],
                  s.box_x0[w][k], s.box_x1[w][k], s.box_y0[w][k], s.box_y1[w][k],
                  s.curvature_radius[w][k], 0, newton_steps, cutoff2, best);
  }
  return best;
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

// The pieces that can hold the nearest point of any point within `reach` of the (reflected,
// relative) point (cx, cy), given that every such point is within `upper` of the outline: the
// renderer finds them once per block of pixels and searches only them per pixel. `certified`
// is false when there are too many of them for the list (then the caller uses the full search).
struct BlockPieces {
  static constexpr int kMax = 24;
  int count = 0;
  bool certified = true;
  std::array<unsigned char, kMax> segment{}, piece{};
};

inline BlockPieces collectBlockPieces(const PreparedShape& s, double cx, double cy, double reach,
                                      double upper) {
  BlockPieces out;
  const double limit = upper + reach;  // box distance from the centre below which a piece counts
  for (int w = 0; w < 2; ++w)
    for (int k = 0; k + 1 < s.samples[w]; ++k) {
      const double x0 = s.box_x0[w][k], x1 = s.box_x1[w][k], y0 = s.box_y0[w][k], y1 = s.box_y1[w][k];
      const double gx = std::max({x0 - cx, 0.0, cx - x1}), gy = std::max({y0 - cy, 0.0, cy - y1});
      if (gx * gx + gy * gy > limit * limit) continue;
      if (out.count == BlockPieces::kMax) {
        out.certified = false;
        return out;
      }
      out.segment[out.count] = static_cast<unsigned char>(w);
      out.piece[out.count] = static_cast<unsigned char>(k);
      ++out.count;
    }
  return out;
}

// The nearest point to (px, py) among the block's pieces, searched with searchPiece (the same
// search as nearestUpperNewton restricted to the pieces that can matter). `hint` (the previous
// pixel's nearest point) gives a first upper bound, so most pieces are dismissed by their box
// alone, and starts Newton in its piece.
inline Candidate nearestInPieces(const PreparedShape& s, const BlockPieces& b, double px, double py,
                                 int newton_steps, const Candidate* hint) {
  Candidate best;
  if (hint) {
    const PowerCubic& c = s.seg[hint->segment];
    const double dx = c.x(hint->t) - px, dy = c.y(hint->t) - py;
    best = {hint->segment, hint->t, dx * dx + dy * dy};
  }
  for (int i = 0; i < b.count; ++i) {
    const int w = b.segment[i], k = b.piece[i];
    if (boxGap2(px, py, s.box_x0[w][k], s.box_x1[w][k], s.box_y0[w][k], s.box_y1[w][k]) >= best.d2)
      continue;
    double slope[2];
    for (int e = 0; e < 2; ++e) {
      const double dx = s.sample_x[w][k + e] - px, dy = s.sample_y[w][k + e] - py;
      const double d2 = dx * dx + dy * dy;
      slope[e] = dx * s.tangent_x[w][k + e] + dy * s.tangent_y[w][k + e];
      if (d2 < best.d2) best = {w, s.sample_t[w][k + e], d2};
    }
    searchPiece(s.seg[w], w, px, py, s.sample_t[w][k], s.sample_t[w][k + 1], slope[0], slope[1],
                s.box_x0[w][k], s.box_x1[w][k], s.box_y0[w][k], s.box_y1[w][k],
                s.curvature_radius[w][k], 0, newton_steps, 1e308, best,
                hint && hint->segment == w ? hint->t : -1.0);
  }
  return best;
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

// The fast path of the renderer: Newton on the upper arc from a starting point (the previous
// pixel's nearest point, or a guess), then an a-posteriori certificate that the point found is the
// global nearest point of the outline; false when it cannot certify (the caller then runs the
// full search). The certificates use that the ghost is convex (0 ≤ Cl, Cr ≤ 1):
//  - outside: the tangent at any outline point B is a supporting line of the ghost, so
//    dist(p, ghost) ≥ (p − B)·n (n the outward normal there), and dist ≤ |p − B|; both agree to
//    kDistanceTolerance at a converged foot of the normal, and then B is the nearest point (the
//    projection onto a convex set);
//  - inside: the disc of radius ρ = min_curvature_radius tangent from inside at B lies in the
//    ghost (Blaschke's rolling theorem), so the distance of p to the outline is at least
//    ρ − |p − c| with c the disc's centre, and at most |p − B|; again both must agree.
// The sign follows from the same bounds (p outside the supporting half-plane, or inside the
// disc), except within 1e-7 px of the outline, where the exact inside test decides. On success
// `c` holds the nearest point (segment 0 or 1, t, d²) and `inside` the sign; both agree with the
// full search (nearestUpperNewton + insideRelative) to Newton's precision (~1e-10 px). Deep inside
// (beyond the rolling disc) the converged point is returned as kUnproven: a tight upper bound
// that lets the full search dismiss most of the outline by its boxes.
enum class Certificate {
  kCertified,    // c is the nearest point, `inside` the sign
  kUnproven,     // Newton converged to c (a good upper bound), but it may not be the nearest point
  kNotConverged  // c is unchanged
};
//
// `dt_dx`, when given, receives dt*/dpx at the result (how fast the nearest point moves along the
// outline as p moves in x; implicit differentiation of f(t, p) = (B − p)·B′ = 0 gives B′x/f′):
// what the renderer extrapolates the next pixel's start with.
inline Certificate certifiedNearest(const PreparedShape& s, double px, double py, Candidate& c,
                                    bool& inside, double* dt_dx = nullptr) {
  int w = c.segment;
  double t = std::clamp(c.t, 0.0, 1.0);
  int clamped = 0;  // consecutive steps stopped at an end of the arc (P_L or P_R)
  bool converged = false;
  const Pair p = {px, py};
  const double speed2_floor = s.speed2_floor;
  double last_fp = 1;  // f′ of the last Newton step (within 1e-5 px of the result)
  for (int i = 0; i < 12; ++i) {
    const PowerCubic& seg = s.seg[w];
    const auto [f, fp, speed2] = seg.newtonTerms(t, p);
    // Not in the basin of a minimum, or B′ ≈ 0 (a corner of a Cl = 0 or Cr = 0 outline).
    if (!(fp > 0) || !(speed2 > speed2_floor)) return Certificate::kNotConverged;
    last_fp = fp;
    double next = t - f / fp;
    if (next < 0 || next > 1) {  // (one test on the common path, inside the segment)
      if (next < 0 && w == 1) {  // continue on segment 0 through the joint at P_T
        w = 0;
        t = 1;
        continue;
      }
      if (next > 1 && w == 0) {
        w = 1;
        t = 0;
        continue;
      }
      next = std::clamp(next, 0.0, 1.0);
      if (++clamped >= 2 && next == t) {
        converged = true;  // the minimum is at the end: the certificate decides
        break;
      }
    } else {
      clamped = 0;
    }
    const double moved = next - t;
    t = next;
    // As in refineNearest: a step below 1e-5 px leaves an error of the order of its square. The
    // foot enters the derivative images directly (the envelope theorem), and the fitter's results
    // follow them closely: a coarser stop (1e-3 px) saved about 6 % of the instructions per frame but
    // moved fitted PSNRs in the CLI tests by tenths of a dB.
    if (moved * moved * speed2 < 1e-10) {
      converged = true;
      break;
    }
  }
  if (!converged) return Certificate::kNotConverged;
  const PowerCubic& seg = s.seg[w];
  const Pair tt = {t, t};
  const Pair v = p - seg.point(tt), tangent = seg.tangent(tt), vv = v * v;
  const double vx = v[0], vy = v[1];
  const double d2 = vv[0] + vv[1];
  const double d = std::sqrt(d2);
  const double tx = tangent[0], ty = tangent[1];
  c = {w, t, d2};
  // At an end of the arc (P_L or P_R) the minimum stays there as p moves.
  if (dt_dx) *dt_dx = (t > 0 && t < 1) ? tx / last_fp : 0.0;
  if (d < 1e-7) {  // on the outline: any sign is within 1e-7 px, take the exact one
    inside = insideRelative(s, px, py);
    return Certificate::kCertified;
  }
  // Outward unit normal: the tangent turned by −90° (the outline runs clockwise as displayed, y
  // down).
  const double speed2 = tx * tx + ty * ty;
  if (!(speed2 > speed2_floor)) return Certificate::kUnproven;
  const double inv_speed = 1 / std::sqrt(speed2);
  const double nx = ty * inv_speed, ny = -tx * inv_speed;
  const double vn = vx * nx + vy * ny;
  if (vn > 0) {
    inside = false;
    return d - vn <= kDistanceTolerance ? Certificate::kCertified : Certificate::kUnproven;
  }
  const double rho = s.min_curvature_radius;
  if (!(rho > d)) return Certificate::kUnproven;
  const double cx = vx + rho * nx, cy = vy + rho * ny;  // p − (B − ρ n)
  const double lower = rho - std::sqrt(cx * cx + cy * cy);
  inside = true;
  return d - lower <= kDistanceTolerance ? Certificate::kCertified : Certificate::kUnproven;
}

// A lower bound of the depth of the reflected relative point (px, py ≤ 0) below the outline
// (positive inside; ≤ 0 means no bound). The polygon of the samples and their mirror images lies
// inside the ghost (the outline is convex, 0 ≤ Cl, Cr ≤ 1), so p's distance to the outline is at
// least its distance to the polygon's boundary, the smallest c − n·p over its edges; in the upper
// half the mirrored edges are never nearer than the edges they mirror (their normals point up,
// ny ≤ 0, so c − n·p' ≥ c − n·p for p' = (px, −py)). Accurate to rounding (~1e-13 px); the
// polygon's chords lie within their sagitta (< 0.4 % of the radius of curvature at ≤ 10° of turn
// per piece) of the outline.
inline double depthLowerBound(const PreparedShape& s, double px, double py) {
  double depth = 1e308;
  for (int w = 0; w < 2; ++w) {
    const int n = s.samples[w] - 1;
    const double* nx = s.edge_nx[w].data();
    const double* ny = s.edge_ny[w].data();
    const double* c = s.edge_c[w].data();
    for (int k = 0; k < n; ++k) depth = std::min(depth, c[k] - (nx[k] * px + ny[k] * py));
  }
  return depth;
}

// A starting point for certifiedNearest without a previous pixel: the outline point at the same
// angle about M on the ellipse through P_L/P_R and P_T (t is nearly proportional to that angle
// on every segment of this family).
inline Candidate angleGuess(const PreparedShape& s, double px, double py) {
  const double ax = px <= 0 ? px / s.left : px / s.right;
  const double ay = py / s.height;  // ≤ 0 in the upper half
  const double angle = std::atan2(-ay, std::abs(ax));  // 0 on the axis, π/2 at P_T
  const double t = std::clamp(angle * (2 / 3.14159265358979323846), 0.0, 1.0);
  return px <= 0 ? Candidate{0, t, 1e308} : Candidate{1, 1 - t, 1e308};
}

// The full search on the reflected relative point; returns the upper segment (0 or 1), t and d².
// `cutoff` as in nearestOnSegmentNewton (kSampledNewton only).
inline void nearestUpper(const PreparedShape& s, double px, double py,
                         const SignedDistanceOptions& o, int& segment, double& t, double& d2,
                         double cutoff = 1e308) {
  if (o.method == NearestPointMethod::kSampledNewton) {
    const Candidate c = nearestUpperNewton(s, px, py, o.newton_steps, cutoff);
    segment = c.segment;
    t = c.t;
    d2 = c.d2;
    return;
  }
  double t0 = 0, d20 = 0, t1 = 0, d21 = 0;
  nearestOnSegmentBisection(s, 0, px, py, o.bisection_steps, t0, d20);
  nearestOnSegmentBisection(s, 1, px, py, o.bisection_steps, t1, d21);
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
