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
// ρ is Cauchy's loss ρ(u) = b·ln(1 + u/b), b = loss_scale², applied per pixel
// (shared/FITTING_NOTES.md: per-pixel blocks with Cauchy 0.2 cut the bias from an unmodelled
// bright blob from 0.74 px to 0.13 px): what the model does not explain (the light's halo and
// starburst, neighbours, noise) then pulls on the fit with bounded force.
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
// (Mx − L, Mx + R), its axis My, height h and curvatures Cl, Cr of every ghost, s its seed (in tracking, the extrapolation from the neighbouring frames).
// Where the frame shows a parameter, the data's thousands of residuals outweigh it; where it does
// not (the part of a ghost beyond the frame's edge, the far side of a ghost cut by the light's
// clipped core) it keeps the parameter where the track says instead of letting it drift to a
// bound: measured on the Heliar capture, a ghost cropped by the frame had its unseen R run from
// 218 px to 714 px over two frames without it. A tighter prior on the unseen parts only (σ × 0.1
// for an outline point beyond the frame's edge, and for h when both its ends are) held the large
// veils' sides no better where it counts: on the 640×427 captures over λ × 0.98–1.02 (recall % /
// precision % / median PSNR dB / median centroid error px, bench/fit_accuracy.sh), Heliar
// 77.6 / 84.1 / 24.2 / 6.6 against 77.2 / 87.0 / 25.4 / 8.0, Tessar 84.2 / 71.1 / 25.2 / 10.0
// against 82.9 / 72.5 / 25.2 / 10.9.
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

// A frame at every level a cost asks for (built on demand; thread-safe: the capture fitter builds
// the costs of a frame's ghost groups concurrently).
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
// fainter half (the background), from a subsample. Known bias (measured, not yet changed because
// detection levels and the fitter's tests are tuned to it): 0.6× the true σ on the Gaussian CLI
// test frames (0.0061 for 0.01), 2.7× the background's on lit Heliar frames, 5–10× once the light
// has left the frame (14–16°: frame-filling veils make the spread); an estimate from differences
// of horizontal neighbours was within 30 % on all three (estimatePixelNoiseSigma). The fitter
// counts in that one by default since glare has its own end rules (FitOptions::pixel_noise, whose
// comment has the figures; this one with --no-pixel-noise). Switched to the pixel noise first, its
// detection levels (in σ) find the sum of the faint veils as one frame-filling blob, and on the
// 640×427 0–30° captures the median PSNR went 22.2 → 25.2 dB on the Heliar (inside the
// 22.2–25.1 dB that λ ± 1 % alone gives) but 22.9 → 19.3 dB on the Tessar, whose precision fell
// 80 → 68 %. Measured again with the fitter
// of 6528a83 (model's recall / precision / median PSNR / median centroid error, means over
// λ × 0.99, 1, 1.01; this estimate: Heliar 71.2 / 86.5 % / 24.0 dB / 8.8 px, Tessar 51.4 / 78.0 /
// 22.5 / 15.6), the Tessar's recall rises most, the precision and PSNR fall:
//   pixel noise everywhere:  Heliar 70.2 / 81.1 / 21.8 / 8.2,  Tessar 71.2 / 66.7 / 21.6 / 10.9;
//   so, lowest level 12σ:    Heliar 69.6 / 85.1 / 21.9 / 10.1, Tessar 58.0 / 63.8 / 23.1 / 11.3;
//   only where tracks end:   Heliar 74.7 / 85.0 / 21.6 / 11.1, Tessar 52.7 / 74.9 / 22.3 / 14.9;
//   everywhere but the light: Heliar 68.8 / 81.9 / 24.0 / 8.5, Tessar 63.7 / 68.9 / 21.9 / 11.4
//   (its zone and symmetric part on this estimate);
//   everywhere, detection also kept off the light's residue (FitOptions::pixel_noise, 9bddd08):
//                            Heliar 74.1 / 82.4 / 23.3 / 7.9,  Tessar 71.1 / 69.0 / 21.9 / 10.1.
// Variants of the last (scratch switches on its fitter), none better on all four figures:
//   the floor at 0.5 × the light: Heliar 75.3 / 83.4 / 23.4 / 9.5, Tessar 62.8 / 63.9 / 22.6 /
//     11.2;
//   at 0.1 × the light and the ghosts modelled so far (the model's own error): Heliar 71.4 /
//     83.7 / 22.1 / 9.0, Tessar 72.1 / 64.1 / 21.7 / 10.8;
//   the cost's scale floor (3σ) on this estimate: Heliar 70.0 / 77.9 / 23.1 / 11.8, Tessar 67.5 /
//     64.2 / 22.6 / 11.9 (so, without the light's residue floor: Heliar 72.7 / 80.5 / 22.3 / 6.5,
//     Tessar 63.2 / 66.7 / 23.0 / 12.4);
//   detection levels in a σ(I) map instead of the floor, the pixel noise binned by the smoothed
//     brightness (shot noise, and the light's steep halo, raise it near the core): Heliar 64.4 /
//     82.3 / 20.9 / 9.4, Tessar 62.0 / 76.4 / 21.5 / 11.5;
//   this estimate while the light is found in the frame, the pixel noise after (no floor): Heliar
//     73.6 / 82.7 / 22.5 / 7.3, Tessar 65.5 / 74.5 / 21.4 / 12.1.
// The first three's fits took 55–96 s wall each, against 47–73 s with this estimate; the later
// ones' ran beside builds and other fits, so their times are not compared.
double estimateNoiseSigma(const cv::Mat& image, const cv::Mat& valid);

// The noise σ of the pixels: 1.4826 / √2 × the median absolute difference of horizontal
// neighbours (mean over channels), over every row. Ghosts, veils and the light's fall-off change
// little from one pixel to the next, and their edges are too few to move the median, so a frame
// full of veils does not inflate it: on the Heliar 640×427 capture, 0–28°, it was within 10 % of
// the σ of frame − noise-free radiance, where estimateNoiseSigma was 2–9.5× that.
double estimatePixelNoiseSigma(const cv::Mat& image, const cv::Mat& valid);

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
  // region (at least 3 noise σ). Not the seeds' peak: where a ghost's deep inside lies beyond the
  // frame its Ii is barely seen, and a bound that follows the seed let it grow 20× per frame of a
  // track (Heliar ghost 21: Ii from 3e-4 to 47 over 1.2°, the model's disc white in every view).
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
  // As evaluate(), without summing the cost: for Ceres, which sums its residual blocks itself (the
  // sum, a log1p per sample, was 2.5 % of a capture fit's CPU time, thrown away).
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
// diagonal. Veiling glare is the exception (isGlare).
inline constexpr double kSharpOutsideFalloffFraction = 0.03;

// Veiling glare: a ghost whose outside fall-off is longer than twice a sharp outline's. The
// frame's glow of many veils, each too faint to see, sums to a pedestal under the ghosts; with
// every Fo free, the fitter drew that pedestal by softening the outlines of the ghosts it held
// (Heliar 640×427 at 12°: one ghost, Fo 1048 px, 85 px from the veil it should have held), and
// without a glare the pedestal is not drawn at all (median PSNR 17 dB instead of 23.6). A glare
// is seeded as one (fit/detection.h detectGlare), keeps its long fall-off, and is held flat over
// the frame by its bounds (fitBounds): its outline holds the frame, and only its intensity is
// fitted. With its outline and fall-offs free, the one glare of a frame drew the large sharp
// veils' bodies too, softly: on the Heliar 640×427 capture at λ × 1 it was the only ghost of 13
// of the 17 frames at 12–15.2°, and ghost 19, a disc 18σ bright there, was found in 4 of the 25
// frames at 12–16.8° (held flat: in 23). On the 640×427 captures (0–30° at 0.2°), means over
// λ × 0.98, 0.99, 1, 1.01, 1.02 of the model's recall / precision / median PSNR / median
// centroid error, glare free → flat (bench/fit_accuracy.sh):
//   Heliar Tronnier: 73.1 → 77.2 %, 81.6 → 87.0 %, 25.8 → 25.4 dB, 7.7 → 8.0 px;
//   Brendel Tessar:  75.0 → 82.9 %, 69.3 → 72.5 %, 25.5 → 25.2 dB, 10.6 → 10.9 px;
// the frames' own fits 72.2 → 78.9 %, 79.5 → 87.2 %, 28.7 → 28.8 dB, 7.6 → 6.9 px and
// 75.8 → 84.6 %, 66.6 → 67.4 %, 27.6 → 28.3 dB, 9.6 → 11.1 px; a fit took 33–37 s and 45–52 s
// instead of 54 and 52 s (λ × 1). A smooth ramp instead (an inside fall-off of at least W + H,
// so that the frame lies within it) gave the Heliar 77.9 / 86.4 / 25.4 / 8.4 over the five λ and
// the Tessar 73.3–76.9 % recall and 62.6–65.2 % precision over λ × 0.98–1, at 79–87 s a fit.
bool isGlare(const model::GhostParameters& ghost, cv::Size image_size);

// The extra bounds a fitter uses on top of model::parameterBounds: lengths and fall-offs within
// the image's diagonal, the centre within one image size of the frame, intensities up to
// `intensity_limit` (GroupCost::intensityLimit); Fo within kSharpOutsideFalloffFraction of the
// diagonal unless `glare`. A glare's bounds hold it flat over the frame (isGlare), within the
// model's own: for frames up to W + H = 4000 px, centre in the frame, half-sizes 2–4 × (W + H), Fi
// at most (W + H) / 2, Fo 0.4–1 × the diagonal (cost.cpp glareBounds for larger frames).
// The exponents Ei, Eo keep the model's [0.1, 10]. Held at ≥ 0.5 for sharp ghosts (so that no
// ghost becomes a rim thinner than a pixel, Ei = Eo = 0.1), the Heliar 640×427 model over
// λ × 0.98–1.02 gave 72.6 / 87.3 / 25.3 / 7.2 (recall % / precision % / median PSNR dB / median
// centroid error px) against 77.2 / 87.0 / 25.4 / 8.0, and the Tessar 72.9 % recall at λ × 0.98
// against 83.0 (the flat glare's fitter, bench/fit_accuracy.sh).
model::ParameterBounds fitBounds(int index, int channels, cv::Size image_size, double intensity_limit,
                                 bool glare);

// Sets a glare seed's centre, half-sizes and fall-offs for a frame of `image_size`, within its
// fitBounds there (glare): centred on the frame, half-sizes at their lower bound (the smallest
// outline that holds the frame flat), an inside fall-off of 0.15 × the half diagonal and an
// outside one of the half diagonal, each clamped to its bounds. The glare's bounds are not
// proportional to the frame (cost.cpp glareBounds), so a seed shaped at a detection level and
// scaled up is shaped again at the capture's size. Its intensities are left as they are.
void shapeGlareSeed(cv::Size image_size, model::GhostParameters* glare);

// Every parameter's fitBounds, in vector order, for a ghost of `cost`'s group seeded as `seed`
// (glare or not as the seed is): the bounds the solvers keep it within.
std::vector<model::ParameterBounds> fitBounds(const GroupCost& cost, const model::GhostParameters& seed);

}  // namespace flarekit::fit
