#include "fit/ghost_candidates.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <numeric>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/image.h"
#include "common/robust_statistics.h"
#include "fit/polynomial.h"

namespace flarekit::fit {

namespace {

double median(std::vector<double> v) {
  return v.empty() ? std::numeric_limits<double>::quiet_NaN() : upperMedian(v);
}

double cleanAt(const SweepImage& s, int row, int x) {
  x = std::clamp(x, 0, s.width() - 1);
  return s.radiance.at<float>(row, x) - s.light.at<float>(row, x);
}

// The mean of S − light over [x0, x1] of a row (clipped to the frame), NaN when empty.
double meanOver(const SweepImage& s, int row, double x0, double x1) {
  const int a = std::max(0, static_cast<int>(std::floor(x0)));
  const int b = std::min(s.width() - 1, static_cast<int>(std::floor(x1)));
  double sum = 0;
  int n = 0;
  for (int x = a; x <= b; ++x)
    if (s.valid.at<uchar>(row, x) || s.radiance.at<float>(row, x) > 0) {
      sum += cleanAt(s, row, x);
      ++n;
    }
  return n ? sum / n : std::numeric_limits<double>::quiet_NaN();
}

// Where a lone border's ghost could end unseen, at the border's frame: the frame's edge or the
// light's zone on the ghost's side, whichever comes first.
double hiddenFrom(const SweepImage& s, int row, double x, BorderSide side) {
  const bool left = side == BorderSide::kLeft;
  if (std::isfinite(s.light_x_px[row])) {
    const double near = left ? s.light_x_px[row] - s.light_zone_left_px : s.light_x_px[row] + s.light_zone_right_px;
    if (left ? near > x : near < x) return near;
  }
  return left ? s.width() : 0.0;
}

// Whether no border can be traced at x in `row`: beyond the frame, in the light's zone, or where
// S has no edge response (the frame's margin, masked pixels).
bool untraceable(const SweepImage& s, int row, double x) {
  if (!(x >= 0 && x < s.width())) return true;
  return s.inLightZone(row, x) || !s.valid.at<uchar>(row, static_cast<int>(x));
}

// Whether S stays raised from the trace to where the ghost's other border could lie unseen
// (hiddenFrom), in most of the trace's frames: above the outside by more than its noise
// (noise_sigma σ, typically), and nowhere by less than `fraction` of the border's step, or of the
// stretch's typical rise where that is less: a bright rim just inside the border inflates the step.
bool raisedToHidden(const SweepImage& s, const BorderTrace& t, double fraction, double noise_sigma) {
  int raised = 0, tested = 0;
  for (const auto& p : t.points) {
    if (!(p.jump > 0)) continue;
    const bool left = t.side == BorderSide::kLeft;
    const double outside = left ? meanOver(s, p.row, p.x_px - 5, p.x_px - 2)
                                : meanOver(s, p.row, p.x_px + 2, p.x_px + 5);
    const double end = hiddenFrom(s, p.row, p.x_px, t.side);
    std::vector<double> inside;
    const int a = left ? static_cast<int>(p.x_px) + 3 : static_cast<int>(end);
    const int b = left ? static_cast<int>(end) - 1 : static_cast<int>(p.x_px) - 3;
    // Where the light's own profile outshines what lies under it, S − light measures the light's
    // profile more than the ghost: a ghost that stays beside the light is part of that profile.
    for (int x = std::max(a, 0); x <= std::min(b, s.width() - 1); ++x)
      if (s.valid.at<uchar>(p.row, x) && !(s.light.at<float>(p.row, x) > cleanAt(s, p.row, x)))
        inside.push_back(cleanAt(s, p.row, x) - outside);
    if (inside.size() < 4 || !std::isfinite(outside)) continue;
    ++tested;
    // A low quantile: the whole stretch, not a part of it, must be raised.
    std::sort(inside.begin(), inside.end());
    const double typical = inside[inside.size() / 2], low = inside[inside.size() / 5];
    const double sigma = s.noise.at<float>(p.row, std::clamp(static_cast<int>(p.x_px), 0, s.width() - 1));
    if (typical > noise_sigma * sigma && low >= fraction * std::min(p.jump, typical)) ++raised;
  }
  return tested > 0 && 2 * raised > tested;
}

// The vertical profile of frame `f` through column x (± half columns), the rows mirrored about
// the horizon averaged: profile[k] at distance k + ½ below... above the horizon's row, k ≥ 0.
std::vector<double> verticalProfile(const cv::Mat& lum, const cv::Mat& valid, double x,
                                    double horizon_y, int half) {
  const int c0 = std::max(0, static_cast<int>(std::floor(x)) - half);
  const int c1 = std::min(lum.cols - 1, static_cast<int>(std::floor(x)) + half);
  const int centre = static_cast<int>(std::floor(horizon_y));
  std::vector<double> profile;
  if (c0 > c1) return profile;
  for (int k = 0;; ++k) {
    const int down = centre + k, up = centre - 1 - k;
    if (down >= lum.rows && up < 0) break;
    double sum = 0;
    int n = 0;
    for (int row : {down, up}) {
      if (row < 0 || row >= lum.rows) continue;
      for (int c = c0; c <= c1; ++c)
        if (valid.at<uchar>(row, c)) {
          sum += lum.at<float>(row, c);
          ++n;
        }
    }
    profile.push_back(n ? sum / n : std::numeric_limits<double>::quiet_NaN());
  }
  return profile;
}

// The distance from the horizon, within [lo, hi], at which the profile falls outwards by a step
// closest to `step` (the ghost's border step on the horizon: one outline value Ib all round),
// within a factor max_ratio; NaN when no step there is that close.
double fallingEdge(const std::vector<double>& profile, double lo, double hi, double step, double max_ratio) {
  const int n = static_cast<int>(profile.size());
  auto at = [&](int k) { return std::isfinite(profile[k]) ? profile[k] : std::numeric_limits<double>::quiet_NaN(); };
  std::vector<double> falls(n, 0.0);
  for (int k = 2; k + 2 < n; ++k) {
    const double f = 0.5 * (at(k - 2) + at(k - 1)) - 0.5 * (at(k + 1) + at(k + 2));
    falls[k] = std::isfinite(f) ? f : 0.0;
  }
  double best = std::log(max_ratio), where = std::numeric_limits<double>::quiet_NaN();
  for (int k = std::max(2, static_cast<int>(lo)); k + 2 < n && k <= hi; ++k) {
    if (!(falls[k] > 0) || falls[k] < falls[k - 1] || falls[k] < falls[k + 1]) continue;
    if (const double mismatch = std::abs(std::log(falls[k] / step)); mismatch < best) {
      best = mismatch;
      where = k + 0.5;
    }
  }
  return where;
}

// Robust polynomial values of `v` over the rows (degree by length).
std::vector<double> smoothed(const std::vector<double>& angles, const std::vector<double>& v) {
  std::vector<double> a, y;
  for (size_t i = 0; i < v.size(); ++i)
    if (std::isfinite(v[i])) {
      a.push_back(angles[i]);
      y.push_back(v[i]);
    }
  std::vector<double> out(v.size(), std::numeric_limits<double>::quiet_NaN());
  if (a.empty()) return out;
  const int degree = std::clamp(static_cast<int>(a.size()) / 10, 0, 3);
  const model::Polynomial p = robustPolynomial(a, y, degree);
  for (size_t i = 0; i < v.size(); ++i) out[i] = p.evaluate(angles[i]);
  return out;
}

// A border's position at every row of [first, last]: its trace's polynomial, of degree 2 at most
// beyond the trace's own frames (it is extrapolated there), moved to run through the trace's end
// point on that side (where the border was last seen, not where a fit over all its points puts it).
std::vector<double> borderAt(const BorderTrace& t, const SweepImage& s, int first, int last) {
  std::vector<double> angles, xs;
  for (const auto& p : t.points) {
    angles.push_back(s.angles_deg[p.row]);
    xs.push_back(p.x_px);
  }
  const model::Polynomial outside = robustPolynomial(angles, xs, std::min<int>(2, angles.size() / 8));
  const double before = xs.front() - outside.evaluate(angles.front());
  const double after = xs.back() - outside.evaluate(angles.back());
  std::vector<double> out;
  for (int r = first; r <= last; ++r) {
    const double a = s.angles_deg[r];
    if (r >= t.firstRow() && r <= t.lastRow())
      out.push_back(t.x_of_angle.evaluate(a));
    else
      out.push_back(outside.evaluate(a) + (r < t.firstRow() ? before : after));
  }
  return out;
}

// Whether `t` keeps its distance to the light: over the rows where the light is found (at least
// half of the trace's), its offset from the light changes by less than `min_motion` of the
// light's own motion.
bool followsTheLight(const SweepImage& s, const BorderTrace& t, double min_motion) {
  std::vector<double> light, offset;
  for (const auto& p : t.points)
    if (std::isfinite(s.light_x_px[p.row])) {
      light.push_back(s.light_x_px[p.row]);
      offset.push_back(p.x_px - s.light_x_px[p.row]);
    }
  if (light.size() < 3 || 2 * light.size() < t.points.size()) return false;
  const auto [lo, hi] = std::minmax_element(light.begin(), light.end());
  if (*hi - *lo < 1) return false;
  const model::Polynomial line = leastSquaresPolynomial(light, offset, 1);
  return line.coefficients.size() > 1 && std::abs(line.coefficients[1]) < min_motion;
}

// The light's curve x(θ) as a cubic in tan θ (the light images at f·tan θ, with distortion),
// through the frames that show it; empty when fewer than four do.
std::optional<model::Polynomial> lightCurve(const SweepImage& s) {
  std::vector<double> t, x;
  for (int i = 0; i < s.rows(); ++i)
    if (std::isfinite(s.light_x_px[i])) {
      t.push_back(std::tan(s.angles_deg[i] * std::numbers::pi / 180));
      x.push_back(s.light_x_px[i]);
    }
  if (t.size() < 4) return std::nullopt;
  return robustPolynomial(t, x, 3);
}

// The optical zero the pairs agree on, as keepPairsThroughTheZero finds it: the light's curve and
// its x there (the axis); what fitBorderModel measures a ghost's borders from.
struct ZeroOfPairs {
  model::Polynomial light;  // the light's curve x(tan θ)
  double axis_x_px = 0;     // the light's x at the zero

  double lightAt(double angle_deg) const { return light.evaluate(std::tan(angle_deg * std::numbers::pi / 180)); }
};

// Keeps the pairs whose middle is, as a real ghost's, an odd function about the optical zero: the
// point of the sweep where the light lies on the axis and every ghost is centred on it. A pair
// fits the zero at (θz, light's x there = cx) when m − cx = k·u + k₃·u³ (u = the light's x − cx)
// runs within the tolerance of its middles; the zero is the θz that the most pairs (weighed by
// their shared frames) fit, and the pairs that do not are dropped: two unrelated borders, or a
// border and a rim's inner edge, are centred elsewhere. Pairs centred on the light itself (its
// starburst's fringes on either side) fit every zero, and are the light's image: dropped too.
// Returns the zero, or nullopt where the light's curve is unknown or no pair fits one.
template <class Pair>
std::optional<ZeroOfPairs> keepPairsThroughTheZero(const SweepImage& s, const CandidateOptions& o,
                                                   std::vector<Pair>& pairs) {
  const std::optional<model::Polynomial> light = lightCurve(s);
  if (!light || pairs.empty()) return std::nullopt;
  ZeroOfPairs zero{*light, 0};  // its axis is chosen below
  auto light_at = [&](double angle) { return zero.lightAt(angle); };
  std::vector<Pair> off_light;
  for (auto& p : pairs) {
    double farthest = 0;
    for (size_t i = 0; i < p.angles.size(); ++i) farthest = std::max(farthest, std::abs(p.centres[i] - light_at(p.angles[i])));
    if (farthest > std::max(o.max_centre_rms_px, 0.02 * p.width)) off_light.push_back(std::move(p));
  }
  pairs = std::move(off_light);
  auto rms = [&](const Pair& p, double cx) {
    Eigen::MatrixXd a(p.angles.size(), 2);
    Eigen::VectorXd b(p.angles.size());
    for (size_t i = 0; i < p.angles.size(); ++i) {
      const double u = light_at(p.angles[i]) - cx;
      a(i, 0) = u;
      a(i, 1) = u * u * u * 1e-4;
      b(i) = p.centres[i] - cx;
    }
    const Eigen::VectorXd k = a.colPivHouseholderQr().solve(b);
    return std::sqrt((a * k - b).squaredNorm() / p.angles.size());
  };
  auto fits = [&](const Pair& p, double cx) { return rms(p, cx) <= o.max_centre_rms_px + 0.01 * p.width; };
  // The zero lies where the light's curve is measured, or a little before its first frame.
  double lo = 1e9, hi = -1e9;
  for (int i = 0; i < s.rows(); ++i)
    if (std::isfinite(s.light_x_px[i])) {
      lo = std::min(lo, s.angles_deg[i] - 3);
      hi = std::max(hi, s.angles_deg[i]);
    }
  double best_zero = 0, best_support = -1;
  for (double zero = lo; zero <= hi; zero += 0.05) {
    double support = 0;
    for (const auto& p : pairs)
      if (fits(p, light_at(zero))) support += static_cast<double>(p.angles.size());
    if (support > best_support) {
      best_support = support;
      best_zero = zero;
    }
  }
  std::vector<Pair> kept;
  for (auto& p : pairs)
    if (fits(p, light_at(best_zero))) kept.push_back(std::move(p));
  pairs = std::move(kept);
  if (best_support <= 0) return std::nullopt;
  zero.axis_x_px = light_at(best_zero);
  return zero;
}

// A ghost's borders over the whole capture. A rotationally symmetric lens images a light at −u
// from the axis as the mirror image of one at +u, so a ghost's middle is an odd function of the
// light's offset u and its half-width an even one (and nearly constant: a ghost keeps its size).
// Fitted once to every point of its traces (x_L = m − w, x_R = m + w), this gives its borders
// where the sweep does not see them: beyond the frame, in the light's zone, or never (a ghost with
// one border seen, whose half-width is then its border's distance from the axis at u = 0).
struct BorderModel {
  double k1 = 0, k3 = 0, w0 = 0, w2 = 0;  // m − cx = k1·u + k3·u³·10⁻⁴, w = w0 + w2·u²·10⁻⁴

  double middle(double u, double cx) const { return cx + k1 * u + k3 * u * u * u * 1e-4; }
  double halfWidth(double u) const { return w0 + w2 * u * u * 1e-4; }
};

// The border model of a ghost from its traces (either may be null), or nullopt when its points do
// not run so (within the pairs' tolerance) or its half-width is not positive: then they bound no
// ghost centred on the axis. The half-width's change (w2) is fitted only with both borders seen.
std::optional<BorderModel> fitBorderModel(const SweepImage& s, const ZeroOfPairs& zero, const BorderTrace* l,
                                          const BorderTrace* r, const CandidateOptions& o) {
  const bool both = l && r;
  std::vector<std::array<double, 5>> rows;  // u, u³, ∓1, ∓u², x − cx
  for (const BorderTrace* t : {l, r}) {
    if (!t) continue;
    const double sign = t == l ? -1 : 1;
    for (const auto& p : t->points) {
      const double u = zero.lightAt(s.angles_deg[p.row]) - zero.axis_x_px;
      rows.push_back({u, u * u * u * 1e-4, sign, sign * u * u * 1e-4, p.x_px - zero.axis_x_px});
    }
  }
  const int unknowns = both ? 4 : 3;
  if (static_cast<int>(rows.size()) < unknowns + 2) return std::nullopt;
  Eigen::MatrixXd a(rows.size(), unknowns);
  Eigen::VectorXd b(rows.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    for (int j = 0; j < unknowns; ++j) a(i, j) = rows[i][j];
    b(i) = rows[i][4];
  }
  const Eigen::VectorXd k = a.colPivHouseholderQr().solve(b);
  BorderModel m{k(0), k(1), k(2), both ? k(3) : 0.0};
  const double rms = std::sqrt((a * k - b).squaredNorm() / rows.size());
  if (!(m.w0 > 1) || rms > o.max_centre_rms_px + 0.01 * m.w0) return std::nullopt;
  return m;
}

// The ghost centred on a peak trace, over the trace's frames and on while the peak is hidden
// (beyond the frame, in the light's zone): at each, its half-width and half-height where S − light
// (the frame's profile through the peak, vertically) falls halfway from the peak to the lowest
// level within peak_reach_px, its outline value that half level and its inside the peak's, falling off
// over the whole half-width inside and out; where hidden, as at the nearest frame that shows it.
GhostCandidate peakCandidate(const FrameStack& stack, const SweepImage& s, const std::vector<cv::Mat>& lums,
                             const BorderTrace& t, const CandidateOptions& o) {
  const int reach = o.peak_reach_px;
  GhostCandidate c;
  c.peak_trace = t.id;
  c.first_row = t.firstRow();
  c.last_row = t.lastRow();
  auto hidden = [&](int row) {
    return untraceable(s, row, borderAt(t, s, row, row)[0]);
  };
  for (int k = 0; k < o.max_hidden_rows && c.first_row > 0 && hidden(c.first_row - 1); ++k) --c.first_row;
  for (int k = 0; k < o.max_hidden_rows && c.last_row + 1 < s.rows() && hidden(c.last_row + 1); ++k) ++c.last_row;
  const int n = c.last_row - c.first_row + 1;
  c.left_seen.assign(n, false);
  c.right_seen.assign(n, false);
  std::vector<double> angles(s.angles_deg.begin() + c.first_row, s.angles_deg.begin() + c.last_row + 1);
  const std::vector<double> x = borderAt(t, s, c.first_row, c.last_row);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> half(n, nan), height(n, nan), peak(n, nan), floor(n, nan);
  for (int i = 0; i < n; ++i) {
    const int row = c.first_row + i;
    const BorderPoint* p = t.at(row);
    const double mx = p ? p->x_px : x[i];
    if (!(mx >= 0 && mx < s.width())) continue;
    const int x0 = static_cast<int>(mx);
    auto value = [&](int xi) { return cleanAt(s, row, xi); };
    double low = value(x0);
    for (int d = 1; d <= reach; ++d)
      for (int xi : {x0 - d, x0 + d})
        if (xi >= 0 && xi < s.width() && s.valid.at<uchar>(row, xi)) low = std::min(low, value(xi));
    const double top = value(x0), level = 0.5 * (top + low);
    std::vector<double> halfway;  // the distances to the half level on either side
    for (int dir : {-1, 1})
      for (int d = 1; d <= reach; ++d) {
        const int xi = x0 + dir * d;
        if (xi < 0 || xi >= s.width()) break;
        if (value(xi) <= level) {
          halfway.push_back(d);
          break;
        }
      }
    if (halfway.empty() || !(top > low)) continue;
    half[i] = median(halfway);
    peak[i] = top;
    floor[i] = low;
    const std::vector<double> profile =
        verticalProfile(lums[row], stack.frames[row].valid, mx, s.horizon_y_px, o.profile_half_columns);
    for (size_t k = 1; k < profile.size(); ++k)
      if (std::isfinite(profile[k]) && profile[k] - s.light.at<float>(row, x0) <= level) {
        height[i] = static_cast<double>(k);
        break;
      }
  }
  half = smoothed(angles, half);
  height = smoothed(angles, height);
  // Where hidden, the nearest measured frame's values.
  std::vector<int> measured;
  for (int i = 0; i < n; ++i)
    if (std::isfinite(peak[i])) measured.push_back(i);
  for (int i = 0; i < n && !measured.empty(); ++i) {
    const int j = std::clamp(i, measured.front(), measured.back());
    if (j == i) continue;
    half[i] = half[j];
    height[i] = height[j];
    peak[i] = peak[j];
    floor[i] = floor[j];
  }
  c.seeds.resize(n);
  std::vector<double> steps;
  for (int i = 0; i < n; ++i) {
    model::GhostParameters& p = c.seeds[i];
    const BorderPoint* q = t.at(c.first_row + i);
    const double a = std::isfinite(half[i]) ? std::max(half[i], 1.0) : 1.0;
    p.channels = stack.channels;
    p.center_x = q ? q->x_px : x[i];
    p.center_y = s.horizon_y_px;
    p.left = p.right = a;
    p.height = std::isfinite(height[i]) && height[i] > 0.5 ? height[i] : a;
    p.curvature_left = p.curvature_right = model::kEllipseCurvature;
    const double rise = std::isfinite(peak[i]) ? peak[i] - floor[i] : 0;
    for (int ch = 0; ch < stack.channels; ++ch) {
      p.border[ch] = 0.5 * rise;
      p.inside[ch] = rise;
    }
    if (rise > 0) steps.push_back(0.5 * rise);
    p.inside_falloff = a;
    p.inside_exponent = 1;
    p.outside_falloff = a;
    p.outside_exponent = 1;
    p = model::clampToBounds(p);
  }
  c.step = steps.empty() ? 0 : median(steps);
  return c;
}

// On while hidden goes by the traces alone; a ghost's range ends where the whole ghost has left
// the frame.
void trimToFrame(GhostCandidate& c, int width) {
  auto beyond = [&](const model::GhostParameters& p) {
    return p.center_x + p.right < 0 || p.center_x - p.left > width;
  };
  int first = 0, last = static_cast<int>(c.seeds.size()) - 1;
  while (first < last && beyond(c.seeds[first])) ++first;
  while (last > first && beyond(c.seeds[last])) --last;
  c.seeds = {c.seeds.begin() + first, c.seeds.begin() + last + 1};
  c.left_seen = {c.left_seen.begin() + first, c.left_seen.begin() + last + 1};
  c.right_seen = {c.right_seen.begin() + first, c.right_seen.begin() + last + 1};
  c.last_row = c.first_row + last;
  c.first_row += first;
}

}  // namespace

bool CandidateOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (min_shared_rows < 1) return fail("candidates: min_shared_rows must be ≥ 1");
  if (!(max_step_ratio > 1)) return fail("candidates: max_step_ratio must be > 1");
  if (!(max_width_change_per_deg > 0)) return fail("candidates: max_width_change_per_deg must be > 0");
  if (!(max_centre_rms_px > 0)) return fail("candidates: max_centre_rms_px must be > 0");
  if (!(min_motion_from_light >= 0)) return fail("candidates: min_motion_from_light must be ≥ 0");
  if (!(single_significance > 0)) return fail("candidates: single_significance must be > 0");
  if (!(single_raised_fraction > 0 && single_raised_fraction <= 1))
    return fail("candidates: single_raised_fraction must be in (0, 1]");
  if (max_hidden_rows < 0) return fail("candidates: max_hidden_rows must be ≥ 0");
  if (profile_half_columns < 0) return fail("candidates: profile_half_columns must be ≥ 0");
  if (!(min_height_fraction > 0 && min_height_fraction < 1))
    return fail("candidates: min_height_fraction must be in (0, 1)");
  if (!(seed_outside_falloff_px > 0)) return fail("candidates: seed_outside_falloff_px must be > 0");
  if (!(rim_px >= 0)) return fail("candidates: rim_px must be ≥ 0");
  if (peak_reach_px < 1) return fail("candidates: peak_reach_px must be ≥ 1");
  if (!(single_raised_sigma >= 0)) return fail("candidates: single_raised_sigma must be ≥ 0");
  return true;
}

std::vector<GhostCandidate> findGhostCandidates(const FrameStack& stack, const SweepImage& s,
                                                const std::vector<BorderTrace>& traces,
                                                const CandidateOptions& o,
                                                CandidateSummary* summary) {
  std::string error;
  if (!o.IsValid(&error)) throw std::invalid_argument(error);
  // Pairs by the agreement of their steps.
  struct Pair {
    double score;
    int left, right;
    std::vector<double> angles, centres;  // the shared frames' centres (x_L + x_R) / 2
    double width = 0;                     // mean half-width over them
  };
  std::vector<bool> light_edge(traces.size(), false);
  for (const auto& t : traces) light_edge[t.id] = followsTheLight(s, t, o.min_motion_from_light);
  std::vector<Pair> pairs;
  for (const auto& l : traces) {
    if (l.side != BorderSide::kLeft || light_edge[l.id]) continue;
    for (const auto& r : traces) {
      if (r.side != BorderSide::kRight || light_edge[r.id]) continue;
      if (r.lastRow() < l.firstRow() || l.lastRow() < r.firstRow()) continue;
      std::vector<double> ratios, angles, widths;
      bool crossed = false;
      for (const auto& p : l.points) {
        const BorderPoint* q = r.at(p.row);
        if (!q) continue;
        if (q->x_px <= p.x_px + 1) crossed = true;
        else if (p.jump > 0 && q->jump > 0) {
          ratios.push_back(std::abs(std::log(p.jump / q->jump)));
          angles.push_back(s.angles_deg[p.row]);
          widths.push_back(0.5 * (q->x_px - p.x_px));
        }
      }
      if (crossed || static_cast<int>(ratios.size()) < o.min_shared_rows) continue;
      const double steps = median(ratios);
      if (steps > std::log(o.max_step_ratio)) continue;
      // A ghost keeps its size as it moves (its two borders move alike; paraxially exactly): the
      // relative change of the half-width per degree counts against a pair.
      const model::Polynomial w = leastSquaresPolynomial(angles, widths, 1);
      const double mean_width = std::accumulate(widths.begin(), widths.end(), 0.0) / widths.size();
      const double growth = w.coefficients.size() > 1 ? std::abs(w.coefficients[1]) / mean_width : 0.0;
      if (growth > o.max_width_change_per_deg) continue;
      Pair pair{steps + growth, l.id, r.id, angles, {}, mean_width};
      for (const auto& p : l.points)
        if (const BorderPoint* q = r.at(p.row); q && q->x_px > p.x_px + 1 && p.jump > 0 && q->jump > 0)
          pair.centres.push_back(0.5 * (p.x_px + q->x_px));
      pairs.push_back(std::move(pair));
    }
  }
  const std::optional<ZeroOfPairs> zero = keepPairsThroughTheZero(s, o, pairs);
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.score < b.score; });
  std::vector<bool> used(traces.size(), false);
  struct Borders {
    int left = -1, right = -1, peak = -1;
  };
  std::vector<Borders> ghosts;
  for (const auto& p : pairs) {
    if (used[p.left] || used[p.right]) continue;
    used[p.left] = used[p.right] = true;
    ghosts.push_back({p.left, p.right});
  }
  // Peaks. One running along a border (most of its points within rim_px) is the ghost's bright
  // rim. One at a pair's middle (in most of the frames that show all three) is the same ghost as
  // the pair, and the one seen in more frames describes it: the pair (its borders seen together),
  // or the peak, whose flanks the pair then was (a ghost whose light gathers to a point has no
  // border of its own, and its flanks are traced only here and there).
  std::vector<int> peaks;
  for (const auto& t : traces) {
    if (t.side != BorderSide::kPeak) continue;
    bool part = light_edge[t.id] || t.significance < o.single_significance;
    for (const auto& b : traces) {
      if (part) break;
      if (b.side == BorderSide::kPeak) continue;
      int beside = 0;
      for (const auto& p : t.points)
        if (const BorderPoint* q = b.at(p.row); q && std::abs(q->x_px - p.x_px) <= o.rim_px) ++beside;
      part = 2 * beside > static_cast<int>(t.points.size());
    }
    for (auto& g : ghosts) {
      if (part || g.left < 0) continue;
      const BorderTrace& l = traces[g.left];
      const BorderTrace& r = traces[g.right];
      int both = 0, all = 0, middle = 0;
      for (const auto& p : l.points) {
        const BorderPoint* q = r.at(p.row);
        if (!q) continue;
        ++both;
        if (const BorderPoint* m = t.at(p.row)) {
          ++all;
          middle += std::abs(m->x_px - 0.5 * (p.x_px + q->x_px)) < 0.25 * (q->x_px - p.x_px);
        }
      }
      if (all == 0 || 2 * middle <= all) continue;
      if (static_cast<int>(t.points.size()) > both)
        g = {-1, -1, -1};  // the pair was the peak's flanks
      else
        part = true;
    }
    if (!part) peaks.push_back(t.id);
  }
  std::erase_if(ghosts, [](const Borders& g) { return g.left < 0; });
  CandidateSummary sum;
  sum.pairs = static_cast<int>(ghosts.size());
  for (int p : peaks) ghosts.push_back({-1, -1, p});
  sum.peaks = static_cast<int>(peaks.size());
  for (const auto& t : traces) {
    if (t.side == BorderSide::kPeak) {
      if (std::find(peaks.begin(), peaks.end(), t.id) == peaks.end()) ++sum.traces_unused;
      continue;
    }
    if (used[t.id]) continue;
    if (!light_edge[t.id] && t.significance >= o.single_significance && raisedToHidden(s, t, o.single_raised_fraction, o.single_raised_sigma)) {
      ghosts.push_back(t.side == BorderSide::kLeft ? Borders{t.id, -1} : Borders{-1, t.id});
      ++sum.single;
    } else {
      ++sum.traces_unused;
    }
  }
  if (summary) *summary = sum;

  // Seeds at every frame of each ghost's range.
  std::vector<cv::Mat> lums(stack.frames.size());
  tbb::parallel_for(size_t{0}, stack.frames.size(), [&](size_t i) { lums[i] = luminance(stack.frames[i].image); });
  std::vector<GhostCandidate> out(ghosts.size());
  tbb::parallel_for(size_t{0}, ghosts.size(), [&](size_t g) {
    const BorderTrace* l = ghosts[g].left >= 0 ? &traces[ghosts[g].left] : nullptr;
    const BorderTrace* r = ghosts[g].right >= 0 ? &traces[ghosts[g].right] : nullptr;
    GhostCandidate& c = out[g];
    c.id = static_cast<int>(g);
    if (ghosts[g].peak >= 0) {
      c = peakCandidate(stack, s, lums, traces[ghosts[g].peak], o);
      c.id = static_cast<int>(g);
      trimToFrame(c, s.width());
      return;
    }
    c.left_trace = l ? l->id : -1;
    c.right_trace = r ? r->id : -1;
    c.first_row = std::min(l ? l->firstRow() : s.rows(), r ? r->firstRow() : s.rows());
    c.last_row = std::max(l ? l->lastRow() : -1, r ? r->lastRow() : -1);
    // On beyond its traces while every border it has is hidden (in the light's zone, or beyond
    // the frame) and some of it is in the frame: a ghost passes behind the light.
    auto hidden = [&](int row) {
      bool in_frame = false;
      for (const BorderTrace* t : {l, r}) {
        if (!t) continue;
        const double x = borderAt(*t, s, row, row)[0];
        if (!untraceable(s, row, x)) return false;
        in_frame |= t == l ? x < s.width() : x > 0;
      }
      return in_frame;
    };
    for (int k = 0; k < o.max_hidden_rows && c.first_row > 0 && hidden(c.first_row - 1); ++k) --c.first_row;
    for (int k = 0; k < o.max_hidden_rows && c.last_row + 1 < s.rows() && hidden(c.last_row + 1); ++k) ++c.last_row;
    const int n = c.last_row - c.first_row + 1;
    std::vector<double> angles(s.angles_deg.begin() + c.first_row, s.angles_deg.begin() + c.last_row + 1);
    // Its borders at every frame: a trace's own curve where it is traced, the border model
    // elsewhere; without a model, a pair's traces extrapolated and a lone border's chord below.
    const std::optional<BorderModel> model = zero ? fitBorderModel(s, *zero, l, r, o) : std::nullopt;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    std::vector<double> xl(n, nan), xr(n, nan);
    c.left_seen.assign(n, false);
    c.right_seen.assign(n, false);
    for (const BorderTrace* t : {l, r}) {
      if (!t) continue;
      const std::vector<double> extrapolated = borderAt(*t, s, c.first_row, c.last_row);
      for (int i = 0; i < n; ++i) {
        const int row = c.first_row + i;
        const bool traced = row >= t->firstRow() && row <= t->lastRow();
        (t == l ? xl : xr)[i] = traced || !model ? extrapolated[i] : nan;
        const double x = (t == l ? xl : xr)[i];
        (t == l ? c.left_seen : c.right_seen)[i] = traced && x >= 0 && x <= s.width();
      }
    }
    if (model)
      for (int i = 0; i < n; ++i) {
        const double u = zero->lightAt(angles[i]) - zero->axis_x_px;
        const double m = model->middle(u, zero->axis_x_px), w = model->halfWidth(u);
        if (!std::isfinite(xl[i])) xl[i] = m - w;
        if (!std::isfinite(xr[i])) xr[i] = m + w;
      }
    std::vector<double> steps;
    for (const BorderTrace* t : {l, r})
      if (t)
        for (const auto& p : t->points)
          if (p.jump > 0) steps.push_back(p.jump);
    c.step = median(steps);
    // Half-heights from the vertical profiles, and a one-border ghost's unseen half, without a
    // border model, from the curvature of its outline near the seen border (a circle through the
    // chord there).
    std::vector<double> height(n), middle(n), half(n), inside(n);
    for (int i = 0; i < n; ++i) {
      const int row = c.first_row + i;
      const cv::Mat& lum = lums[row];
      const cv::Mat& valid = stack.frames[row].valid;
      double a0, mx;
      if (std::isfinite(xl[i]) && std::isfinite(xr[i])) {
        a0 = 0.5 * (xr[i] - xl[i]);
        mx = 0.5 * (xr[i] + xl[i]);
      } else {
        const double border = l ? xl[i] : xr[i];
        // To where the other border lies unseen (the frame's edge, or the light's zone).
        const double room = std::abs(hiddenFrom(s, row, border, l ? BorderSide::kLeft : BorderSide::kRight) - border);
        const double depth = std::clamp(room / 2, 4.0, 60.0);
        const double column = l ? border + depth : border - depth;
        const std::vector<double> profile =
            verticalProfile(lum, valid, column, s.horizon_y_px, o.profile_half_columns);
        const double chord = fallingEdge(profile, 1, static_cast<double>(profile.size()), c.step, o.max_step_ratio);
        double radius = std::isfinite(chord) ? (chord * chord + depth * depth) / (2 * depth) : room;
        radius = std::max(radius, 0.5 * (room + 1));  // the other border lies beyond that
        a0 = radius;
        mx = l ? border + radius : border - radius;
      }
      half[i] = std::max(a0, 0.5);
      middle[i] = mx;
      const std::vector<double> profile =
          verticalProfile(lum, valid, mx, s.horizon_y_px, o.profile_half_columns);
      height[i] = fallingEdge(profile, o.min_height_fraction * a0, a0 / o.min_height_fraction, c.step,
                              o.max_step_ratio);
      // The middle's brightness over the outside's (where the borders are in the frame).
      std::vector<double> outside;
      if (c.left_seen[i] && xl[i] > 6) outside.push_back(meanOver(s, row, xl[i] - 5, xl[i] - 2));
      if (c.right_seen[i] && xr[i] < s.width() - 6) outside.push_back(meanOver(s, row, xr[i] + 2, xr[i] + 5));
      const double out_level = outside.empty() ? 0 : median(outside);
      inside[i] = mx >= 0 && mx < s.width() ? meanOver(s, row, mx - 2, mx + 2) - out_level
                                            : std::numeric_limits<double>::quiet_NaN();
    }
    height = smoothed(angles, height);
    inside = smoothed(angles, inside);
    c.seeds.resize(n);
    for (int i = 0; i < n; ++i) {
      model::GhostParameters& p = c.seeds[i];
      p.channels = stack.channels;
      p.center_x = middle[i];
      p.center_y = s.horizon_y_px;
      p.left = p.right = half[i];
      p.height = std::isfinite(height[i]) && height[i] > 0.5 ? height[i] : half[i];
      p.curvature_left = p.curvature_right = model::kEllipseCurvature;
      const double ib = std::isfinite(c.step) ? c.step : 0;
      const double ii = std::isfinite(inside[i]) ? std::max(inside[i], 0.0) : ib;
      for (int ch = 0; ch < stack.channels; ++ch) {
        p.border[ch] = ib;
        p.inside[ch] = ii;
      }
      p.inside_falloff = std::max(1.0, 0.3 * std::min({p.left, p.right, p.height}));
      p.inside_exponent = 1;
      p.outside_falloff = o.seed_outside_falloff_px;
      p.outside_exponent = 1;
      p = model::clampToBounds(p);
    }
    trimToFrame(c, s.width());
  });
  return out;
}

std::vector<CentreSamples> centreSamples(const std::vector<GhostCandidate>& candidates,
                                         const std::vector<BorderTrace>& traces,
                                         const SweepImage& s) {
  std::vector<CentreSamples> out;
  for (const auto& c : candidates) {
    CentreSamples cs;
    if (c.peak_trace >= 0) {
      for (const auto& p : traces[c.peak_trace].points) {
        cs.angles_deg.push_back(s.angles_deg[p.row]);
        cs.centre_x_px.push_back(p.x_px);
      }
      out.push_back(std::move(cs));
      continue;
    }
    if (c.left_trace < 0 || c.right_trace < 0) continue;
    for (const auto& p : traces[c.left_trace].points)
      if (const BorderPoint* q = traces[c.right_trace].at(p.row)) {
        cs.angles_deg.push_back(s.angles_deg[p.row]);
        cs.centre_x_px.push_back(0.5 * (p.x_px + q->x_px));
      }
    out.push_back(std::move(cs));
  }
  return out;
}

}  // namespace flarekit::fit
