#include "model/signed_distance.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <sstream>

#include "model/detail/outline_search.h"
#include "model/render_benchmark.h"

namespace flarekit::model {
namespace {

// The dense reference of the issue: ≥ 10 000 samples on each of the four segments (no symmetry
// used), then Newton on the best sample of each segment, and the sign from a point-in-polygon test
// on the dense polyline (an independent inside test).
// The unit normal (tangent.y, −tangent.x)/|tangent| of `segment` at t; zero where the tangent
// vanishes. Test points are placed along it at a chosen signed offset from the outline.
cv::Point2d unitNormal(const CubicBezier& segment, double t) {
  const cv::Point2d tangent = segment.derivative(t);
  const double len = std::hypot(tangent.x, tangent.y);
  return len > 0 ? cv::Point2d(tangent.y, -tangent.x) / len : cv::Point2d(0, 0);
}

class DenseReference {
 public:
  explicit DenseReference(const GhostParameters& g) : outline_(ghostOutline(g)) {
    for (int s = 0; s < 4; ++s)
      for (int i = 0; i < kSamples; ++i) {
        const cv::Point2d p = outline_[s].at(static_cast<double>(i) / (kSamples - 1));
        points_[s].push_back(p);
        if (i + 1 < kSamples) polygon_.push_back(p);
      }
  }

  double unsignedDistance(cv::Point2d p) const {
    double best = 1e300;
    for (int s = 0; s < 4; ++s) {
      int k = 0;
      double d2 = 1e300;
      for (int i = 0; i < kSamples; ++i) {
        const cv::Point2d v = points_[s][i] - p;
        const double e = v.dot(v);
        if (e < d2) {
          d2 = e;
          k = i;
        }
      }
      double t = static_cast<double>(k) / (kSamples - 1);
      const double lo = std::max(0.0, t - 1.0 / (kSamples - 1)), hi = std::min(1.0, t + 1.0 / (kSamples - 1));
      for (int it = 0; it < 30; ++it) {
        const cv::Point2d b = outline_[s].at(t) - p, d1 = outline_[s].derivative(t),
                          dd = outline_[s].secondDerivative(t);
        const double f = b.dot(d1), fp = d1.dot(d1) + b.dot(dd);
        if (!(fp > 0)) break;
        t = std::clamp(t - f / fp, lo, hi);
      }
      const cv::Point2d v = outline_[s].at(t) - p;
      best = std::min({best, std::sqrt(d2), std::sqrt(v.dot(v))});
    }
    return best;
  }

  // +1 outside, −1 inside, by the crossing-number test (in double) on the dense polygon.
  double sign(cv::Point2d p) const {
    bool inside = false;
    const size_t n = polygon_.size();
    for (size_t i = 0, j = n - 1; i < n; j = i++) {
      const cv::Point2d a = polygon_[i], b = polygon_[j];
      if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x)
        inside = !inside;
    }
    return inside ? -1 : 1;
  }

 private:
  static constexpr int kSamples = 10001;
  std::array<CubicBezier, 4> outline_;
  std::array<std::vector<cv::Point2d>, 4> points_;
  std::vector<cv::Point2d> polygon_;
};

double logUniform(std::mt19937& rng, double lo, double hi) {
  return std::exp(std::uniform_real_distribution<double>(std::log(lo), std::log(hi))(rng));
}

// A random valid shape over the whole allowed range: sizes and fall-offs log-uniform over their
// bounds, curvatures uniform with the bounds themselves drawn often.
GhostParameters randomShape(std::mt19937& rng) {
  GhostParameters g;
  const ParameterBounds size = parameterBounds(param::kL, 1);
  const ParameterBounds fi = parameterBounds(ParameterLayout{1}.fi(), 1);
  std::uniform_real_distribution<double> unit(0, 1);
  auto curvature = [&] {
    const double u = unit(rng);
    return u < 0.1 ? 0.0 : u > 0.9 ? 1.0 : unit(rng);
  };
  g.center_x = std::uniform_real_distribution<double>(-2000, 2000)(rng);
  g.center_y = std::uniform_real_distribution<double>(-2000, 2000)(rng);
  g.left = logUniform(rng, size.lower, size.upper);
  g.right = logUniform(rng, size.lower, size.upper);
  g.height = logUniform(rng, size.lower, size.upper);
  g.curvature_left = curvature();
  g.curvature_right = curvature();
  g.inside_falloff = logUniform(rng, fi.lower, fi.upper);
  g.outside_falloff = logUniform(rng, fi.lower, fi.upper);
  EXPECT_TRUE(isValid(g));
  return g;
}

TEST(SignedDistance, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(SignedDistanceOptions{}.IsValid(&error)) << error;
  SignedDistanceOptions bad;
  bad.samples_per_segment = 2;
  EXPECT_FALSE(bad.IsValid(&error));
}

TEST(SignedDistance, CircleDistanceIsRadial) {
  GhostParameters g;
  g.center_x = 50;
  g.center_y = 40;
  g.left = g.right = g.height = 20;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> angle(0, 2 * M_PI), radius(0, 40);
  for (int i = 0; i < 1000; ++i) {
    const double a = angle(rng), r = radius(rng);
    const cv::Point2d p(50 + r * std::cos(a), 40 + r * std::sin(a));
    // The Bézier circle deviates from the true one by < 0.03 % of the radius.
    EXPECT_NEAR(signedDistance(g, p), r - 20, 20 * 3e-4 + 1e-9);
  }
}

TEST(SignedDistance, MatchesDenseReferenceOverTheWholeParameterRange) {
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> unit(0, 1);
  const SignedDistanceOptions options;
  SignedDistanceOptions paper;
  paper.method = NearestPointMethod::kBisection12;
  double worst = 0, paper_worst = 0;
  int points = 0, sign_checks = 0;
  for (int shape = 0; shape < 200; ++shape) {
    const GhostParameters g = randomShape(rng);
    const DenseReference ref(g);
    const auto outline = ghostOutline(g);
    const cv::Rect2d box = outlineBounds(g);
    int kept = 0;
    for (int attempt = 0; attempt < 2000 && kept < 60; ++attempt) {
      cv::Point2d p;
      if (attempt % 2 == 0) {
        // Near the outline: a random outline point moved along its normal within the band.
        const int s = static_cast<int>(unit(rng) * 4) % 4;
        const double t = unit(rng);
        const cv::Point2d normal = unitNormal(outline[s], t);
        const double offset = -g.inside_falloff + unit(rng) * (g.inside_falloff + g.outside_falloff);
        p = outline[s].at(t) + offset * normal;
      } else {
        // Anywhere in the box the renderer touches.
        const double fo = g.outside_falloff;
        p = cv::Point2d(box.x - fo + unit(rng) * (box.width + 2 * fo),
                        box.y - fo + unit(rng) * (box.height + 2 * fo));
      }
      const double reference = ref.unsignedDistance(p);
      const double reference_sign = ref.sign(p);
      const NearestPoint n = nearestPoint(g, p, options);
      // The sign everywhere (except within rounding of the outline, where the polygon and the
      // curve may disagree).
      if (reference > 1e-6 * (1 + std::max(box.width, box.height) * 1e-3)) {
        ++sign_checks;
        ASSERT_EQ(n.distance < 0 ? -1 : 1, reference_sign)
            << "shape " << shape << " M " << g.center_x << "," << g.center_y << " p " << p << " d " << n.distance << " L " << g.left << " R "
            << g.right << " h " << g.height << " Cl " << g.curvature_left << " Cr " << g.curvature_right;
      }
      const double signed_reference = reference_sign * reference;
      if (signed_reference < -g.inside_falloff || signed_reference > g.outside_falloff) continue;
      ++kept;
      ++points;
      const double error = std::abs(std::abs(n.distance) - reference);
      worst = std::max(worst, error);
      paper_worst = std::max(paper_worst, std::abs(std::abs(signedDistance(g, p, paper)) - reference));
      ASSERT_LE(error, 0.01) << "shape " << shape << " M " << g.center_x << "," << g.center_y << " p " << p << " d " << n.distance << " ref "
                             << reference << " L " << g.left << " R " << g.right << " h "
                             << g.height << " Cl " << g.curvature_left << " Cr " << g.curvature_right;
      // The returned nearest point is on the outline at the returned t and at |d|.
      const cv::Point2d b = outline[n.segment].at(n.t);
      EXPECT_NEAR(b.x, n.point.x, 1e-6 * (1 + std::abs(b.x)));
      EXPECT_NEAR(b.y, n.point.y, 1e-6 * (1 + std::abs(b.y)));
      EXPECT_NEAR(std::hypot(p.x - b.x, p.y - b.y), std::abs(n.distance), 1e-6 * (1 + reference));
    }
  }
  EXPECT_GT(points, 3000);
  EXPECT_GT(sign_checks, 3000);
  // For the record (the XML report): ours, and the paper's 12-step bisection on the same points.
  std::ostringstream figures;
  figures << std::scientific << worst << " (paper 12-step bisection: " << paper_worst << ")";
  RecordProperty("worst_error_px", figures.str());
}

TEST(SignedDistance, RendererFastPathMatchesDenseReferenceWheneverItCertifies) {
  // The renderer's fast path (detail::certifiedNearest: Newton from a start, then a supporting-line
  // or rolling-disc certificate) must meet the same 0.01 px bound with the sign right, on the same
  // kind of shapes and points as MatchesDenseReferenceOverTheWholeParameterRange, from good starts
  // (the angle guess, the exact answer of a neighbour) and from arbitrary ones. It may decline
  // (the renderer then runs the full search), but not too often, or it would be no fast path.
  std::mt19937 rng(20261122);
  std::uniform_real_distribution<double> unit(0, 1);
  const SignedDistanceOptions options;
  double worst = 0;
  int band_points = 0, certified_from_guess = 0, certified = 0;
  for (int shape = 0; shape < 200; ++shape) {
    const GhostParameters g = randomShape(rng);
    const DenseReference ref(g);
    const detail::PreparedShape prepared(g, options.samples_per_segment, options.max_sample_turn_deg);
    const auto outline = ghostOutline(g);
    const cv::Rect2d box = outlineBounds(g);
    int kept = 0;
    for (int attempt = 0; attempt < 2000 && kept < 60; ++attempt) {
      cv::Point2d p;
      if (attempt % 2 == 0) {
        const int s = static_cast<int>(unit(rng) * 4) % 4;
        const double t = unit(rng);
        const cv::Point2d normal = unitNormal(outline[s], t);
        // A third of them within 0.01 px of the outline, where the transfer function is steepest
        // (exponents below 1) and an inexact foot shows most in the distance.
        const double offset = attempt % 3 == 0 ? 0.02 * (unit(rng) - 0.5)
                                                : -g.inside_falloff + unit(rng) * (g.inside_falloff + g.outside_falloff);
        p = outline[s].at(t) + offset * normal;
      } else {
        const double fo = g.outside_falloff;
        p = cv::Point2d(box.x - fo + unit(rng) * (box.width + 2 * fo),
                        box.y - fo + unit(rng) * (box.height + 2 * fo));
      }
      const double reference = ref.unsignedDistance(p);
      const double reference_sign = ref.sign(p);
      const double signed_reference = reference_sign * reference;
      // The full search (nearestPoint, ~1e-10 px): the renderer's fast path must agree with it to
      // that order, not just to the 0.01 px of the dense reference, or its images would differ
      // from the per-pixel reference where the transfer function is steep.
      const double full = std::abs(nearestPoint(g, p, options).distance);
      const bool in_band = signed_reference >= -g.inside_falloff && signed_reference <= g.outside_falloff;
      if (in_band) {
        ++kept;
        ++band_points;
      }
      // The reflected point relative to M, as the renderer passes it.
      const double rx = p.x - g.center_x, ry = -std::abs(p.y - g.center_y);
      // The exact answer of a pixel next to p (a row neighbour's hint).
      const NearestPoint neighbour = nearestPoint(g, p + cv::Point2d(1, 0), options);
      const int neighbour_segment = neighbour.segment >= 2 ? 3 - neighbour.segment : neighbour.segment;
      const double neighbour_t = neighbour.segment >= 2 ? 1 - neighbour.t : neighbour.t;
      const detail::Candidate starts[3] = {detail::angleGuess(prepared, rx, ry),
                                           {neighbour_segment, neighbour_t, 0},
                                           {unit(rng) < 0.5 ? 0 : 1, unit(rng), 0}};
      for (int k = 0; k < 3; ++k) {
        detail::Candidate c = starts[k];
        bool inside = false;
        if (detail::certifiedNearest(prepared, rx, ry, c, inside) != detail::Certificate::kCertified)
          continue;
        ++certified;
        if (k == 0 && in_band) ++certified_from_guess;
        const double distance = std::sqrt(c.d2);
        if (reference > 1e-6 * (1 + std::max(box.width, box.height) * 1e-3)) {
          ASSERT_EQ(inside ? -1 : 1, reference_sign)
              << "shape " << shape << " start " << k << " p " << p << " d " << distance << " L " << g.left
              << " R " << g.right << " h " << g.height << " Cl " << g.curvature_left << " Cr "
              << g.curvature_right;
        }
        // Certified anywhere means exact anywhere (the certificate has no cutoff).
        const double error = std::abs(distance - reference);
        if (in_band) worst = std::max(worst, error);
        ASSERT_LE(error, 0.01) << "shape " << shape << " start " << k << " p " << p << " d " << distance
                               << " ref " << reference << " L " << g.left << " R " << g.right << " h "
                               << g.height << " Cl " << g.curvature_left << " Cr " << g.curvature_right;
        EXPECT_NEAR(distance, full, 1e-9 * (1 + full))
            << "shape " << shape << " start " << k << " p " << p << " L " << g.left << " R " << g.right
            << " h " << g.height << " Cl " << g.curvature_left << " Cr " << g.curvature_right;
        // The returned point is on the outline at the returned t.
        const detail::PowerCubic& seg = prepared.seg[c.segment];
        EXPECT_NEAR(std::hypot(rx - seg.x(c.t), ry - seg.y(c.t)), distance, 1e-9 * (1 + distance));
      }
    }
  }
  EXPECT_GT(band_points, 3000);
  // Shapes over the whole range include corners (Cl or Cr = 0) and very thin ones, where the fast
  // path declines deep inside; most band points still certify from the angle guess alone.
  EXPECT_GT(certified_from_guess, band_points * 2 / 5);
  std::ostringstream figures;
  figures << std::scientific << worst << " (" << certified << " certified results, "
          << certified_from_guess << " of " << band_points << " band points from the angle guess)";
  RecordProperty("fast_path_worst_error_px", figures.str());
}

TEST(SignedDistance, InsideTestIsExactOnTheAxesAndCorners) {
  GhostParameters g;
  g.center_x = 0;
  g.center_y = 0;
  g.left = 10;
  g.right = 4;
  g.height = 6;
  g.curvature_left = 0;  // a diamond on the left: corners at P_L and P_T
  g.curvature_right = 1;
  EXPECT_TRUE(isInside(g, {0, 0}));
  EXPECT_TRUE(isInside(g, {-9.999, 0}));
  EXPECT_FALSE(isInside(g, {-10.001, 0}));
  EXPECT_TRUE(isInside(g, {0, 5.999}));
  EXPECT_FALSE(isInside(g, {0, 6.001}));
  EXPECT_TRUE(isInside(g, {0, -5.999}));
  EXPECT_FALSE(isInside(g, {-5, 3.01}));   // beyond the diamond's straight edge y = 3 at x = −5
  EXPECT_TRUE(isInside(g, {-5, 2.99}));
  EXPECT_FALSE(isInside(g, {4.001, 0}));
  EXPECT_FALSE(isInside(g, {100, 100}));
  // The distance to a straight left edge is the distance to the line through P_L and P_T.
  const cv::Point2d p(-8, -4);
  // Line through (−10, 0) and (0, −6): 6x + 10y + 60 = 0.
  EXPECT_NEAR(std::abs(signedDistance(g, p)), std::abs(6 * p.x + 10 * p.y + 60) / std::hypot(6.0, 10.0), 1e-9);
  EXPECT_GT(signedDistance(g, p), 0);
}

TEST(SignedDistance, GradientMatchesCentralDifferences) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  int checked = 0;
  for (int trial = 0; trial < 60; ++trial) {
    GhostParameters g;
    g.center_x = 100 * unit(rng);
    g.center_y = 100 * unit(rng);
    g.left = 5 + 40 * unit(rng);
    g.right = 5 + 40 * unit(rng);
    g.height = 5 + 40 * unit(rng);
    g.curvature_left = 0.1 + 0.85 * unit(rng);
    g.curvature_right = 0.1 + 0.85 * unit(rng);
    const auto outline = ghostOutline(g);
    for (int i = 0; i < 20; ++i) {
      // Near the outline on either side, away from the medial axis.
      const int s = i % 4;
      const double t = 0.05 + 0.9 * unit(rng);
      const cv::Point2d normal = unitNormal(outline[s], t);
      const double offset = (unit(rng) - 0.3) * 4;
      if (std::abs(offset) < 0.05) continue;
      const cv::Point2d p = outline[s].at(t) + offset * normal;
      const NearestPoint n = nearestPoint(g, p);
      const auto grad = signedDistanceGradient(g, p, n);
      for (int q = 0; q < param::kShapeCount; ++q) {
        std::vector<double> v = toParameterVector(g);
        const double h = 1e-6 * std::max(1.0, std::abs(v[q]));
        v[q] += h;
        const double plus = signedDistance(fromParameterVector(v, 1), p);
        v[q] -= 2 * h;
        const double minus = signedDistance(fromParameterVector(v, 1), p);
        const double fd = (plus - minus) / (2 * h);
        EXPECT_NEAR(grad[q], fd, 1e-5 * std::max(1.0, std::abs(fd)))
            << parameterName(q, 1) << " trial " << trial << " p " << p;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 5000);
}

TEST(SignedDistance, PaperBisectionIsAvailableForComparison) {
  GhostParameters g;
  g.left = g.right = g.height = 30;
  SignedDistanceOptions paper;
  paper.method = NearestPointMethod::kBisection12;
  // On a circle the bisection reading is close to the Newton result (within 1/2¹² of a quarter).
  for (double a = 0; a < 6.28; a += 0.1) {
    const cv::Point2d p(40 * std::cos(a), 40 * std::sin(a));
    EXPECT_NEAR(signedDistance(g, p, paper), signedDistance(g, p), 0.05);
  }
}


TEST(SignedDistance, ConvexityBoundNeverExceedsTheSecondDerivative) {
  // detail::convexityLowerBound lets the full search stop splitting a piece where the squared
  // distance g is convex: it must never exceed g″(t) = |B′|² + (B − p)·B″ anywhere on the piece
  // (else a piece holding a second minimum could be skipped), for pieces of shapes over the whole
  // parameter range and points near and far; and it must certify the pieces around the nearest
  // point of a point far outside, which is what it is for.
  std::mt19937 rng(977);
  std::uniform_real_distribution<double> unit(0, 1);
  const SignedDistanceOptions options;
  int certified = 0, far_nearest = 0, far_nearest_certified = 0;
  for (int shape = 0; shape < 200; ++shape) {
    const GhostParameters g = randomShape(rng);
    const detail::PreparedShape s(g, options.samples_per_segment, options.max_sample_turn_deg);
    const double size = g.left + g.right + g.height;
    for (int i = 0; i < 100; ++i) {
      const int w = static_cast<int>(unit(rng) * 2) % 2;
      const int k = static_cast<int>(unit(rng) * (s.samples[w] - 1)) % (s.samples[w] - 1);
      const double a = s.sample_t[w][k], b = s.sample_t[w][k + 1];
      // Around the outline out to three times the ghost's size, in the upper half (relative to M).
      const double r = size * logUniform(rng, 1e-3, 3), angle = unit(rng) * 3.14159265358979323846;
      const double px = r * std::cos(angle), py = -r * std::sin(angle);
      const detail::PowerCubic& c = s.seg[w];
      const double bound = detail::convexityLowerBound(c, px, py, a, b, s.box_x0[w][k], s.box_x1[w][k],
                                                       s.box_y0[w][k], s.box_y1[w][k]);
      double least = 1e308;
      for (int j = 0; j <= 400; ++j) {
        const double t = a + (b - a) * j / 400;
        const double bx = c.x(t) - px, by = c.y(t) - py;
        least = std::min(least, c.dx(t) * c.dx(t) + c.dy(t) * c.dy(t) + bx * c.ddx(t) + by * c.ddy(t));
      }
      // A positive bound claims g is convex over the piece, at least that much; 0 claims nothing.
      if (bound > 0) {
        ++certified;
        ASSERT_LE(bound, least + 1e-9 * (std::abs(least) + size * size))
            << "shape " << shape << " piece " << w << "/" << k << " p " << px << "," << py;
      }
      // The piece holding the nearest point of a point farther out than the ghost's size.
      if (r > size) {
        const detail::Candidate n = detail::nearestUpperNewton(s, px, py, options.newton_steps, 1e308);
        if (n.segment == w && n.t > a && n.t < b) {
          ++far_nearest;
          if (bound > 0) ++far_nearest_certified;
        }
      }
    }
  }
  EXPECT_GT(certified, 1000);
  EXPECT_GT(far_nearest, 20);
  EXPECT_GE(far_nearest_certified, 0.9 * far_nearest);
  RecordProperty("far_nearest_pieces_certified",
                 std::to_string(far_nearest_certified) + " of " + std::to_string(far_nearest));
}

TEST(SignedDistance, SamplePolygonDepthNeverExceedsTheTrueDepth) {
  // detail::depthLowerBound (the renderer proves blocks deeper than Fi with it where the rolling
  // disc is too small) must never exceed the depth of a point below the outline, on shapes over
  // the whole parameter range (corners, boxes, thin shapes), and must be close to it (the
  // polygon's chords turn by at most 10°, so it loses under 0.4 % of the radius of curvature).
  std::mt19937 rng(404);
  std::uniform_real_distribution<double> unit(0, 1);
  const SignedDistanceOptions options;
  int inside_points = 0;
  double worst_slack = 0;
  for (int shape = 0; shape < 200; ++shape) {
    const GhostParameters g = randomShape(rng);
    const DenseReference ref(g);
    const detail::PreparedShape prepared(g, options.samples_per_segment, options.max_sample_turn_deg);
    const cv::Rect2d box = outlineBounds(g);
    for (int i = 0; i < 200; ++i) {
      const cv::Point2d p(box.x + unit(rng) * box.width, box.y + unit(rng) * box.height);
      const double depth = -ref.sign(p) * ref.unsignedDistance(p);  // > 0 inside
      const double bound = detail::depthLowerBound(prepared, p.x - g.center_x, -std::abs(p.y - g.center_y));
      // A positive bound claims p is inside at least that deep; ≤ 0 claims nothing.
      if (bound > 0) {
        ++inside_points;
        ASSERT_LE(bound, depth + 1e-9 * (1 + box.width + box.height))
            << "shape " << shape << " p " << p << " L " << g.left << " R " << g.right << " h "
            << g.height << " Cl " << g.curvature_left << " Cr " << g.curvature_right;
      }
    }
  }
  EXPECT_GT(inside_points, 5000);
  // Tight on the benchmark's ghosts (radius 20–80 px, Cl, Cr in [0.35, 0.75]): within 1 % of the
  // ghost's size of the true depth at every point more than 1 px inside.
  const std::vector<GhostParameters> ghosts = benchmarkGhosts({});
  for (const GhostParameters& g : ghosts) {
    const detail::PreparedShape prepared(g, options.samples_per_segment, options.max_sample_turn_deg);
    const cv::Rect2d box = outlineBounds(g);
    for (int i = 0; i < 100; ++i) {
      const cv::Point2d p(box.x + unit(rng) * box.width, box.y + unit(rng) * box.height);
      const double depth = -signedDistance(g, p, options);
      if (depth < 1) continue;
      const double bound = detail::depthLowerBound(prepared, p.x - g.center_x, -std::abs(p.y - g.center_y));
      worst_slack = std::max(worst_slack, (depth - bound) / std::max({g.left, g.right, g.height}));
    }
  }
  EXPECT_LT(worst_slack, 0.01);
  RecordProperty("worst_slack_of_size", std::to_string(worst_slack));
  // A circle's centre is its radius deep.
  GhostParameters circle;
  circle.left = circle.right = circle.height = 40;
  circle.curvature_left = circle.curvature_right = 0.5523;
  const detail::PreparedShape prepared(circle, options.samples_per_segment, options.max_sample_turn_deg);
  EXPECT_GT(detail::depthLowerBound(prepared, 0, 0), 0.995 * 40);
  EXPECT_LT(detail::depthLowerBound(prepared, 0, 0), 40 * 1.0003);
}

}  // namespace
}  // namespace flarekit::model
