#include "predict/estimators.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "common/image.h"

namespace flarekit::predict {

bool EstimatorOptions::IsValid(std::string* error) const {
  if (!(log_epsilon > 0) || !std::isfinite(log_epsilon)) {
    if (error) *error = "log_epsilon must be positive and finite";
    return false;
  }
  return true;
}

const std::vector<Estimator>& allEstimators() {
  static const std::vector<Estimator> all = {Estimator::kMin,  Estimator::kMax,
                                             Estimator::kSum,  Estimator::kMean,
                                             Estimator::kLogAverageRatio, Estimator::kContrastRatio};
  return all;
}

std::string toString(Estimator e) {
  switch (e) {
    case Estimator::kMin: return "min";
    case Estimator::kMax: return "max";
    case Estimator::kSum: return "sum";
    case Estimator::kMean: return "mean";
    case Estimator::kLogAverageRatio: return "log_average_ratio";
    case Estimator::kContrastRatio: return "contrast_ratio";
  }
  return "?";
}

bool parseEstimator(const std::string& name, Estimator* out) {
  for (Estimator e : allEstimators())
    if (toString(e) == name) {
      *out = e;
      return true;
    }
  return false;
}

double value(const Estimators& e, Estimator which) {
  switch (which) {
    case Estimator::kMin: return e.min;
    case Estimator::kMax: return e.max;
    case Estimator::kSum: return e.sum;
    case Estimator::kMean: return e.mean;
    case Estimator::kLogAverageRatio: return e.log_average_ratio;
    case Estimator::kContrastRatio: return e.contrast_ratio;
  }
  return 0;
}

bool largerIsWorse(Estimator which) { return which != Estimator::kLogAverageRatio; }

namespace {

cv::Mat luminance64(const cv::Mat& image) {
  if (image.empty()) throw std::invalid_argument("estimators: empty image");
  if (image.depth() != CV_32F || (image.channels() != 1 && image.channels() != 3))
    throw std::invalid_argument("estimators: images must be CV_32FC1 or CV_32FC3");
  cv::Mat y;
  luminance(image).convertTo(y, CV_64F);
  return y;
}

Estimators compute(const cv::Mat& f, const cv::Mat& r, double delta) {
  Estimators e;
  cv::minMaxLoc(f, &e.min, &e.max);
  e.sum = cv::sum(f)[0];
  e.mean = e.sum / static_cast<double>(f.total());
  // §3.5: log-averages (exp of the mean log) of scene and overlay.
  cv::Mat log_f, log_r;
  cv::log(f + delta, log_f);
  cv::log(r + delta, log_r);
  const double n = static_cast<double>(f.total());
  e.log_average_ratio = std::exp(cv::sum(log_r)[0] / n - cv::sum(log_f)[0] / n);
  // §3.5 and [4]: contrast without flare (ideal) over contrast with flare (real).
  double r_min, r_max, c_min, c_max;
  cv::minMaxLoc(r, &r_min, &r_max);
  cv::minMaxLoc(r + f, &c_min, &c_max);
  e.contrast_without_flare = (r_max + delta) / (r_min + delta);
  e.contrast_with_flare = (c_max + delta) / (c_min + delta);
  e.contrast_ratio = e.contrast_without_flare / e.contrast_with_flare;
  return e;
}

}  // namespace

Estimators computeEstimators(const cv::Mat& overlay, const cv::Mat& scene, const EstimatorOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("estimator options: " + error);
  const cv::Mat f = luminance64(overlay), r = luminance64(scene);
  if (f.size() != r.size()) throw std::invalid_argument("estimators: overlay and scene sizes differ");
  return compute(f, r, options.log_epsilon);
}

Estimators computeEstimators(const cv::Mat& overlay, double scene_level, const EstimatorOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("estimator options: " + error);
  const cv::Mat f = luminance64(overlay);
  return compute(f, cv::Mat(f.size(), CV_64F, cv::Scalar(scene_level)), options.log_epsilon);
}

double percentile(const std::vector<double>& distribution, double x) {
  if (distribution.empty()) return std::numeric_limits<double>::quiet_NaN();
  double below = 0, equal = 0;
  for (double v : distribution) {
    if (v < x) below += 1;
    else if (v == x) equal += 1;
  }
  return 100.0 * (below + 0.5 * equal) / static_cast<double>(distribution.size());
}

namespace {

std::vector<double> ranks(const std::vector<double>& v) {
  std::vector<size_t> order(v.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return v[a] < v[b]; });
  std::vector<double> r(v.size());
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    while (j + 1 < order.size() && v[order[j + 1]] == v[order[i]]) ++j;
    const double mean_rank = 0.5 * static_cast<double>(i + j) + 1.0;
    for (size_t k = i; k <= j; ++k) r[order[k]] = mean_rank;
    i = j + 1;
  }
  return r;
}

}  // namespace

double spearmanCorrelation(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.size() < 2)
    throw std::invalid_argument("spearmanCorrelation: needs two samples of the same length ≥ 2");
  const std::vector<double> ra = ranks(a), rb = ranks(b);
  const double n = static_cast<double>(a.size());
  const double mean = (n + 1) / 2;
  double sab = 0, saa = 0, sbb = 0;
  for (size_t i = 0; i < ra.size(); ++i) {
    sab += (ra[i] - mean) * (rb[i] - mean);
    saa += (ra[i] - mean) * (ra[i] - mean);
    sbb += (rb[i] - mean) * (rb[i] - mean);
  }
  if (saa == 0 || sbb == 0) return std::numeric_limits<double>::quiet_NaN();
  return sab / std::sqrt(saa * sbb);
}

nlohmann::json toJson(const Estimators& e) {
  return {{"min", e.min},
          {"max", e.max},
          {"sum", e.sum},
          {"mean", e.mean},
          {"log_average_ratio", e.log_average_ratio},
          {"contrast_without_flare", e.contrast_without_flare},
          {"contrast_with_flare", e.contrast_with_flare},
          {"contrast_ratio", e.contrast_ratio}};
}

}  // namespace flarekit::predict
