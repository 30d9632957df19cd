#include "fit/horizon.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/image.h"
#include "common/robust_statistics.h"

namespace flarekit::fit {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180;

// The valid values of every other row and column: enough for a frame's quantiles.
std::vector<float> validSamples(const cv::Mat& lum, const cv::Mat& valid) {
  std::vector<float> v;
  v.reserve(lum.total() / 4);
  for (int y = 0; y < lum.rows; y += 2) {
    const float* p = lum.ptr<float>(y);
    const uchar* ok = valid.ptr<uchar>(y);
    for (int x = 0; x < lum.cols; x += 2)
      if (ok[x]) v.push_back(p[x]);
  }
  return v;
}

double quantileOfValid(const cv::Mat& lum, const cv::Mat& valid, double q) {
  std::vector<float> v = validSamples(lum, valid);
  if (v.empty()) return 0;
  const size_t k = static_cast<size_t>(q * (v.size() - 1));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

double medianOfValid(const cv::Mat& lum, const cv::Mat& valid) {
  std::vector<float> v = validSamples(lum, valid);
  return v.empty() ? 0 : upperMedian(v);
}

// The light's core: the pixels at least half as bright as the brightest (clipped pixels count as
// brightest), connected to it.
LightImage findLight(const cv::Mat& lum, const cv::Mat& valid, double contrast) {
  LightImage light;
  double peak = 0;
  cv::Point at;
  cv::minMaxLoc(lum, nullptr, &peak, nullptr, &at);
  // The light clips, or (behind a filter) outshines the frame's brightest ghosts by far.
  bool clipped = false;
  for (int y = 0; y < lum.rows && !clipped; ++y)
    for (int x = 0; x < lum.cols; ++x)
      if (!valid.at<uchar>(y, x) && lum.at<float>(y, x) >= 0.5 * peak) {
        clipped = true;
        break;
      }
  if (!clipped && !(peak > contrast * std::max(quantileOfValid(lum, valid, 0.99), 1e-30))) return light;
  cv::Mat core = (lum >= 0.5 * peak) | ((valid == 0) & (lum > 0.5 * peak));
  cv::Mat labels;
  cv::connectedComponents(core, labels, 8, CV_32S);
  const int label = labels.at<int>(at);
  double sx = 0, sy = 0, n = 0;
  for (int y = 0; y < labels.rows; ++y) {
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < labels.cols; ++x)
      if (l[x] == label) {
        sx += x + 0.5;
        sy += y + 0.5;
        n += 1;
      }
  }
  light.found = true;
  light.center = {sx / n, sy / n};
  light.core_radius_px = std::sqrt(n / std::numbers::pi);
  return light;
}

// Mean squared log-difference between the rows mirrored about y = c (c a multiple of ½: row j
// maps to row 2c − 1 − j), over `band` rows on each side, valid pixels only.
double mirrorCost(const std::vector<cv::Mat>& logs, const std::vector<cv::Mat>& valids, double c,
                  int band, double* rms) {
  double sum = 0;
  long long count = 0;
  const int rows = logs.front().rows, cols = logs.front().cols;
  const int mirror = static_cast<int>(std::lround(2 * c)) - 1;
  for (size_t f = 0; f < logs.size(); ++f)
    for (int j = static_cast<int>(std::ceil(c)); j < rows && j - c <= band; ++j) {
      const int k = mirror - j;
      if (k < 0 || k >= j) continue;
      const float* a = logs[f].ptr<float>(j);
      const float* b = logs[f].ptr<float>(k);
      const uchar* va = valids[f].ptr<uchar>(j);
      const uchar* vb = valids[f].ptr<uchar>(k);
      for (int x = 0; x < cols; ++x)
        if (va[x] && vb[x]) {
          const double d = a[x] - b[x];
          sum += d * d;
          ++count;
        }
    }
  if (rms) *rms = count ? std::sqrt(sum / count) : 0;
  return count ? sum / count : std::numeric_limits<double>::infinity();
}

}  // namespace

bool HorizonOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(search_px > 0)) return fail("horizon: search_px must be > 0");
  if (frame_stride < 1) return fail("horizon: frame_stride must be ≥ 1");
  if (!(band_fraction > 0 && band_fraction <= 0.5)) return fail("horizon: band_fraction must be in (0, 0.5]");
  if (!(light_contrast > 1)) return fail("horizon: light_contrast must be > 1");
  return true;
}

Horizon measureHorizon(const FrameStack& stack, const HorizonOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  Horizon h;
  const size_t n = stack.frames.size();
  h.lights.resize(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    const Frame& f = stack.frames[i];
    h.lights[i] = findLight(luminance(f.image), f.valid, options.light_contrast);
  });
  std::vector<double> core_y;
  for (const auto& l : h.lights)
    if (l.found) core_y.push_back(l.center.y);
  h.lights_found = static_cast<int>(core_y.size());
  double start = stack.size.height / 2.0;
  if (!core_y.empty()) {
    std::nth_element(core_y.begin(), core_y.begin() + core_y.size() / 2, core_y.end());
    start = core_y[core_y.size() / 2];
  }
  // The frames compared, in log scale (ghosts of every brightness count alike), the light's core
  // left out: clipped, it is no evidence of where the middle lies.
  std::vector<cv::Mat> logs, valids;
  for (size_t i = 0; i < n; i += options.frame_stride) {
    const Frame& f = stack.frames[i];
    cv::Mat lum = luminance(f.image);
    const double floor = std::max(1e-3 * medianOfValid(lum, f.valid), 1e-30);
    cv::Mat l;
    cv::max(lum, floor, l);
    cv::log(l, l);
    cv::Mat valid = f.valid.clone();
    if (h.lights[i].found)
      cv::circle(valid, h.lights[i].center, static_cast<int>(std::ceil(2 * h.lights[i].core_radius_px + 2)),
                 cv::Scalar(0), cv::FILLED);
    logs.push_back(l);
    valids.push_back(valid);
  }
  const int band = std::max(1, static_cast<int>(options.band_fraction * stack.size.height));
  const double lo = std::max(1.0, std::round(2 * (start - options.search_px)) / 2);
  const double hi = std::min(stack.size.height - 1.0, std::round(2 * (start + options.search_px)) / 2);
  std::vector<double> centres;
  for (double c = lo; c <= hi + 1e-9; c += 0.5) centres.push_back(c);
  std::vector<double> costs(centres.size());
  tbb::parallel_for(size_t{0}, centres.size(),
                    [&](size_t k) { costs[k] = mirrorCost(logs, valids, centres[k], band, nullptr); });
  const size_t best = std::min_element(costs.begin(), costs.end()) - costs.begin();
  h.y_px = centres[best];
  // Sub-pixel: the vertex of the parabola through the best and its neighbours.
  if (best > 0 && best + 1 < costs.size()) {
    const double a = costs[best - 1], b = costs[best], c = costs[best + 1];
    const double den = a - 2 * b + c;
    if (den > 0) h.y_px += 0.5 * std::clamp(0.5 * (a - c) / den, -0.5, 0.5);
  }
  mirrorCost(logs, valids, centres[best], band, &h.symmetry_rms);
  return h;
}

// ── The light's pattern ─────────────────────────────────────────────────────────────────────────

bool LightPatternOptions::IsValid(std::string* error) const {
  if (radius_px >= 1 && percentile > 0 && percentile < 1 && min_frames >= 1) return true;
  if (error) *error = "light pattern: need radius_px ≥ 1, percentile in (0, 1), min_frames ≥ 1";
  return false;
}

LightPattern measureLightPattern(const FrameStack& stack, const Horizon& horizon,
                                 const LightPatternOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  LightPattern pattern;
  std::vector<size_t> frames;
  for (size_t i = 0; i < horizon.lights.size(); ++i)
    if (horizon.lights[i].found) frames.push_back(i);
  if (static_cast<int>(frames.size()) < options.min_frames) return pattern;
  const int r = options.radius_px, side = 2 * r + 1;
  std::vector<cv::Mat> lums(frames.size());
  tbb::parallel_for(size_t{0}, frames.size(), [&](size_t k) { lums[k] = luminance(stack.frames[frames[k]].image); });
  pattern.image = cv::Mat::zeros(side, side, CV_32F);
  pattern.radius_px = r;
  tbb::parallel_for(0, side, [&](int v) {
    std::vector<float> samples;
    for (int u = 0; u < side; ++u) {
      samples.clear();
      for (size_t k = 0; k < frames.size(); ++k) {
        const cv::Point2d c = horizon.lights[frames[k]].center;
        const int x = static_cast<int>(std::floor(c.x)) + u - r, y = static_cast<int>(std::floor(c.y)) + v - r;
        if (x < 0 || y < 0 || x >= lums[k].cols || y >= lums[k].rows) continue;
        samples.push_back(lums[k].at<float>(y, x));
      }
      if (static_cast<int>(samples.size()) < options.min_frames) continue;
      const size_t q = static_cast<size_t>(options.percentile * (samples.size() - 1));
      std::nth_element(samples.begin(), samples.begin() + q, samples.end());
      pattern.image.at<float>(v, u) = samples[q];
    }
  });
  // Less what lies at the window's edge: the veils under the light are not its.
  std::vector<float> edge;
  for (int k = 0; k < side; ++k)
    for (float e : {pattern.image.at<float>(0, k), pattern.image.at<float>(side - 1, k),
                    pattern.image.at<float>(k, 0), pattern.image.at<float>(k, side - 1)})
      edge.push_back(e);
  std::nth_element(edge.begin(), edge.begin() + edge.size() / 2, edge.end());
  pattern.image = cv::max(pattern.image - edge[edge.size() / 2], 0.0f);
  return pattern;
}

void LightPattern::takeOut(const LightImage& light, cv::Mat& image, cv::Mat& valid) const {
  if (this->image.empty() || !light.found) return;
  const int r = radius_px, channels = image.channels();
  const int cx = static_cast<int>(std::floor(light.center.x)), cy = static_cast<int>(std::floor(light.center.y));
  const cv::Mat lum = luminance(image);
  for (int v = 0; v <= 2 * r; ++v) {
    const int y = cy + v - r;
    if (y < 0 || y >= image.rows) continue;
    float* row = image.ptr<float>(y);
    for (int u = 0; u <= 2 * r; ++u) {
      const int x = cx + u - r;
      if (x < 0 || x >= image.cols) continue;
      const float p = this->image.at<float>(v, u);
      if (p <= 0) continue;
      // Where the light outshines what lies under it, nothing under it can be measured.
      if (p > lum.at<float>(y, x) - p) valid.at<uchar>(y, x) = 0;
      for (int c = 0; c < channels; ++c) row[x * channels + c] = std::max(0.0f, row[x * channels + c] - p);
    }
  }
}

// ── Optical zero ───────────────────────────────────────────────────────────────────────────────

bool OpticalZeroOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (light_terms < 1 || light_terms > 4) return fail("optical zero: light_terms must be 1–4");
  if (ghost_terms < 1 || ghost_terms > 4) return fail("optical zero: ghost_terms must be 1–4");
  if (min_samples < 3) return fail("optical zero: min_samples must be ≥ 3");
  if (!(max_zero_deg > 0)) return fail("optical zero: max_zero_deg must be > 0");
  return true;
}

double OpticalZero::lightX(double angle_deg) const {
  const double t = std::tan((angle_deg - angle_zero_deg) * kDegToRad);
  double x = axis_x_px, power = t;
  for (double a : light_coefficients) {
    x += a * power;
    power *= t * t;
  }
  return x;
}

namespace {

// The odd-curve fit at one θ0 by weighted linear least squares: unknowns axis x, the light's
// coefficients, each ghost's. Returns the weighted squared error; fills `zero` and the residuals.
struct OddFitData {
  std::vector<double> light_angles, light_x;
  std::vector<CentreSamples> ghosts;
};

double fitAtZero(const OddFitData& d, double theta0, int light_terms, int ghost_terms,
                 double light_weight, const std::vector<std::vector<double>>& ghost_weights,
                 OpticalZero* zero, std::vector<double>* light_res,
                 std::vector<std::vector<double>>* ghost_res) {
  const int g = static_cast<int>(d.ghosts.size());
  const int unknowns = 1 + light_terms + g * ghost_terms;
  int rows = static_cast<int>(d.light_angles.size());
  for (const auto& s : d.ghosts) rows += static_cast<int>(s.angles_deg.size());
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, unknowns);
  Eigen::VectorXd b(rows), w(rows);
  int r = 0;
  auto odd = [&](double angle, int first, int terms) {
    const double t = std::tan((angle - theta0) * kDegToRad);
    double power = t;
    for (int k = 0; k < terms; ++k) {
      a(r, first + k) = power;
      power *= t * t;
    }
  };
  for (size_t i = 0; i < d.light_angles.size(); ++i, ++r) {
    a(r, 0) = 1;
    odd(d.light_angles[i], 1, light_terms);
    b(r) = d.light_x[i];
    w(r) = light_weight;
  }
  for (int k = 0; k < g; ++k)
    for (size_t i = 0; i < d.ghosts[k].angles_deg.size(); ++i, ++r) {
      a(r, 0) = 1;
      odd(d.ghosts[k].angles_deg[i], 1 + light_terms + k * ghost_terms, ghost_terms);
      b(r) = d.ghosts[k].centre_x_px[i];
      w(r) = ghost_weights[k][i];
    }
  const Eigen::VectorXd sw = w.cwiseSqrt();
  const Eigen::VectorXd x = (sw.asDiagonal() * a).colPivHouseholderQr().solve(sw.asDiagonal() * b);
  const Eigen::VectorXd res = a * x - b;
  if (zero) {
    zero->axis_x_px = x(0);
    zero->angle_zero_deg = theta0;
    zero->light_coefficients.assign(x.data() + 1, x.data() + 1 + light_terms);
  }
  r = 0;
  if (light_res) light_res->assign(res.data(), res.data() + d.light_angles.size());
  r = static_cast<int>(d.light_angles.size());
  if (ghost_res) {
    ghost_res->clear();
    for (int k = 0; k < g; ++k) {
      const int m = static_cast<int>(d.ghosts[k].angles_deg.size());
      ghost_res->emplace_back(res.data() + r, res.data() + r + m);
      r += m;
    }
  }
  return res.cwiseProduct(res).dot(w);
}

double rmsOf(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / v.size());
}

double robustSigma(std::vector<double> v) {
  if (v.empty()) return 1;
  return std::max(madSigma(v), 1e-3);
}

}  // namespace

OpticalZero measureOpticalZero(const FrameStack& stack, const Horizon& horizon,
                               const std::vector<CentreSamples>& ghosts,
                               const OpticalZeroOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  OpticalZero zero;
  zero.axis_x_px = stack.size.width / 2.0;
  OddFitData d;
  for (size_t i = 0; i < stack.frames.size() && i < horizon.lights.size(); ++i) {
    const LightImage& l = horizon.lights[i];
    if (!l.found || l.cutByEdge(stack.size.width)) continue;
    d.light_angles.push_back(stack.frames[i].angle_deg);
    d.light_x.push_back(l.center.x);
  }
  if (d.light_angles.size() < 4) return zero;
  const int light_terms =
      std::min(options.light_terms, static_cast<int>(d.light_angles.size()) - 2);
  for (const auto& g : ghosts)
    if (static_cast<int>(g.angles_deg.size()) >= options.min_samples) d.ghosts.push_back(g);
  zero.ghosts_used = static_cast<int>(d.ghosts.size());
  std::vector<std::vector<double>> weights;
  for (const auto& g : d.ghosts) weights.emplace_back(g.angles_deg.size(), 1.0);
  double light_weight = 1;
  auto search = [&](double lo, double hi, double step) {
    double best = lo, best_cost = std::numeric_limits<double>::infinity();
    for (double t = lo; t <= hi + 1e-12; t += step) {
      const double c = fitAtZero(d, t, light_terms, options.ghost_terms, light_weight, weights,
                                 nullptr, nullptr, nullptr);
      if (c < best_cost) {
        best_cost = c;
        best = t;
      }
    }
    return best;
  };
  // Nothing tells θ0 from the axis's x: θ0 = 0, the axis where the light's curve is there.
  auto unmeasured = [&] {
    OddFitData light = d;
    light.ghosts.clear();
    OpticalZero none;
    std::vector<double> light_res;
    fitAtZero(light, 0, light_terms, 1, 1, {}, &none, &light_res, nullptr);
    none.ghosts_used = zero.ghosts_used;
    none.light_rms_px = rmsOf(light_res);
    return none;
  };
  if (d.ghosts.empty()) return unmeasured();
  double theta0 = 0;
  // Iteratively reweighted: the light and each ghost weighed by their own spread, samples beyond
  // 3σ of it down-weighted (Huber), so that the centres of a wrong pair or of a peak that is no
  // ghost's centre, which scatter, do not pull the zero.
  constexpr double kCoarseDeg = 0.05;  // the search's first grid, then 0.001° about its best
  for (int pass = 0; pass < 4; ++pass) {
    theta0 = search(-options.max_zero_deg, options.max_zero_deg, kCoarseDeg);
    theta0 = search(theta0 - kCoarseDeg, theta0 + kCoarseDeg, 0.001);
    std::vector<double> light_res;
    std::vector<std::vector<double>> ghost_res;
    fitAtZero(d, theta0, light_terms, options.ghost_terms, light_weight, weights, &zero,
              &light_res, &ghost_res);
    const double light_sigma = robustSigma(light_res);
    std::vector<double> all;
    for (const auto& g : ghost_res) all.insert(all.end(), g.begin(), g.end());
    light_weight = 1 / (light_sigma * light_sigma);
    for (size_t k = 0; k < ghost_res.size(); ++k) {
      const double ghost_sigma = robustSigma(ghost_res[k]);
      for (size_t i = 0; i < ghost_res[k].size(); ++i) {
        const double u = std::abs(ghost_res[k][i]) / (3 * ghost_sigma);
        weights[k][i] = (u > 1 ? 1 / u : 1.0) / (ghost_sigma * ghost_sigma);
      }
    }
    zero.light_rms_px = rmsOf(light_res);
    zero.centre_rms_px = rmsOf(all);
  }
  // The best fit on the search's bound: the ghosts' centres agree on no zero within it.
  if (std::abs(theta0) >= options.max_zero_deg - kCoarseDeg) return unmeasured();
  zero.measured = true;
  return zero;
}

}  // namespace flarekit::fit
