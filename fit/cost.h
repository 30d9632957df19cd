#pragma once
// The cost of a set of ghost parameters against one frame (Walch et al. 2018 §3.3.1):
//
//   cost = ½ Σ_p ρ( Σ_c r_data(p,c)² + r_edge(p,c)² )
//   r_data(p,c) = (Y_c(p) − X_c(p)) / s
//   r_edge(p,c) = √λ · ((E∗Y)_c(p) − (E∗X)_c(p)) / s
//
// with X the frame minus the ghosts modelled elsewhere, Y the model image of the ghosts being
// fitted, and E = G_σ2 ∗ Lap ∗ G_σ1 the paper's edge filter (Fig. 7: Gaussian pre-smoothing, a
// discrete Laplacian that responds to horizontal, vertical and diagonal edges, Gaussian
// post-smoothing so that nearby edges overlap), built from separable Gaussians. We multiply E by
// σ1² + σ2² (Lindeberg's scale normalisation of a Laplacian of Gaussian) so that λ = 1 weighs edges
// about as much as values whatever the σ.
//
// Normalisation (ours, the paper fits 8-bit-like images): HDR frames span orders of magnitude, so
// every residual is divided by the region scale s: the peak max(Ib, Ii) of the brightest ghost of
// the group at its seed (never below 3 noise σ). A ghost at 1e-4 of the light's brightness then
// weighs as much in its own fit as a bright one in its own, convergence tolerances mean the same
// for both, and the robust loss ρ has one scale for all: residuals well above the ghost's own
// brightness (the light's starburst, a brighter neighbour crossing the region) are outliers. (A
// percentile of the frame over the region would be ruled by exactly those.)
//
// ρ is Cauchy's loss ρ(u) = b·ln(1 + u/b), b = loss_scale², applied per pixel:
// what the model does not explain (the light's halo and starburst,
// neighbours, noise) then pulls on the fit with bounded force.
//
// Masks: pixels that are saturated or non-finite in the frame carry no data residual; edge
// residuals within the filter's radius of such a pixel are left out too (E∗X is wrong there).
//
// The region: the union of the fitted ghosts' pixel bounds (model/model_renderer.h
// ghostPixelBounds), grown by region_margin_px and clipped to the image. Regions larger than
// max_pixels are fitted on a coarser level of the frame (k×k pixel averages, k the smallest
// integer that brings the region within max_pixels): the model is rendered there through a
// ViewTransform of scale 1/k (parameters stay in capture pixels), which keeps the cost of a
// frame-filling ghost near that of a small one. Model images are point samples at each coarse
// pixel's centre, the frame's are area averages: for the smooth fall-offs of ghosts the two agree
// and an edge's position is unbiased by symmetry.
//
// Shape prior (ours): ½ Σ_k ((p_k − s_k)/σ_k)² over the outline's left and right points
// (Mx − L, Mx + R), its axis My, height h and curvatures Cl, Cr of every ghost, s its seed.
// Where the frame shows a parameter, the data's thousands of residuals outweigh it; where it does
// not (the part of a ghost beyond the frame's edge, the far side of a ghost cut by the light's
// clipped core) it keeps the parameter near its seed instead of letting it drift to a bound.
//
// Derivatives: the model is linear in nothing but Ib, Ii, yet every parameter's derivative image
// is analytic (model/'s renderer, envelope theorem at the fixed nearest point); E is linear, so
// the Jacobian of r_edge is E applied to those images.

#include <array>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/ghost_shape.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

struct CostOptions {
  double edge_weight = 1.0;      // λ: weight of the edge term against the MSE term (≥ 0)
  double edge_sigma1_px = 1.0;   // σ1: Gaussian before the Laplacian, pixels (> 0)
  double edge_sigma2_px = 1.0;   // σ2: Gaussian after the Laplacian, pixels (> 0)
  double region_margin_px = 6;   // the fitted region reaches this far beyond the ghosts (≥ 0)
  double loss_scale = 0.2;       // Cauchy loss scale in normalised units; 0 = plain least squares
  int max_pixels = 12000;        // larger regions are fitted on a coarser level (≥ 1000)
  // Shape prior (see the top of this file): σ of the prior on the outline's left and right points,
  // its axis and h as a fraction of the seed's size max(L, R, h) (plus 1 px), and on Cl, Cr in
  // curvature units; 0 = no prior.
  double prior_fraction = 1.0;
  // The region is the whole frame, whatever the ghosts reach (default false: their reach).
  bool whole_frame = false;

  bool IsValid(std::string* error) const;
};

// E = G_σ2 ∗ Lap ∗ G_σ1 (scale-normalised, see above), per channel, on CV_32FC1/3 images.
class EdgeFilter {
 public:
  explicit EdgeFilter(const CostOptions& options);
  // E∗image with replicated borders; same size and type.
  cv::Mat apply(const cv::Mat& image) const;
  // Pixels beyond which the filter's support is negligible (3σ of each Gaussian + 1).
  int radius() const { return radius_; }

 private:
  double sigma1_, sigma2_, scale_;
  int radius_;
};

// What the cost needs from one frame at one level, computed once per frame and level.
struct FrameData {
  cv::Mat image;       // X: CV_32FC(channels), non-finite set to 0
  cv::Mat valid;       // CV_8U 255 = finite and not saturated (at a coarse level: all k×k were)
  cv::Mat edge;        // E∗X
  cv::Mat edge_valid;  // CV_8U: valid, eroded by the filter radius
  double noise_sigma = 0;  // robust noise estimate of the background (luminance), same units
  int channels = 1;
  int factor = 1;      // k: one pixel here is k×k capture pixels

  static FrameData make(const cv::Mat& image, const cv::Mat& valid, const EdgeFilter& edge,
                        int factor = 1);
};

// A frame at every level a cost asks for (built on demand; thread-safe, so that costs built on
// several threads may share one).
class FramePyramid {
 public:
  // `noise_sigma` ≥ 0: the frame's noise σ at full resolution, σ/k at level k (k×k averages of
  // independent noise), for an image whose own statistics mislead the estimate (the frame minus
  // the light's image is exactly 0 wherever the light's estimate took the whole residual).
  // Negative: estimated from each level's image.
  FramePyramid(const cv::Mat& image, const cv::Mat& valid, const EdgeFilter& edge,
               double noise_sigma = -1);
  // The frame averaged over k×k blocks (k = 1: the frame itself). Sizes round down.
  const FrameData& level(int factor) const;
  const FrameData& full() const { return level(1); }
  cv::Size size() const { return image_.size(); }

 private:
  cv::Mat image_, valid_;
  const EdgeFilter& edge_;
  double noise_sigma_ = -1;
  mutable std::mutex mutex_;  // guards levels_ (elements stay where they are once built)
  mutable std::map<int, FrameData> levels_;
};

// Robust noise σ of an image: 1.4826 × the median absolute deviation of the luminance of its
// fainter half (the background), from a subsample. Biased wherever the background is not flat
// (frame-filling veils widen its spread). FramePyramid falls back on it when given no σ; the
// fitter gives its pyramids estimatePixelNoiseSigma's.
double estimateNoiseSigma(const cv::Mat& image, const cv::Mat& valid);

// The noise σ of the pixels: 1.4826 / √2 × the median absolute difference of horizontal
// neighbours (mean over channels), over every row. Ghosts, veils and the light's fall-off change
// little from one pixel to the next, and their edges are too few to move the median, so a frame
// full of veils does not inflate it. With block_px > 1, of neighbouring block_px × block_px means
// (wholly valid ones), times block_px: the photosites' noise where a demosaic has smoothed the
// pixels and made neighbours alike, so that a mono and an RGGB capture of the same light get the
// same σ.
double estimatePixelNoiseSigma(const cv::Mat& image, const cv::Mat& valid, int block_px = 1);

// The block width at which noise is measured independently of the sensor's layout: past a
// bilinear demosaic's 3×3 reach, where its smoothing no longer hides the photosites' noise.
inline constexpr int kNoiseBlockPx = 4;

// The cost of one group of ghosts (those that overlap, fitted jointly) in one frame. Holds the
// residual and Jacobian images at the last evaluated point. Not thread-safe itself; Ceres's
// residual blocks read it concurrently only after evaluate() returned.
class GroupCost {
 public:
  // `others`: the ghosts modelled outside this group (fixed), subtracted from X. `seeds` fix the
  // region, its level and the number of ghosts.
  // `prior_sigmas`, when given (one per seed), replace the shape prior's σ of each ghost: for its
  // left point, right point, axis, h, Cl and Cr, in that order.
  GroupCost(const FramePyramid& frame, const EdgeFilter& edge,
            std::span<const model::GhostParameters> others,
            std::span<const model::GhostParameters> seeds, const CostOptions& options,
            std::span<const std::array<double, 6>> prior_sigmas = {});

  int ghostCount() const { return ghost_count_; }
  int parametersPerGhost() const { return parameters_per_ghost_; }
  int channels() const { return channels_; }
  // The region in the level's pixels, and the level (k: capture pixels per level pixel).
  cv::Rect region() const { return region_; }
  int factor() const { return frame_.factor; }
  const model::ViewTransform& view() const { return view_; }
  double scale() const { return scale_; }
  // The largest intensity a ghost of this group may take: 20× the brightest valid pixel of the
  // region (at least 3 noise σ), since its peak may lie where no pixel is valid. Taken from the
  // data, not the seeds: where a ghost's deep inside lies beyond the frame its Ii is barely seen,
  // and nothing else keeps it from growing.
  double intensityLimit() const { return intensity_limit_; }
  double lossScale() const { return options_.loss_scale; }
  // The capture's size (full resolution).
  cv::Size imageSize() const { return image_size_; }
  // Sampled pixels, region coordinates (level pixels).
  const std::vector<cv::Point>& samples() const { return samples_; }
  // Residuals per sample: 2·channels (data then edge per channel).
  int residualsPerSample() const { return 2 * channels_; }

  // Evaluates residual images (and Jacobian images when asked) at `ghosts`; returns the cost.
  double evaluate(std::span<const model::GhostParameters> ghosts, bool jacobians);
  // Evaluates from flat parameter vectors (one per ghost).
  double evaluate(const std::vector<const double*>& parameters, bool jacobians);
  // As evaluate(), without summing the cost: for Ceres, which sums its residual blocks itself.
  void prepare(const std::vector<const double*>& parameters, bool jacobians);
  // Number of evaluate() calls so far (cost evaluations, with or without derivatives).
  long long evaluations() const { return evaluations_; }

  // Per-sample residuals and Jacobian rows at the last evaluated point (derivatives only when the
  // last evaluate() computed them): residuals[2·channels], jacobian of ghost g row-major
  // [2·channels × parametersPerGhost()].
  void sampleResiduals(int sample, double* residuals) const;
  // sampleJacobian returns false where the rows are all zero (the pixel is beyond the ghost's reach).
  bool sampleJacobian(int sample, int ghost, double* jacobian) const;
  bool hasJacobians() const { return has_jacobians_; }

  // The shape prior (see above): residuals per ghost, and their Jacobian row-major
  // [priorResidualCount() × parametersPerGhost()] when `jacobian` is not null.
  int priorResidualCount() const { return prior_sigma_.empty() ? 0 : kPriorParameters; }
  void priorResiduals(int ghost, const double* parameters, double* residuals, double* jacobian) const;

  // The Cauchy loss ρ(u) of this cost (u = squared norm of a sample's residuals).
  double loss(double squared_norm) const;
  // A sample's residuals and, when `jacobians` is not null (one row-major [2·channels ×
  // parametersPerGhost()] array per ghost, null entries skipped), their Jacobians, weighted as
  // Ceres weights a residual block with this loss (its Corrector, Triggs et al. 2000, for a loss
  // with ρ″ ≤ 0 like Cauchy's): r̃ = √ρ′(u)·r, J̃ = √ρ′(u)·J. Returns ρ(u) − ρ′(u)·u ≥ 0, the part of
  // the sample's cost ½ρ(u) that ½‖r̃‖² leaves out. A residual block of many samples then has the
  // loss per sample, the Gauss–Newton model and gradient of per-sample blocks, and its exact cost
  // with one more residual, √(Σ of these), constant in the parameters. `reached` (one per ghost,
  // when not null) says whose Jacobian rows are not all zero (the pixel is within its reach).
  double robustSample(int sample, double* residuals, double* const* jacobians,
                      bool* reached = nullptr) const;
  // The cost from the stored residuals.
  double totalCost() const;

  // The model image over the region at the last evaluated point (CV_32FC(channels)).
  const cv::Mat& modelImage() const { return model_; }
  // The target X − others over the region.
  const cv::Mat& target() const { return target_; }
  // Whether `ghost`, as one of the others, reaches the pixels the others are rendered over (the
  // region grown by the filter's radius, at this cost's level). A ghost that does not leaves the
  // cost unchanged bit for bit, whatever its parameters: the renderer skips it.
  bool reaches(const model::GhostParameters& ghost) const;

 private:
  const FrameData& frame_;
  const EdgeFilter& edge_;
  cv::Size image_size_;
  model::ViewTransform view_;
  CostOptions options_;
  int ghost_count_ = 0, parameters_per_ghost_ = 0, channels_ = 1;
  cv::Rect region_;        // in the image
  cv::Rect grown_;         // region grown by the filter radius (may leave the image)
  double scale_ = 1;
  double intensity_limit_ = 1;
  std::vector<cv::Point> samples_;
  cv::Mat target_, target_edge_;  // over region
  cv::Mat data_valid_, edge_valid_;
  cv::Mat model_;                 // Y over region
  cv::Mat residual_data_, residual_edge_;  // CV_32FC(channels), normalised
  // Jacobian images [ghost][parameter], normalised; empty Mat = zero.
  std::vector<std::vector<cv::Mat>> jacobian_data_, jacobian_edge_;
  std::vector<std::vector<cv::Rect>> jacobian_rect_;  // where each image is non-zero (region coords)
  struct JacobianPlane {
    const float* data = nullptr;  // null: the image is zero
    size_t step = 0;              // floats per row
  };
  std::vector<std::vector<JacobianPlane>> jacobian_data_planes_, jacobian_edge_planes_;  // [ghost][parameter]
  bool has_jacobians_ = false;
  long long evaluations_ = 0;
  // evaluate() but the cost sum.
  void evaluateImages(std::span<const model::GhostParameters> ghosts, bool jacobians);
  // Shape prior on P_L = Mx − L, P_R = Mx + R, My, h, Cl, Cr.
  static constexpr int kPriorParameters = 6;
  std::vector<std::vector<double>> prior_center_, prior_sigma_;  // [ghost][k]
  double prior_cost_ = 0;  // at the last evaluated point
};

// A ghost's outline is sharp: its outside fall-off Fo is at most this fraction of the image's
// diagonal. The smooth glow under the ghosts is the frame's pedestal (model/pedestal.h), not a
// ghost's soft edge.
inline constexpr double kSharpOutsideFalloffFraction = 0.03;

// The extra bounds a fitter uses on top of model::parameterBounds: lengths and fall-offs within
// the image's diagonal, the centre within one image size of the frame, intensities up to
// `intensity_limit` (GroupCost::intensityLimit), Fo within kSharpOutsideFalloffFraction of the
// diagonal. The exponents Ei, Eo keep the model's [0.1, 10].
model::ParameterBounds fitBounds(int index, int channels, cv::Size image_size, double intensity_limit);

// Every parameter's fitBounds, in vector order, for a ghost of `cost`'s group: the bounds the
// solvers keep it within.
std::vector<model::ParameterBounds> fitBounds(const GroupCost& cost);

}  // namespace flarekit::fit
