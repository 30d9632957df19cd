#include "fit/pedestal.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace flarekit::fit {

bool PedestalFitOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(outlier_sigma >= 0) || !std::isfinite(outlier_sigma))
    return fail("pedestal outlier_sigma must be ≥ 0");
  if (iterations < 1) return fail("pedestal iterations must be ≥ 1");
  if (step < 1) return fail("pedestal step must be ≥ 1");
  return true;
}

model::Pedestal fitPedestal(const cv::Mat& residual, const cv::Mat& valid, cv::Size capture_size,
                            int factor, double noise_sigma, const PedestalFitOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (residual.depth() != CV_32F || valid.type() != CV_8U || valid.size() != residual.size())
    throw std::invalid_argument(
        "fitPedestal: residual must be CV_32F with a CV_8U mask of its size");
  constexpr int kTerms = model::kPedestalTerms;
  const int channels = residual.channels();
  struct Sample {
    std::array<double, kTerms> terms;
    int x, y;
  };
  std::vector<Sample> samples;
  for (int y = options.step / 2; y < residual.rows; y += options.step)
    for (int x = options.step / 2; x < residual.cols; x += options.step)
      if (valid.at<uchar>(y, x))
        samples.push_back(
            {model::pedestalTerms({factor * (x + 0.5), factor * (y + 0.5)}, capture_size), x, y});
  model::Pedestal p;
  p.channels = channels;
  p.coefficients.assign(kTerms * channels, 0.0);
  if (samples.empty()) return p;
  const bool robust = options.outlier_sigma > 0 && noise_sigma > 0;
  const double scale = options.outlier_sigma * noise_sigma;
  auto biweight = [&](double e) {
    const double q = e / scale;
    return std::abs(q) < 1 ? (1 - q * q) * (1 - q * q) : 0.0;
  };
  std::vector<double> r(samples.size()), w(samples.size(), 1.0);
  for (int c = 0; c < channels; ++c) {
    for (size_t i = 0; i < samples.size(); ++i)
      r[i] = residual.ptr<float>(samples[i].y)[samples[i].x * channels + c];
    if (robust) {
      std::vector<double> sorted = r;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double median = sorted[sorted.size() / 2];
      for (size_t i = 0; i < samples.size(); ++i) w[i] = biweight(r[i] - median);
    }
    cv::Vec<double, kTerms> b = cv::Vec<double, kTerms>::all(0);
    for (int it = 0; it < (robust ? options.iterations : 1); ++it) {
      // The normal equations, symmetric: their upper triangle summed, over the samples that count
      // (this sum is most of a fit's time).
      cv::Matx<double, kTerms, kTerms> normal = cv::Matx<double, kTerms, kTerms>::zeros();
      cv::Vec<double, kTerms> right = cv::Vec<double, kTerms>::all(0);
      for (size_t i = 0; i < samples.size(); ++i) {
        if (w[i] == 0) continue;
        const auto& t = samples[i].terms;
        for (int a = 0; a < kTerms; ++a) {
          const double wt = w[i] * t[a];
          right[a] += wt * r[i];
          for (int d = a; d < kTerms; ++d) normal(a, d) += wt * t[d];
        }
      }
      for (int a = 1; a < kTerms; ++a)
        for (int d = 0; d < a; ++d) normal(a, d) = normal(d, a);
      cv::solve(normal, right, b, cv::DECOMP_SVD);
      if (!robust) break;
      for (size_t i = 0; i < samples.size(); ++i) {
        double e = r[i];
        for (int a = 0; a < kTerms; ++a) e -= b[a] * samples[i].terms[a];
        w[i] = biweight(e);
      }
    }
    for (int a = 0; a < kTerms; ++a) p.coefficients[c * kTerms + a] = b[a];
  }
  return p;
}

}  // namespace flarekit::fit
