#pragma once
// Occurrence estimators of a flare overlay (Walch et al. 2018 §3.5): "minimum and maximum intensity
// values are important to define contrast. The sum and average ... approximate brightness. The ratio
// between logarithmic averages of virtual scene and overlay can be used as a glare indicator ...
// The ratio of the ideal contrast and the real contrast describes the change of contrast".
// Each is "rated" by comparing it with its distribution over the model's sampled range
// (percentile()).
//
// These functions take any linear image (a model overlay, or a physical render's flare), so tests
// comparing the model with the physical renderer can use them on both. Colour images are reduced
// to Rec. 709 luminance first (common/image.h).

#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

namespace flarekit::predict {

struct EstimatorOptions {
  // δ added before taking logarithms and in the contrast denominators, so black pixels stay
  // finite (Reinhard's log-average uses the same trick): linear image units, > 0.
  double log_epsilon = 1e-6;

  bool IsValid(std::string* error) const;
};

// The estimators of one overlay F over one scene image R (same size), all from luminance.
struct Estimators {
  double min = 0;   // min F
  double max = 0;   // max F
  double sum = 0;   // Σ F over all pixels
  double mean = 0;  // Σ F / pixel count
  // L̄(R) / L̄(F) with L̄(X) = exp(mean(log(δ + X))): large when the scene outshines the flare.
  double log_average_ratio = 0;
  // Contrast without flare (max R + δ) / (min R + δ), with flare (max(R+F) + δ) / (min(R+F) + δ),
  // and the paper's ratio ideal / real (> 1 when flare lowers the contrast).
  double contrast_without_flare = 0;
  double contrast_with_flare = 0;
  double contrast_ratio = 0;
};

// Which estimator a severity map, timeline or rating uses.
enum class Estimator { kMin, kMax, kSum, kMean, kLogAverageRatio, kContrastRatio };
// All of them, in the order above (for iteration), and their names in files
// ("min", "max", "sum", "mean", "log_average_ratio", "contrast_ratio").
const std::vector<Estimator>& allEstimators();
std::string toString(Estimator e);
// InputError-free parse: returns false for an unknown name.
bool parseEstimator(const std::string& name, Estimator* out);
// The value of one estimator.
double value(const Estimators& e, Estimator which);
// True when a larger value means more flare (false for log_average_ratio, where the scene
// outshining the flare is good).
bool largerIsWorse(Estimator which);

// The estimators of `overlay` over `scene` (CV_32FC1 or CV_32FC3, same size, non-empty, finite).
// Throws std::invalid_argument for empty or mismatched images.
Estimators computeEstimators(const cv::Mat& overlay, const cv::Mat& scene,
                             const EstimatorOptions& options = {});
// Over a uniform scene of `scene_level` (the scene images a test has no picture for).
Estimators computeEstimators(const cv::Mat& overlay, double scene_level,
                             const EstimatorOptions& options = {});

// The percentile (0–100) of `x` within `distribution`: the share of values below x plus half the
// share equal to it (mid-rank), so the median of a distribution rates 50. An empty distribution
// gives NaN.
double percentile(const std::vector<double>& distribution, double x);

// Spearman's rank correlation of two equally long samples (ties get their mean rank): how well two
// severity rankings agree, e.g. the model's against the physical renderer's for the same lights.
// Throws std::invalid_argument for different lengths or fewer than 2 values; NaN when a sample is
// constant.
double spearmanCorrelation(const std::vector<double>& a, const std::vector<double>& b);

nlohmann::json toJson(const Estimators& e);

}  // namespace flarekit::predict
