#include "fit/cost.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/robust_statistics.h"

namespace flarekit::fit {

bool CostOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(edge_weight >= 0) || !std::isfinite(edge_weight)) return fail("edge_weight (λ) must be ≥ 0");
  if (!(edge_sigma1_px > 0) || !(edge_sigma1_px <= 50)) return fail("edge_sigma1_px must be in (0, 50]");
  if (!(edge_sigma2_px > 0) || !(edge_sigma2_px <= 50)) return fail("edge_sigma2_px must be in (0, 50]");
  if (!(region_margin_px >= 0) || !(region_margin_px <= 1000)) return fail("region_margin_px must be in [0, 1000]");
  if (!(loss_scale >= 0) || !std::isfinite(loss_scale)) return fail("loss_scale must be ≥ 0");
  if (max_pixels < 1000) return fail("max_pixels must be ≥ 1000");
  if (!(prior_fraction >= 0) || !std::isfinite(prior_fraction)) return fail("prior_fraction must be ≥ 0");
  return true;
}

// ── Edge filter ───────────────────────────────────────────────────────────────────────────────

EdgeFilter::EdgeFilter(const CostOptions& options)
    : sigma1_(options.edge_sigma1_px),
      sigma2_(options.edge_sigma2_px),
      // The 8-neighbour Laplacian approximates 3∇²; σ1² + σ2² is the Lindeberg normalisation.
      scale_((options.edge_sigma1_px * options.edge_sigma1_px +
              options.edge_sigma2_px * options.edge_sigma2_px) / 3.0) {
  // OpenCV's GaussianBlur with ksize 0 truncates float kernels at 4σ.
  radius_ = static_cast<int>(std::ceil(4 * sigma1_)) + static_cast<int>(std::ceil(4 * sigma2_)) + 1;
}

cv::Mat EdgeFilter::apply(const cv::Mat& image) const {
  // Walch 2018 §3.3.1, Fig. 7: Gaussian, Laplacian (horizontal, vertical and diagonal edges),
  // Gaussian again. Each Gaussian is separable (OpenCV runs it as two 1-D passes).
  static const cv::Mat laplacian8 = (cv::Mat_<float>(3, 3) << 1, 1, 1, 1, -8, 1, 1, 1, 1);
  cv::Mat a, b;
  cv::GaussianBlur(image, a, cv::Size(0, 0), sigma1_, sigma1_, cv::BORDER_REPLICATE);
  cv::filter2D(a, b, CV_32F, laplacian8, cv::Point(-1, -1), 0, cv::BORDER_REPLICATE);
  cv::GaussianBlur(b, a, cv::Size(0, 0), sigma2_, sigma2_, cv::BORDER_REPLICATE);
  a *= scale_;
  return a;
}

// ── Frame data ────────────────────────────────────────────────────────────────────────────────

double estimateNoiseSigma(const cv::Mat& image, const cv::Mat& valid) {
  std::vector<float> values;
  const int c = image.channels();
  const int step = std::max(1, static_cast<int>(std::sqrt(image.total() / 40000.0)));
  for (int y = 0; y < image.rows; y += step) {
    const float* p = image.ptr<float>(y);
    const uchar* v = valid.ptr<uchar>(y);
    for (int x = 0; x < image.cols; x += step) {
      if (!v[x]) continue;
      double sum = 0;
      for (int k = 0; k < c; ++k) sum += p[x * c + k];
      values.push_back(static_cast<float>(sum / c));
    }
  }
  if (values.size() < 16) return 0;
  // The fainter half is background (and faint flare): its spread is the noise. Partial sorts give
  // the values a full sort would, in less time (it ran for every frame and level).
  const size_t half = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + half, values.end());
  values.resize(half);
  return madSigma(values, upperMedian(values));
}

double estimatePixelNoiseSigma(const cv::Mat& image, const cv::Mat& valid, int block_px) {
  if (block_px > 1) {
    // Block means over the channels' mean; invalid blocks are NaN and left out.
    const int rows = image.rows / block_px, cols = image.cols / block_px, c = image.channels();
    cv::Mat means(rows, cols, CV_32F);
    for (int by = 0; by < rows; ++by)
      for (int bx = 0; bx < cols; ++bx) {
        double sum = 0;
        bool whole = true;
        for (int y = by * block_px; y < (by + 1) * block_px && whole; ++y) {
          const float* p = image.ptr<float>(y);
          const uchar* v = valid.ptr<uchar>(y);
          for (int x = bx * block_px; x < (bx + 1) * block_px; ++x) {
            whole = whole && v[x];
            for (int k = 0; k < c; ++k) sum += p[x * c + k];
          }
        }
        means.at<float>(by, bx) = whole ? static_cast<float>(sum / (c * block_px * block_px))
                                        : std::numeric_limits<float>::quiet_NaN();
      }
    cv::Mat valid_means = means == means;
    return block_px * estimatePixelNoiseSigma(cv::Mat(means).setTo(0, ~valid_means), valid_means);
  }
  std::vector<float> differences;
  const int c = image.channels();
  differences.reserve(image.total());
  for (int y = 0; y < image.rows; ++y) {
    const float* p = image.ptr<float>(y);
    const uchar* v = valid.ptr<uchar>(y);
    for (int x = 0; x + 1 < image.cols; ++x) {
      if (!v[x] || !v[x + 1]) continue;
      double difference = 0;
      for (int k = 0; k < c; ++k) difference += p[(x + 1) * c + k] - p[x * c + k];
      differences.push_back(static_cast<float>(std::abs(difference / c)));
    }
  }
  if (differences.size() < 16) return 0;
  // A difference of two independent values of σ has σ√2.
  return kSigmaPerMad / std::sqrt(2.0) * upperMedian(differences);
}

FrameData FrameData::make(const cv::Mat& image, const cv::Mat& valid, const EdgeFilter& edge,
                          int factor) {
  FrameData d;
  d.factor = factor;
  d.image = image;
  d.valid = valid;
  d.channels = image.channels();
  d.edge = edge.apply(image);
  cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT,
                                             cv::Size(2 * edge.radius() + 1, 2 * edge.radius() + 1));
  cv::erode(valid, d.edge_valid, kernel, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(255));
  d.noise_sigma = estimateNoiseSigma(image, valid);
  return d;
}

FramePyramid::FramePyramid(const cv::Mat& image, const cv::Mat& valid, const EdgeFilter& edge,
                           double noise_sigma)
    : image_(image), valid_(valid), edge_(edge), noise_sigma_(noise_sigma) {}

const FrameData& FramePyramid::level(int factor) const {
  factor = std::max(1, factor);
  const std::lock_guard<std::mutex> lock(mutex_);
  auto it = levels_.find(factor);
  if (it != levels_.end()) return it->second;
  if (factor == 1) {
    levels_[1] = FrameData::make(image_, valid_, edge_, 1);
    if (noise_sigma_ >= 0) levels_[1].noise_sigma = noise_sigma_;
    return levels_[1];
  }
  const cv::Size size(std::max(1, image_.cols / factor), std::max(1, image_.rows / factor));
  const cv::Rect crop(0, 0, size.width * factor, size.height * factor);
  cv::Mat image, valid;
  cv::resize(image_(crop), image, size, 0, 0, cv::INTER_AREA);
  // A coarse pixel is valid only when all its k×k pixels are.
  cv::Mat invalid = valid_(crop) == 0, any_invalid;
  cv::Mat invalid_f;
  invalid.convertTo(invalid_f, CV_32F, 1.0 / 255);
  cv::resize(invalid_f, any_invalid, size, 0, 0, cv::INTER_AREA);
  valid = any_invalid <= 0;
  levels_[factor] = FrameData::make(image, valid, edge_, factor);
  if (noise_sigma_ >= 0) levels_[factor].noise_sigma = noise_sigma_ / factor;
  return levels_[factor];
}

// ── Bounds ────────────────────────────────────────────────────────────────────────────────────

namespace {

// The model's bounds on parameter `index` (model::parameterBounds) intersected with [lo, hi].
model::ParameterBounds modelBoundsWithin(int index, int channels, double lo, double hi) {
  model::ParameterBounds b = model::parameterBounds(index, channels);
  b.lower = std::max(b.lower, lo);
  b.upper = std::min(b.upper, hi);
  return b;
}

}  // namespace

model::ParameterBounds fitBounds(int index, int channels, cv::Size size, double intensity_limit) {
  using namespace model::param;
  const model::ParameterLayout layout{channels};
  const double diag = std::hypot(size.width, size.height);
  auto clamp = [&](double lo, double hi) { return modelBoundsWithin(index, channels, lo, hi); };
  if (index == kMx) return clamp(-size.width, 2.0 * size.width);
  if (index == kMy) return clamp(-size.height, 2.0 * size.height);
  if (index == kL || index == kR || index == kH) return clamp(0.5, diag);
  if (index >= layout.ib(0) && index < layout.fi()) return clamp(0, intensity_limit);
  if (index == layout.fi()) return clamp(0.3, diag);
  if (index == layout.fo()) return clamp(0.3, kSharpOutsideFalloffFraction * diag);
  return model::parameterBounds(index, channels);
}

std::vector<model::ParameterBounds> fitBounds(const GroupCost& cost) {
  std::vector<model::ParameterBounds> bounds;
  for (int k = 0; k < cost.parametersPerGhost(); ++k)
    bounds.push_back(fitBounds(k, cost.channels(), cost.imageSize(), cost.intensityLimit()));
  return bounds;
}

// ── Group cost ────────────────────────────────────────────────────────────────────────────────

namespace {

// The level at which a region of `area` capture pixels fits within max_pixels.
int levelFor(double area, int max_pixels) {
  return std::max(1, static_cast<int>(std::ceil(std::sqrt(area / max_pixels))));
}

const FrameData& chooseLevel(const FramePyramid& pyramid,
                             std::span<const model::GhostParameters> seeds,
                             const CostOptions& options) {
  const cv::Rect image_rect(0, 0, pyramid.size().width, pyramid.size().height);
  if (options.whole_frame) return pyramid.level(levelFor(image_rect.area(), options.max_pixels));
  cv::Rect box;
  for (const auto& g : seeds) box |= model::ghostPixelBounds(g);
  const int m = static_cast<int>(std::ceil(options.region_margin_px));
  const cv::Rect region = cv::Rect(box.x - m, box.y - m, box.width + 2 * m, box.height + 2 * m) & image_rect;
  return pyramid.level(levelFor(region.area(), options.max_pixels));
}

}  // namespace

GroupCost::GroupCost(const FramePyramid& pyramid, const EdgeFilter& edge,
                     std::span<const model::GhostParameters> others,
                     std::span<const model::GhostParameters> seeds, const CostOptions& options,
                     std::span<const std::array<double, 6>> prior_sigmas)
    : frame_(chooseLevel(pyramid, seeds, options)), edge_(edge), options_(options) {
  if (seeds.empty()) throw std::invalid_argument("GroupCost needs at least one ghost");
  const FrameData& frame = frame_;
  image_size_ = pyramid.size();
  const double k = frame.factor;
  if (frame.factor > 1) view_.scale = 1.0 / k;  // model (capture) pixels → level pixels
  ghost_count_ = static_cast<int>(seeds.size());
  channels_ = frame.channels;
  parameters_per_ghost_ = model::parameterCount(channels_);
  const cv::Rect image_rect(0, 0, frame.image.cols, frame.image.rows);
  cv::Rect box;
  for (const auto& g : seeds) {
    if (g.channels != channels_) throw std::invalid_argument("ghost channels differ from the frame's");
    box |= model::ghostPixelBounds(g, view_);
  }
  const int m = static_cast<int>(std::ceil(options.region_margin_px / k));
  region_ = options.whole_frame ? image_rect
                                : cv::Rect(box.x - m, box.y - m, box.width + 2 * m, box.height + 2 * m) & image_rect;
  const int r = edge.radius();
  grown_ = cv::Rect(region_.x - r, region_.y - r, region_.width + 2 * r, region_.height + 2 * r);
  if (region_.empty()) return;

  target_ = frame.image(region_).clone();
  target_edge_ = frame.edge(region_).clone();
  if (!others.empty()) {
    // The other ghosts over the grown region, so their edge image is exact on the region.
    model::RenderOptions render;
    cv::Mat o = model::renderGhosts(others, grown_, channels_, render, view_);
    const cv::Rect inner(region_.x - grown_.x, region_.y - grown_.y, region_.width, region_.height);
    target_ -= o(inner);
    target_edge_ -= edge.apply(o)(inner);
  }
  data_valid_ = frame.valid(region_);
  edge_valid_ = frame.edge_valid(region_);

  // The region scale s: the brightest seed's peak (see cost.h), at least 3 noise σ.
  double scale = 0;
  for (const auto& g : seeds)
    for (int c = 0; c < channels_; ++c) scale = std::max({scale, g.border[c], g.inside[c]});
  scale_ = std::max({scale, 3 * frame.noise_sigma, 1e-12});
  double data_peak = 0;
  std::vector<cv::Mat> planes;
  cv::split(target_, planes);
  for (const cv::Mat& plane : planes) {
    double peak = 0;
    cv::minMaxLoc(plane, nullptr, &peak, nullptr, nullptr, data_valid_);
    data_peak = std::max(data_peak, peak);
  }
  // A ghost may be up to 20× brighter than the region's brightest valid pixel: its peak may lie
  // where no pixel is valid (cost.h intensityLimit).
  intensity_limit_ = 20 * std::max({data_peak, 3 * frame.noise_sigma, 1e-12});

  if (!prior_sigmas.empty())
    for (size_t i = 0; i < seeds.size(); ++i) {
      const auto& g = seeds[i];
      prior_center_.push_back({g.center_x - g.left, g.center_x + g.right, g.center_y, g.height,
                               g.curvature_left, g.curvature_right});
      prior_sigma_.emplace_back(prior_sigmas[i].begin(), prior_sigmas[i].end());
    }
  else if (options.prior_fraction > 0)
    for (const auto& g : seeds) {
      const double length = options.prior_fraction * std::max({g.left, g.right, g.height}) + 1;
      prior_center_.push_back({g.center_x - g.left, g.center_x + g.right, g.center_y, g.height,
                               g.curvature_left, g.curvature_right});
      prior_sigma_.push_back({length, length, length, length, options.prior_fraction, options.prior_fraction});
    }

  const int stride = levelFor(region_.area(), options.max_pixels);
  for (int y = stride / 2; y < region_.height; y += stride) {
    const uchar* v = data_valid_.ptr<uchar>(y);
    for (int x = stride / 2; x < region_.width; x += stride)
      if (v[x]) samples_.emplace_back(x, y);
  }
}

namespace {

std::vector<model::GhostParameters> ghostsFrom(const std::vector<const double*>& parameters, int count,
                                               int channels) {
  std::vector<model::GhostParameters> ghosts;
  ghosts.reserve(parameters.size());
  for (const double* p : parameters)
    ghosts.push_back(model::fromParameterVector(std::span<const double>(p, count), channels));
  return ghosts;
}

}  // namespace

double GroupCost::evaluate(const std::vector<const double*>& parameters, bool jacobians) {
  return evaluate(ghostsFrom(parameters, parameters_per_ghost_, channels_), jacobians);
}

void GroupCost::prepare(const std::vector<const double*>& parameters, bool jacobians) {
  evaluateImages(ghostsFrom(parameters, parameters_per_ghost_, channels_), jacobians);
}

double GroupCost::evaluate(std::span<const model::GhostParameters> input, bool jacobians) {
  evaluateImages(input, jacobians);
  return region_.empty() ? 0.0 : totalCost();
}

void GroupCost::evaluateImages(std::span<const model::GhostParameters> input, bool jacobians) {
  ++evaluations_;
  if (static_cast<int>(input.size()) != ghost_count_)
    throw std::invalid_argument("GroupCost::evaluate: wrong number of ghosts");
  if (region_.empty()) {
    has_jacobians_ = jacobians;
    return;
  }
  prior_cost_ = 0;
  if (priorResidualCount() > 0) {
    std::vector<double> r(kPriorParameters);
    for (int g = 0; g < ghost_count_; ++g) {
      priorResiduals(g, model::toParameterVector(input[g]).data(), r.data(), nullptr);
      for (double v : r) prior_cost_ += 0.5 * v * v;
    }
  }
  // Ceres keeps parameters within bounds; a caller (the GD baseline) may step onto the edge.
  std::vector<model::GhostParameters> ghosts;
  for (const auto& g : input) ghosts.push_back(model::isValid(g) ? g : model::clampToBounds(g));

  const float inv_scale = static_cast<float>(1.0 / scale_);
  const float edge_factor = static_cast<float>(std::sqrt(options_.edge_weight) / scale_);
  const cv::Rect inner(region_.x - grown_.x, region_.y - grown_.y, region_.width, region_.height);

  model::RenderOptions render;
  render.parallel = true;
  // Tiles of 32 px, not the renderer's 64: a region holds about max_pixels samples at its level
  // (12000: 110 × 110 px), which 64-px tiles cut into four tasks or fewer for two threads, one of
  // them idle where a ghost covers only part of the region. The tiles decide where the
  // nearest-point search starts along a row, so changing their size changes the fits at the level
  // of that search's tolerance.
  render.tile_size = 32;
  model::RenderedGhosts rendered;
  if (jacobians)
    rendered = model::renderGhostsWithDerivatives(ghosts, grown_, channels_, render, view_);
  else
    rendered.image = model::renderGhosts(ghosts, grown_, channels_, render, view_);
  model_ = rendered.image(inner).clone();
  cv::Mat model_edge = edge_.apply(rendered.image)(inner);
  cv::subtract(model_, target_, residual_data_);
  residual_data_ *= inv_scale;
  cv::subtract(model_edge, target_edge_, residual_edge_);
  residual_edge_ *= edge_factor;

  has_jacobians_ = jacobians;
  if (jacobians) {
    jacobian_data_.assign(ghost_count_, std::vector<cv::Mat>(parameters_per_ghost_));
    jacobian_edge_.assign(ghost_count_, std::vector<cv::Mat>(parameters_per_ghost_));
    jacobian_rect_.assign(ghost_count_, std::vector<cv::Rect>(2));
    const int r = edge_.radius();
    for (int g = 0; g < ghost_count_; ++g) {
      const auto& d = rendered.derivatives[g];
      if (d.rect.empty()) continue;
      // Data part: the derivative image where it meets the region.
      jacobian_rect_[g][0] = (d.rect & region_) - region_.tl();
      // Edge part: E spreads the derivative by the filter radius.
      const cv::Rect spread(d.rect.x - r, d.rect.y - r, d.rect.width + 2 * r, d.rect.height + 2 * r);
      jacobian_rect_[g][1] = (spread & region_) - region_.tl();
    }
    // Each parameter's images on their own task (the edge filter of every derivative image ran on
    // one thread, beside Ceres's); each task writes its own images, so the result is the same.
    tbb::parallel_for(0, ghost_count_ * parameters_per_ghost_, [&](int index) {
      const int g = index / parameters_per_ghost_, k = index % parameters_per_ghost_;
      const auto& d = rendered.derivatives[g];
      if (d.rect.empty()) return;
      const cv::Rect data_rect = jacobian_rect_[g][0] + region_.tl();
      const cv::Rect edge_rect = jacobian_rect_[g][1] + region_.tl();
      const cv::Rect spread(d.rect.x - r, d.rect.y - r, d.rect.width + 2 * r, d.rect.height + 2 * r);
      const cv::Mat& image = d.images[k];
      if (!data_rect.empty()) {
        cv::Mat crop = image(data_rect - d.rect.tl());
        crop.convertTo(jacobian_data_[g][k], CV_32F, inv_scale);
      }
      if (!edge_rect.empty()) {
        cv::Mat padded = cv::Mat::zeros(spread.size(), image.type());
        image.copyTo(padded(cv::Rect(r, r, d.rect.width, d.rect.height)));
        cv::Mat e = edge_.apply(padded);
        e(edge_rect - spread.tl()).convertTo(jacobian_edge_[g][k], CV_32F, edge_factor);
      }
    });
    // Raw planes for sampleJacobian, called once per pixel and ghost.
    auto planes = [&](const std::vector<std::vector<cv::Mat>>& images) {
      std::vector<std::vector<JacobianPlane>> out(ghost_count_, std::vector<JacobianPlane>(parameters_per_ghost_));
      for (int g = 0; g < ghost_count_; ++g)
        for (int k = 0; k < parameters_per_ghost_; ++k)
          if (const cv::Mat& m = images[g][k]; !m.empty()) out[g][k] = {m.ptr<float>(), m.step1()};
      return out;
    };
    jacobian_data_planes_ = planes(jacobian_data_);
    jacobian_edge_planes_ = planes(jacobian_edge_);
  }
}

bool GroupCost::reaches(const model::GhostParameters& ghost) const {
  // The test renderGhosts applies to each ghost it is given (model_renderer.cpp renderInto).
  return !region_.empty() && (model::ghostPixelBounds(ghost, view_) & grown_).area() > 0;
}

void GroupCost::sampleResiduals(int sample, double* residuals) const {
  const cv::Point p = samples_[sample];
  const float* d = residual_data_.ptr<float>(p.y) + p.x * channels_;
  const float* e = residual_edge_.ptr<float>(p.y) + p.x * channels_;
  const bool edge_ok = edge_valid_.at<uchar>(p) != 0;
  for (int c = 0; c < channels_; ++c) {
    residuals[c] = d[c];
    residuals[channels_ + c] = edge_ok ? e[c] : 0.0;
  }
}

bool GroupCost::sampleJacobian(int sample, int ghost, double* jacobian) const {
  const cv::Point p = samples_[sample];
  const int n = parameters_per_ghost_;
  std::fill(jacobian, jacobian + 2 * channels_ * n, 0.0);
  if (!has_jacobians_ || jacobian_rect_.empty()) return false;
  const cv::Rect& data_rect = jacobian_rect_[ghost][0];
  const cv::Rect& edge_rect = jacobian_rect_[ghost][1];
  const bool edge_ok = edge_valid_.at<uchar>(p) != 0;
  auto copy = [&](const std::vector<JacobianPlane>& planes, cv::Point q, int first_row) {
    const size_t offset = static_cast<size_t>(q.x) * channels_;
    for (int k = 0; k < n; ++k) {
      const JacobianPlane& plane = planes[k];
      if (plane.data == nullptr) continue;
      const float* v = plane.data + static_cast<size_t>(q.y) * plane.step + offset;
      for (int c = 0; c < channels_; ++c) jacobian[(first_row + c) * n + k] = v[c];
    }
  };
  const bool data = data_rect.contains(p), edge = edge_ok && edge_rect.contains(p);
  if (data) copy(jacobian_data_planes_[ghost], p - data_rect.tl(), 0);
  if (edge) copy(jacobian_edge_planes_[ghost], p - edge_rect.tl(), channels_);
  return data || edge;
}

void GroupCost::priorResiduals(int ghost, const double* parameters, double* residuals,
                               double* jacobian) const {
  using namespace model::param;
  const int n = parameters_per_ghost_;
  if (jacobian) std::fill(jacobian, jacobian + kPriorParameters * n, 0.0);
  // The outline's left and right points, its axis, height and curvatures. Not Mx itself: with
  // P_L and P_R fixed, moving Mx only slides the top and bottom points along a nearly flat
  // outline, a direction the data barely sees and a prior on Mx would pull along.
  const double* s = prior_center_[ghost].data();
  const double* sigma = prior_sigma_[ghost].data();
  const double value[kPriorParameters] = {parameters[kMx] - parameters[kL], parameters[kMx] + parameters[kR],
                                          parameters[kMy], parameters[kH], parameters[kCl], parameters[kCr]};
  for (int k = 0; k < kPriorParameters; ++k) residuals[k] = (value[k] - s[k]) / sigma[k];
  if (!jacobian) return;
  auto set = [&](int row, int column, double v) { jacobian[row * n + column] = v / sigma[row]; };
  set(0, kMx, 1);
  set(0, kL, -1);
  set(1, kMx, 1);
  set(1, kR, 1);
  set(2, kMy, 1);
  set(3, kH, 1);
  set(4, kCl, 1);
  set(5, kCr, 1);
}

double GroupCost::loss(double u) const {
  if (options_.loss_scale <= 0) return u;
  const double b = options_.loss_scale * options_.loss_scale;
  return b * std::log1p(u / b);
}

double GroupCost::robustSample(int sample, double* residuals, double* const* jacobians,
                               bool* reached) const {
  const int m = residualsPerSample(), n = parameters_per_ghost_;
  sampleResiduals(sample, residuals);
  double sqrt_rho1 = 1, rest = 0;  // √ρ′(u) and ρ(u) − ρ′(u)·u
  if (options_.loss_scale > 0) {
    const double b = options_.loss_scale * options_.loss_scale;
    double u = 0;
    for (int i = 0; i < m; ++i) u += residuals[i] * residuals[i];
    const double x = u / b;
    sqrt_rho1 = 1 / std::sqrt(1 + x);
    rest = std::max(0.0, b * (std::log1p(x) - x / (1 + x)));
  }
  if (jacobians != nullptr)
    for (int g = 0; g < ghost_count_; ++g) {
      double* J = jacobians[g];
      const bool nonzero = J != nullptr && sampleJacobian(sample, g, J);
      if (reached) reached[g] = nonzero;
      if (nonzero && sqrt_rho1 != 1)
        for (int i = 0; i < m * n; ++i) J[i] *= sqrt_rho1;
    }
  for (int i = 0; i < m; ++i) residuals[i] *= sqrt_rho1;
  return rest;
}

double GroupCost::totalCost() const {
  if (residual_data_.empty()) return prior_cost_;
  double cost = 0;
  std::vector<double> r(2 * channels_);
  for (size_t i = 0; i < samples_.size(); ++i) {
    sampleResiduals(static_cast<int>(i), r.data());
    double u = 0;
    for (double v : r) u += v * v;
    cost += loss(u);
  }
  return 0.5 * cost + prior_cost_;
}

}  // namespace flarekit::fit
