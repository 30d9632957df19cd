#include "fit/sweep.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/image.h"
#include "common/robust_statistics.h"
#include "fit/polynomial.h"

namespace flarekit::fit {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

double quantile(std::vector<float>& v, double q) {
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

// A row at fractional image position y (pixel centres at j + 0.5), linearly interpolated; `ok`
// false where either row is invalid or outside.
void rowAt(const cv::Mat& lum, const cv::Mat& valid, double y, std::vector<float>& out,
           std::vector<uchar>& ok) {
  const double r = y - 0.5;
  const int j0 = static_cast<int>(std::floor(r));
  const double f = r - j0;
  const int w = lum.cols;
  out.assign(w, 0);
  ok.assign(w, 0);
  if (j0 < 0 || j0 + 1 >= lum.rows) return;
  const float* a = lum.ptr<float>(j0);
  const float* b = lum.ptr<float>(j0 + 1);
  const uchar* va = valid.ptr<uchar>(j0);
  const uchar* vb = valid.ptr<uchar>(j0 + 1);
  for (int x = 0; x < w; ++x) {
    out[x] = static_cast<float>((1 - f) * a[x] + f * b[x]);
    ok[x] = va[x] && (f == 0 || vb[x]);
  }
}

// S at fractional x of one row (linear), or NaN where invalid or outside.
double sampleRow(const cv::Mat& s, const cv::Mat& valid, int row, double x) {
  const double r = x - 0.5;
  const int i0 = static_cast<int>(std::floor(r));
  const double f = r - i0;
  if (i0 < 0 || i0 + 1 >= s.cols) return kNaN;
  if (!valid.at<uchar>(row, i0) || !valid.at<uchar>(row, i0 + 1)) return kNaN;
  return (1 - f) * s.at<float>(row, i0) + f * s.at<float>(row, i0 + 1);
}

// var(I) = α·I + β from the differences of rows mirrored about the horizon (pure noise: the
// flare is symmetric about it), binned by brightness, each bin's median of d²/2 scaled to a
// Gaussian's variance.
void noiseModel(const std::vector<std::pair<float, float>>& samples, double* alpha, double* beta) {
  *alpha = 0;
  *beta = 0;
  if (samples.size() < 100) return;
  std::vector<std::pair<float, float>> s = samples;
  std::sort(s.begin(), s.end());
  const int bins = 24;
  std::vector<double> level, variance;
  for (int b = 0; b < bins; ++b) {
    const size_t lo = s.size() * b / bins, hi = s.size() * (b + 1) / bins;
    if (hi - lo < 20) continue;
    std::vector<float> d2, mean;
    for (size_t i = lo; i < hi; ++i) {
      d2.push_back(s[i].second);
      mean.push_back(s[i].first);
    }
    level.push_back(quantile(mean, 0.5));
    variance.push_back(quantile(d2, 0.5) / 2 / 0.4549);  // median of χ²₁ is 0.4549
  }
  if (level.size() < 2) return;
  // Least squares of variance = α·level + β, in relative error (each bin weighed by 1/variance).
  Eigen::MatrixXd a(level.size(), 2);
  Eigen::VectorXd b(level.size());
  for (size_t i = 0; i < level.size(); ++i) {
    const double w = 1 / std::max(variance[i], 1e-300);
    a(i, 0) = w * std::max(level[i], 0.0);
    a(i, 1) = w;
    b(i) = w * variance[i];
  }
  const Eigen::Vector2d x = a.colPivHouseholderQr().solve(b);
  *alpha = std::max(x(0), 0.0);
  *beta = std::max(x(1), 0.0);
  if (*beta <= 0) *beta = 1e-3 * *std::min_element(variance.begin(), variance.end());
}

// Convolution of each row with a 1-D kernel, borders replicated.
cv::Mat filterRows(const cv::Mat& m, const cv::Mat& kernel) {
  cv::Mat out;
  cv::sepFilter2D(m, out, CV_32F, kernel, cv::Mat::ones(1, 1, CV_64F), cv::Point(-1, -1), 0,
                  cv::BORDER_REPLICATE);
  return out;
}

// The derivative of a Gaussian of σ as a row kernel for sepFilter2D (which correlates).
cv::Mat gaussianDerivative(double sigma) {
  const int r = static_cast<int>(std::ceil(4 * sigma));
  cv::Mat k(1, 2 * r + 1, CV_64F);
  double norm = 0;
  for (int i = -r; i <= r; ++i) norm += std::exp(-0.5 * i * i / (sigma * sigma));
  for (int i = -r; i <= r; ++i)
    k.at<double>(0, i + r) = i / (sigma * sigma) * std::exp(-0.5 * i * i / (sigma * sigma)) / norm;
  return k;
}

// The second derivative of a Gaussian of σ as a row kernel.
cv::Mat gaussianSecondDerivative(double sigma) {
  const int r = static_cast<int>(std::ceil(4 * sigma));
  cv::Mat k(1, 2 * r + 1, CV_64F);
  for (int i = -r; i <= r; ++i)
    k.at<double>(0, i + r) = (i * i / (sigma * sigma) - 1) / (sigma * sigma) * std::exp(-0.5 * i * i / (sigma * sigma));
  // No response to a constant or a line: zero sum (the even kernel has no first moment).
  k -= cv::mean(k)[0];
  // Unit response to x²/2.
  double second = 0;
  for (int i = -r; i <= r; ++i) second += 0.5 * i * i * k.at<double>(0, i + r);
  return k / second;
}

// The median of each row over ±half points (fewer at the ends): the slope under the borders,
// without the side lobes a wider derivative would put beside every strong border.
cv::Mat runningMedian(const cv::Mat& m, int half) {
  cv::Mat out(m.size(), CV_32F);
  tbb::parallel_for(0, m.rows, [&](int r) {
    const float* in = m.ptr<float>(r);
    float* o = out.ptr<float>(r);
    std::vector<float> window;
    for (int x = 0; x < m.cols; ++x) {
      window.assign(in + std::max(0, x - half), in + std::min(m.cols, x + half + 1));
      std::nth_element(window.begin(), window.begin() + window.size() / 2, window.end());
      o[x] = window[window.size() / 2];
    }
  });
  return out;
}

}  // namespace

bool SweepOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (band_half_rows < 0) return fail("sweep: band_half_rows must be ≥ 0");
  if (!(edge_sigma_px > 0)) return fail("sweep: edge_sigma_px must be > 0");
  if (!(trend_sigma_px > edge_sigma_px)) return fail("sweep: trend_sigma_px must be > edge_sigma_px");
  if (!(light_window_px >= 0)) return fail("sweep: light_window_px must be ≥ 0");
  if (!(light_percentile > 0 && light_percentile < 1)) return fail("sweep: light_percentile must be in (0, 1)");
  if (light_min_frames < 1) return fail("sweep: light_min_frames must be ≥ 1");
  if (!(peak_sigma > 0)) return fail("sweep: peak_sigma must be > 0");
  if (!(gate_px > 0)) return fail("sweep: gate_px must be > 0");
  if (!(max_slope_px > 0)) return fail("sweep: max_slope_px must be > 0");
  if (max_gap_rows < 0) return fail("sweep: max_gap_rows must be ≥ 0");
  if (min_trace_rows < 2) return fail("sweep: min_trace_rows must be ≥ 2");
  if (!(min_significance > 0)) return fail("sweep: min_significance must be > 0");
  if (kink_rows < 2) return fail("sweep: kink_rows must be ≥ 2");
  if (!(max_kink_px_per_row > 0)) return fail("sweep: max_kink_px_per_row must be > 0");
  if (max_join_gap_rows < 0) return fail("sweep: max_join_gap_rows must be ≥ 0");
  if (!(join_tolerance_px > 0)) return fail("sweep: join_tolerance_px must be > 0");
  return true;
}

const BorderPoint* BorderTrace::at(int row) const {
  auto it = std::lower_bound(points.begin(), points.end(), row,
                             [](const BorderPoint& p, int r) { return p.row < r; });
  return it != points.end() && it->row == row ? &*it : nullptr;
}

SweepImage buildSweep(const FrameStack& stack, const Horizon& horizon, const SweepOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const int rows = static_cast<int>(stack.frames.size());
  const int w = stack.size.width;
  SweepImage s;
  s.horizon_y_px = horizon.y_px;
  s.radiance = cv::Mat::zeros(rows, w, CV_32F);
  s.valid = cv::Mat::zeros(rows, w, CV_8U);
  s.light_x_px.assign(rows, kNaN);
  std::vector<std::vector<std::pair<float, float>>> noise_samples(rows);
  const int b = options.band_half_rows;
  tbb::parallel_for(0, rows, [&](int i) {
    const Frame& f = stack.frames[i];
    const cv::Mat lum = luminance(f.image);
    std::vector<double> sum(w, 0);
    std::vector<int> count(w, 0);
    std::vector<uchar> all_ok(w, 1);
    std::vector<float> up, down;
    std::vector<uchar> ok_up, ok_down;
    for (int k = 0; k <= b; ++k) {
      rowAt(lum, f.valid, horizon.y_px - k, up, ok_up);
      rowAt(lum, f.valid, horizon.y_px + k, down, ok_down);
      for (int x = 0; x < w; ++x) {
        all_ok[x] &= ok_up[x] && ok_down[x];
        sum[x] += k == 0 ? up[x] : up[x] + down[x];
        count[x] += k == 0 ? 1 : 2;
        // Every 4th column is enough for the noise model.
        if (k > 0 && x % 4 == 0 && ok_up[x] && ok_down[x]) {
          const float d = up[x] - down[x];
          noise_samples[i].emplace_back(0.5f * (up[x] + down[x]), d * d);
        }
      }
    }
    for (int x = 0; x < w; ++x) {
      s.radiance.at<float>(i, x) = static_cast<float>(sum[x] / count[x]);
      s.valid.at<uchar>(i, x) = all_ok[x] ? 255 : 0;
    }
  });
  s.angles_deg.resize(rows);
  for (int i = 0; i < rows; ++i) s.angles_deg[i] = stack.frames[i].angle_deg;

  std::vector<std::pair<float, float>> all_noise;
  for (auto& n : noise_samples) all_noise.insert(all_noise.end(), n.begin(), n.end());
  double alpha = 0, beta = 0;
  noiseModel(all_noise, &alpha, &beta);
  const double rows_averaged = 2.0 * b + 1;

  // The light's own profile along the horizon, as a function of the distance from its centre.
  s.light = cv::Mat::zeros(rows, w, CV_32F);
  const int window = static_cast<int>(std::ceil(options.light_window_px));
  for (int i = 0; i < rows && i < static_cast<int>(horizon.lights.size()); ++i)
    if (horizon.lights[i].found) s.light_x_px[i] = horizon.lights[i].center.x;
  // The light's zone is at least the core the horizon found (clipped, or above half the light's
  // peak), which a merged HDR frame may hold without clipping; with the light in too few frames
  // to measure its profile, that core alone.
  std::vector<float> core_radii;
  for (const LightImage& l : horizon.lights)
    if (l.found) core_radii.push_back(static_cast<float>(l.core_radius_px));
  const double core = core_radii.empty() ? 0.0 : quantile(core_radii, 0.5);
  s.light_zone_left_px = s.light_zone_right_px = core;
  const auto light_frames = std::count_if(s.light_x_px.begin(), s.light_x_px.end(),
                                          [](double x) { return std::isfinite(x); });
  if (window > 0 && light_frames >= options.light_min_frames) {
    std::vector<double> profile(2 * window + 1, kNaN);
    for (int d = -window; d <= window; ++d) {
      std::vector<float> v;
      for (int i = 0; i < rows; ++i)
        if (std::isfinite(s.light_x_px[i]))
          if (const double x = sampleRow(s.radiance, s.valid, i, s.light_x_px[i] + d); std::isfinite(x))
            v.push_back(static_cast<float>(x));
      if (static_cast<int>(v.size()) >= options.light_min_frames)
        profile[d + window] = quantile(v, options.light_percentile);
    }
    // The part of the profile that falls off with the distance: what lies under the light at
    // the window's edges (the veils about it) is not the light's.
    const double left = profile.front(), right = profile.back();
    const double edge = std::isfinite(left) && std::isfinite(right) ? std::max(left, right)
                        : std::isfinite(left)                       ? left
                                                                    : right;
    // The light's zone: its core, out from its centre: where it clips (no profile there), and
    // at least the core the horizon found.
    for (int side : {-1, 1}) {
      int d = 0;
      while (d + 1 <= window && !std::isfinite(profile[window + side * (d + 1)])) ++d;
      (side < 0 ? s.light_zone_left_px : s.light_zone_right_px) = std::max<double>(d, core);
    }
    if (std::isfinite(edge))
      for (double& p : profile) p = std::isfinite(p) ? std::max(0.0, p - edge) : 0.0;
    else
      std::fill(profile.begin(), profile.end(), 0.0);
    for (int i = 0; i < rows; ++i) {
      if (!std::isfinite(s.light_x_px[i])) continue;
      for (int x = 0; x < w; ++x) {
        const double d = x + 0.5 - s.light_x_px[i];
        if (std::abs(d) >= window) continue;
        const int k0 = static_cast<int>(std::floor(d)) + window;
        const double f = d - std::floor(d);
        s.light.at<float>(i, x) = static_cast<float>((1 - f) * profile[k0] + f * profile[k0 + 1]);
      }
    }
  }

  // Noise σ of S, and log(S − light) with a floor at that σ (below it nothing is seen).
  s.noise = cv::Mat(rows, w, CV_32F);
  cv::Mat log_s(rows, w, CV_32F), scale(rows, w, CV_32F);
  for (int i = 0; i < rows; ++i) {
    float last = 0;
    bool have = false;
    for (int x = 0; x < w; ++x) {
      const double v = s.radiance.at<float>(i, x);
      const double sigma = std::sqrt(std::max(alpha * std::max(v, 0.0) + beta, 1e-300) / rows_averaged);
      s.noise.at<float>(i, x) = static_cast<float>(sigma);
      const double clean = std::max(v - s.light.at<float>(i, x), 2 * sigma);
      if (s.valid.at<uchar>(i, x)) {
        last = static_cast<float>(std::log(clean));
        have = true;
      }
      // Invalid points carry the last valid value along the row, so the filters do not ring.
      log_s.at<float>(i, x) = have ? last : static_cast<float>(std::log(clean));
      scale.at<float>(i, x) = static_cast<float>(clean / sigma);
    }
  }
  cv::Mat derivative = filterRows(log_s, gaussianDerivative(options.edge_sigma_px));
  s.edge = (derivative - runningMedian(derivative, static_cast<int>(std::ceil(2 * options.trend_sigma_px))))
               .mul(scale);
  s.slope = derivative;
  s.peak = -filterRows(log_s, gaussianSecondDerivative(options.edge_sigma_px)).mul(scale);

  // Masked: within reach of an invalid point (the light's clipped core) or the frame's edge, and
  // the light's zone.
  cv::Mat invalid = s.valid == 0;
  const int reach = static_cast<int>(std::ceil(3 * options.edge_sigma_px));
  cv::Mat near_invalid;
  cv::dilate(invalid, near_invalid, cv::getStructuringElement(cv::MORPH_RECT, {2 * reach + 1, 1}));
  s.valid = near_invalid == 0;
  s.valid.colRange(0, std::min(w, reach)).setTo(0);
  s.valid.colRange(std::max(0, w - reach), w).setTo(0);
  for (int i = 0; i < rows; ++i) {
    if (!std::isfinite(s.light_x_px[i])) continue;
    for (int x = 0; x < w; ++x)
      if (s.inLightZone(i, x + 0.5)) s.valid.at<uchar>(i, x) = 0;
  }
  // In σ of the response: its robust spread over the valid points (the filters' gain and the
  // rows' correlation in one factor).
  for (cv::Mat* response : {&s.edge, &s.peak}) {
    std::vector<float> magnitudes;
    for (int i = 0; i < rows; ++i)
      for (int x = 0; x < w; ++x)
        if (s.valid.at<uchar>(i, x)) magnitudes.push_back(std::abs(response->at<float>(i, x)));
    if (!magnitudes.empty()) {
      const double spread = madSigma(magnitudes);
      if (spread > 0) *response /= spread;
    }
    response->setTo(0, s.valid == 0);
  }
  return s;
}

// ── Traces ─────────────────────────────────────────────────────────────────────────────────────

namespace {

struct Growing {
  BorderTrace trace;
  int missed = 0;
};

// The trace's position at `row` predicted by a line through its last points, and the gate.
void predict(const BorderTrace& t, int row, const SweepOptions& o, double* x, double* gate) {
  const int n = static_cast<int>(t.points.size());
  const int gap = row - t.points.back().row;
  if (n == 1) {
    *x = t.points[0].x_px;
    *gate = o.gate_px + o.max_slope_px * gap;
    return;
  }
  const int k = std::min(n, 8);
  double sw = 0, st = 0, sx = 0, stt = 0, stx = 0;
  for (int i = n - k; i < n; ++i) {
    const double r = t.points[i].row, v = t.points[i].x_px;
    sw += 1;
    st += r;
    sx += v;
    stt += r * r;
    stx += r * v;
  }
  const double den = sw * stt - st * st;
  const double slope = den > 1e-9 ? (sw * stx - st * sx) / den : 0;
  *x = (sx - slope * st) / sw + slope * row;
  *gate = (n < 3 ? 2 * o.gate_px : o.gate_px) + 0.5 * (gap - 1);
}

// The points of one row: extrema of the border response beyond `level` (σ) for a border, or
// where the slope falls through 0 with a curvature beyond `level` for a peak.
std::vector<BorderPoint> rowPoints(const SweepImage& s, int row, BorderSide side, double level) {
  std::vector<BorderPoint> peaks;
  if (side == BorderSide::kPeak) {
    const float* d = s.slope.ptr<float>(row);
    const float* c = s.peak.ptr<float>(row);
    const uchar* ok = s.valid.ptr<uchar>(row);
    for (int x = 0; x + 1 < s.width(); ++x) {
      if (!ok[x] || !ok[x + 1] || !(d[x] >= 0 && d[x + 1] < 0)) continue;
      const double strength = std::max(c[x], c[x + 1]);
      if (strength > level) peaks.push_back({row, x + 0.5 + d[x] / (d[x] - d[x + 1]), strength, 0});
    }
    return peaks;
  }
  const int sign = side == BorderSide::kLeft ? 1 : -1;
  const float* e = s.edge.ptr<float>(row);
  const uchar* ok = s.valid.ptr<uchar>(row);
  for (int x = 1; x + 1 < s.width(); ++x) {
    if (!ok[x] || !ok[x - 1] || !ok[x + 1]) continue;
    const double v = sign * e[x], l = sign * e[x - 1], r = sign * e[x + 1];
    if (!(v > level && v >= l && v > r)) continue;
    const double den = l - 2 * v + r;
    const double offset = den < 0 ? std::clamp(0.5 * (l - r) / den, -0.5, 0.5) : 0.0;
    peaks.push_back({row, x + 0.5 + offset, v, 0});
  }
  return peaks;
}

// S − light just inside the border minus just outside it, over 2–5 px on either side.
double jumpAt(const SweepImage& s, int row, double x, BorderSide side) {
  if (side == BorderSide::kPeak) {
    const int xi = std::clamp(static_cast<int>(std::floor(x)), 0, s.width() - 1);
    return s.radiance.at<float>(row, xi) - s.light.at<float>(row, xi);
  }
  double inside = 0, outside = 0;
  int ni = 0, no = 0;
  const int direction = side == BorderSide::kLeft ? 1 : -1;
  for (int d = 2; d <= 5; ++d)
    for (int sgn : {1, -1}) {
      const int xi = static_cast<int>(std::floor(x + sgn * d));
      if (xi < 0 || xi >= s.width()) continue;
      const double v = s.radiance.at<float>(row, xi) - s.light.at<float>(row, xi);
      if (sgn == direction) {
        inside += v;
        ++ni;
      } else {
        outside += v;
        ++no;
      }
    }
  return ni && no ? inside / ni - outside / no : 0.0;
}

void finish(BorderTrace& t, const SweepImage& s) {
  double sum = 0;
  std::vector<double> angles, xs;
  for (auto& p : t.points) {
    sum += p.strength;
    p.jump = jumpAt(s, p.row, p.x_px, t.side);
    angles.push_back(s.angles_deg[p.row]);
    xs.push_back(p.x_px);
  }
  t.significance = sum / std::sqrt(static_cast<double>(t.points.size()));
  const int degree = std::clamp(static_cast<int>(t.points.size()) / 8, 1, 3);
  t.x_of_angle = robustPolynomial(angles, xs, degree, 4, 0.3);
}

// Whether `later` continues `earlier`: one polynomial (degree 2, 3 over long spans) runs through
// both pieces' points within the tolerance, as through each piece alone.
bool continues(const BorderTrace& earlier, const BorderTrace& later, const SweepImage& s,
               const SweepOptions& o) {
  if (earlier.side != later.side) return false;
  const int gap = later.firstRow() - earlier.lastRow();
  if (gap < 1 || gap > o.max_join_gap_rows) return false;
  // Quick rejection: the earlier's line at the later's start.
  const double predicted = earlier.x_of_angle.evaluate(s.angles_deg[later.firstRow()]);
  if (std::abs(predicted - later.points.front().x_px) > 10 * o.join_tolerance_px + 2 * gap) return false;
  std::vector<double> angles, xs;
  for (const BorderTrace* t : {&earlier, &later})
    for (const auto& p : t->points) {
      angles.push_back(s.angles_deg[p.row]);
      xs.push_back(p.x_px);
    }
  const int span = later.lastRow() - earlier.firstRow();
  const model::Polynomial joint = leastSquaresPolynomial(angles, xs, span > 40 ? 3 : 2);
  double worst = 0, sum = 0;
  for (size_t i = 0; i < angles.size(); ++i) {
    const double r = std::abs(joint.evaluate(angles[i]) - xs[i]);
    worst = std::max(worst, r);
    sum += r * r;
  }
  return std::sqrt(sum / angles.size()) <= 0.5 * o.join_tolerance_px && worst <= 2 * o.join_tolerance_px;
}

// A border's slope changes slowly; where a trace's slope before and after a point differs by more
// than max_kink_px_per_row (lines through the kink_rows points on either side), the linking passed
// from one border onto another that crossed it: the trace is split there (at the largest change).
std::vector<BorderTrace> splitAtKinks(BorderTrace t, const SweepOptions& o) {
  const int n = static_cast<int>(t.points.size());
  const int k = o.kink_rows;
  auto slope = [&](int from, int to) {  // least-squares slope of points [from, to)
    double sw = 0, sr = 0, sx = 0, srr = 0, srx = 0;
    for (int i = from; i < to; ++i) {
      const double r = t.points[i].row, x = t.points[i].x_px;
      sw += 1;
      sr += r;
      sx += x;
      srr += r * r;
      srx += r * x;
    }
    const double den = sw * srr - sr * sr;
    return den > 1e-9 ? (sw * srx - sr * sx) / den : 0.0;
  };
  int best = -1;
  double largest = o.max_kink_px_per_row;
  for (int i = k; i + k <= n; ++i)
    if (const double change = std::abs(slope(i - k, i) - slope(i, i + k)); change > largest) {
      largest = change;
      best = i;
    }
  if (best < 0) return {std::move(t)};
  BorderTrace later = t;
  later.points.erase(later.points.begin(), later.points.begin() + best);
  t.points.resize(best);
  std::vector<BorderTrace> out = splitAtKinks(std::move(t), o);
  for (auto& piece : splitAtKinks(std::move(later), o)) out.push_back(std::move(piece));
  return out;
}

// Whether a trace keeps its distance from the light (within 2 px, over five frames or more that
// show the light, most of its own): a fringe of the light's own image, never a ghost's border.
bool movesWithLight(const BorderTrace& t, const SweepImage& s) {
  double lo = 1e9, hi = -1e9;
  int n = 0;
  for (const auto& p : t.points)
    if (std::isfinite(s.light_x_px[p.row])) {
      const double d = p.x_px - s.light_x_px[p.row];
      lo = std::min(lo, d);
      hi = std::max(hi, d);
      ++n;
    }
  return n >= 5 && n * 2 >= static_cast<int>(t.points.size()) && hi - lo <= 2;
}

}  // namespace

std::vector<BorderTrace> findTraces(const SweepImage& s, const SweepOptions& o) {
  std::string error;
  if (!o.IsValid(&error)) throw std::invalid_argument(error);
  std::vector<BorderTrace> done;
  for (BorderSide side : {BorderSide::kLeft, BorderSide::kRight, BorderSide::kPeak}) {
    std::vector<Growing> active;
    for (int row = 0; row < s.rows(); ++row) {
      const std::vector<BorderPoint> peaks = rowPoints(s, row, side, o.peak_sigma);
      struct Candidate {
        double cost;
        int trace, peak;
      };
      std::vector<Candidate> candidates;
      for (size_t t = 0; t < active.size(); ++t) {
        double x, gate;
        predict(active[t].trace, row, o, &x, &gate);
        // Established traces choose first: a new one's wide gate must not take their points.
        const double rank = active[t].trace.points.size() < 3 ? 1e6 : 0;
        for (size_t p = 0; p < peaks.size(); ++p)
          if (const double d = std::abs(peaks[p].x_px - x); d <= gate)
            candidates.push_back({rank + d, static_cast<int>(t), static_cast<int>(p)});
      }
      std::sort(candidates.begin(), candidates.end(),
                [](const Candidate& a, const Candidate& b) { return a.cost < b.cost; });
      std::vector<bool> trace_taken(active.size(), false), peak_taken(peaks.size(), false);
      for (const auto& c : candidates) {
        if (trace_taken[c.trace] || peak_taken[c.peak]) continue;
        trace_taken[c.trace] = peak_taken[c.peak] = true;
        active[c.trace].trace.points.push_back(peaks[c.peak]);
        active[c.trace].missed = 0;
      }
      std::vector<Growing> next;
      for (size_t t = 0; t < active.size(); ++t) {
        if (!trace_taken[t] && ++active[t].missed > o.max_gap_rows)
          done.push_back(std::move(active[t].trace));
        else
          next.push_back(std::move(active[t]));
      }
      for (size_t p = 0; p < peaks.size(); ++p)
        if (!peak_taken[p]) {
          Growing g;
          g.trace.side = side;
          g.trace.points.push_back(peaks[p]);
          next.push_back(std::move(g));
        }
      active = std::move(next);
    }
    for (auto& g : active) done.push_back(std::move(g.trace));
  }
  // Pieces of three points or more (fewer cannot show where they go), split where the linking
  // went from one border onto another, and the light's own fringes left out.
  std::vector<BorderTrace> traces;
  for (auto& whole : done)
    for (auto& t : splitAtKinks(std::move(whole), o))
      if (t.points.size() >= 3 && !movesWithLight(t, s)) {
        finish(t, s);
        traces.push_back(std::move(t));
      }
  // Each piece, earliest first, takes the nearest later piece that continues it, until none does.
  std::sort(traces.begin(), traces.end(),
            [](const BorderTrace& a, const BorderTrace& b) { return a.firstRow() < b.firstRow(); });
  std::vector<bool> joined(traces.size(), false);
  for (size_t a = 0; a < traces.size(); ++a) {
    if (joined[a]) continue;
    for (;;) {
      int best = -1;
      for (size_t b = 0; b < traces.size(); ++b) {
        if (b == a || joined[b] || traces[b].firstRow() <= traces[a].lastRow()) continue;
        if (best >= 0 && traces[b].firstRow() >= traces[best].firstRow()) continue;
        if (continues(traces[a], traces[b], s, o)) best = static_cast<int>(b);
      }
      if (best < 0) break;
      traces[a].points.insert(traces[a].points.end(), traces[best].points.begin(), traces[best].points.end());
      finish(traces[a], s);
      joined[best] = true;
    }
  }
  for (size_t a = 0; a < traces.size(); ++a)
    if (joined[a]) traces[a].points.clear();
  std::vector<BorderTrace> kept;
  for (auto& t : traces) {
    if (t.points.empty() || static_cast<int>(t.points.size()) < o.min_trace_rows || t.significance < o.min_significance)
      continue;
    t.id = static_cast<int>(kept.size());
    kept.push_back(std::move(t));
  }
  return kept;
}

}  // namespace flarekit::fit
