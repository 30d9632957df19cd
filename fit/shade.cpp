#include "fit/shade.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "common/robust_statistics.h"

#include "model/model_renderer.h"

namespace flarekit::fit {

bool ShadeOptions::IsValid(std::string* error) const {
  if (level >= 1 && outlier_sigma > 0 && iterations >= 1) return true;
  if (error) *error = "shade: need level ≥ 1, outlier_sigma > 0, iterations ≥ 1";
  return false;
}

void fitShades(const cv::Mat& image, const cv::Mat& valid, double noise_sigma,
               std::vector<model::GhostParameters>& ghosts, model::Pedestal* pedestal,
               const ShadeOptions& o, ShadeEquations* equations) {
  std::string error;
  if (!o.IsValid(&error)) throw std::invalid_argument(error);
  const int channels = image.channels(), k = o.level;
  const cv::Size capture = image.size();
  const cv::Size size(capture.width / k, capture.height / k);
  const cv::Rect whole(0, 0, size.width * k, size.height * k);
  cv::Mat level, level_valid;
  cv::resize(image(whole), level, size, 0, 0, cv::INTER_AREA);
  cv::resize(valid(whole), level_valid, size, 0, 0, cv::INTER_AREA);
  level_valid = level_valid >= 255;
  model::ViewTransform view;
  view.scale = 1.0 / k;
  // Basis images: each ghost's outline value and inside value alone (one channel, value 1).
  const int g = static_cast<int>(ghosts.size());
  const int terms = o.pedestal && pedestal ? model::kPedestalTerms : 0;
  const int m = 2 * g + terms;
  std::vector<cv::Mat> basis;
  for (const auto& ghost : ghosts)
    for (int part = 0; part < 2; ++part) {
      model::GhostParameters one = ghost;
      one.channels = 1;
      one.border = {part == 0 ? 1.0 : 0.0, 0, 0};
      one.inside = {part == 1 ? 1.0 : 0.0, 0, 0};
      basis.push_back(model::renderGhosts(std::span(&one, 1), size, 1, {}, view));
    }
  // The pixels that count, and their terms.
  std::vector<cv::Point> pixels;
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x)
      if (level_valid.at<uchar>(y, x)) pixels.emplace_back(x, y);
  if (equations) *equations = {};
  if (pixels.empty()) return;
  Eigen::MatrixXd a(pixels.size(), m);
  for (size_t p = 0; p < pixels.size(); ++p) {
    for (int j = 0; j < 2 * g; ++j) a(p, j) = basis[j].at<float>(pixels[p]);
    if (terms) {
      const auto t = model::pedestalTerms({k * (pixels[p].x + 0.5), k * (pixels[p].y + 0.5)}, capture);
      for (int j = 0; j < terms; ++j) a(p, 2 * g + j) = t[j];
    }
  }
  const double sigma = std::max(noise_sigma / k, 1e-30);
  std::vector<double> pedestal_coefficients(terms * channels, 0.0);
  for (int c = 0; c < channels; ++c) {
    Eigen::VectorXd b(pixels.size());
    for (size_t p = 0; p < pixels.size(); ++p) b(p) = level.ptr<float>(pixels[p].y)[pixels[p].x * channels + c];
    Eigen::VectorXd w = Eigen::VectorXd::Ones(pixels.size());
    Eigen::VectorXd x = Eigen::VectorXd::Zero(m);
    for (int pass = 0; pass < o.iterations; ++pass) {
      // The weighted normal equations, then an active set: Ib, Ii held at 0 where the free solve
      // wants them negative.
      const Eigen::MatrixXd aw = w.asDiagonal() * a;
      const Eigen::MatrixXd normal = aw.transpose() * aw;
      const Eigen::VectorXd rhs = aw.transpose() * b.cwiseProduct(w);
      std::vector<bool> held(m, false);
      for (int round = 0; round <= 2 * g; ++round) {
        std::vector<int> free;
        for (int j = 0; j < m; ++j)
          if (!held[j]) free.push_back(j);
        const int n = static_cast<int>(free.size());
        Eigen::MatrixXd nf(n, n);
        Eigen::VectorXd rf(n);
        for (int i = 0; i < n; ++i) {
          rf(i) = rhs(free[i]);
          for (int j = 0; j < n; ++j) nf(i, j) = normal(free[i], free[j]);
        }
        const Eigen::VectorXd xf = nf.completeOrthogonalDecomposition().solve(rf);
        x.setZero();
        bool negative = false;
        for (size_t j = 0; j < free.size(); ++j) {
          x(free[j]) = xf(j);
          if (free[j] < 2 * g && xf(j) < 0) {
            held[free[j]] = true;
            negative = true;
          }
        }
        if (!negative) break;
        for (int j = 0; j < 2 * g; ++j) x(j) = std::max(x(j), 0.0);
      }
      // Tukey's biweight about the residual's median.
      const Eigen::VectorXd r = a * x - b;
      std::vector<double> residuals(r.data(), r.data() + r.size());
      const double centre = upperMedian(residuals);
      // The residual's own robust scale, at least the noise: where the outlines are still off,
      // their misfit, far above the noise, is not an outlier.
      const double scale = std::max(sigma, madSigma(residuals, centre));
      for (Eigen::Index p = 0; p < r.size(); ++p) {
        const double u = (r(p) - centre) / (o.outlier_sigma * scale);
        w(p) = std::abs(u) < 1 ? 1 - u * u : 0.0;  // √ of the biweight (1 − u²)²
      }
    }
    if (equations) {
      // Weighted as the last pass left them; the pedestal's terms eliminated (Schur complement).
      const Eigen::MatrixXd aw = w.asDiagonal() * a;
      const Eigen::MatrixXd normal = aw.transpose() * aw;
      const Eigen::VectorXd rhs = aw.transpose() * b.cwiseProduct(w);
      Eigen::MatrixXd n = normal.topLeftCorner(2 * g, 2 * g);
      Eigen::VectorXd r = rhs.head(2 * g);
      if (terms) {
        const auto pp = normal.bottomRightCorner(terms, terms).completeOrthogonalDecomposition();
        const Eigen::MatrixXd gp = normal.topRightCorner(2 * g, terms);
        n -= gp * pp.solve(gp.transpose());
        r -= gp * pp.solve(rhs.tail(terms));
      }
      equations->normal.push_back(std::move(n));
      equations->rhs.push_back(std::move(r));
    }
    for (int i = 0; i < g; ++i) {
      ghosts[i].border[c] = x(2 * i);
      ghosts[i].inside[c] = x(2 * i + 1);
    }
    for (int j = 0; j < terms; ++j) pedestal_coefficients[c * terms + j] = x(2 * g + j);
  }
  if (terms) {
    pedestal->channels = channels;
    pedestal->coefficients = pedestal_coefficients;
  }
}

}  // namespace flarekit::fit
