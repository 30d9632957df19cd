#pragma once
// Automatic key frames and initial parameters (Walch et al. 2018 §3.3.2 sets them by hand).
//
// Ghosts lie on the line through the light's image and the image centre and are mirror-symmetric
// about it (shared/FITTING_NOTES.md). Detection works on the residual: the frame minus every ghost
// already modelled. It finds the light's own image (its saturated core, halo and starburst) and
// keeps out of it, smooths the residual, thresholds it at several levels (HDR ghosts span orders
// of magnitude: a bright ghost and a faint one beside it separate at some level), and turns every
// connected blob whose centre lies near the axis into a seed: centre from the blob's centroid on
// the axis, L, R, h from its box, Ib and Ii from its values, an ellipse (Cl = Cr = 0.5523).

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/ghost_shape.h"

namespace flarekit::fit {

struct DetectionOptions {
  // Gaussian smoothing of the residual before thresholding, pixels (> 0).
  double smoothing_px = 2.0;
  // Threshold levels in noise σ of the (unsmoothed) frame, tried from the highest down; a blob
  // is kept at the first level where it is separate from the light's zone. Each > 0.
  // A level at 10σ between 20 and 6 (where a faint body beside a bright ghost might separate
  // from the frame-wide 6σ blob: Brendel Tessar ghost 15 at 8°, whose hexagonal body no
  // candidate takes) did not help. Means over λ × 0.99, 1, 1.01 on the 640×427 captures
  // (recall / precision / median PSNR / median centroid error), this level set → with 10σ:
  //   Heliar Tronnier: 71.2 / 86.5 % / 24.0 dB / 8.8 px → 70.6 / 85.7 / 24.0 / 7.9;
  //   Brendel Tessar:  51.4 / 78.0 / 22.5 / 15.6 → 54.3 / 80.0 / 21.1 / 19.4.
  // A level below 6σ, for the faint veils the PSNR needs (fit/evaluation.h
  // CeilingOptions::fit_factor: the Tessar's ceiling is 30.0 dB above 6σ, 33.6 above 4σ), gained
  // within the spread over λ and cost time. Means over λ × 0.98–1.02 (bench/fit_accuracy.sh),
  // this level set → with 3σ → with 4σ:
  //   Heliar: 74.9 / 81.6 / 25.1 / 6.9 → 78.2 / 82.0 / 25.1 / 6.2 → 80.3 / 78.7 / 23.9 / 6.0;
  //   Tessar: 78.3 / 60.4 / 25.2 / 11.3 → 79.0 / 60.0 / 26.3 / 10.7 → 78.1 / 58.7 / 25.7 / 12.4.
  // With 3σ the fits took 52–72 s, beyond the 60 s a capture may take (λ × 1, each run alone:
  // Heliar 55.8 s against 37.5, Tessar 64.5 against 55.6; 157 candidates at 3σ on the Tessar, 38
  // kept); without its blobs under 1000 px, the Tessar still took 66.8 s.
  std::vector<double> levels_sigma = {1000, 100, 20, 6};
  // Smallest blob, pixels (≥ 1).
  int min_area_px = 30;
  // A blob's centroid may lie at most this far from the axis (light–centre line), as a fraction
  // of the image height (> 0).
  // 0.06 let starburst lines 27 px off the axis through (Heliar capture, 8°); the true ghosts'
  // centres lie within 0.5 px of it there.
  double max_axis_offset = 0.03;
  // The light's zone reaches where the azimuthal median around the light falls below this many
  // noise σ above the frame's median, times zone_margin (≥ 1). Blobs inside are ignored.
  double light_zone_sigma = 50;
  double zone_margin = 1.15;
  // At most this many new ghosts per frame (≥ 1). At 2, over λ × 0.98–1.02 on the 640×427
  // captures (recall % / precision % / median PSNR dB / median centroid error px of the model,
  // bench/fit_accuracy.sh), fewer pieces of ghosts were seeded (fit/evaluation.h Unmatched), but
  // the Heliar lost ghosts: 74.9 / 81.6 / 25.1 / 6.9 → 69.0 / 89.9 / 23.8 / 6.2; Tessar
  // 78.3 / 60.4 / 25.2 / 11.3 → 78.1 / 63.1 / 25.5 / 11.7.
  int max_new_per_frame = 4;
  // Separate the light's own image by its point symmetry (estimateLightImage) instead of keeping
  // out of the whole light zone: detection then keeps out of the clipped core only (its radius ×
  // core_margin), and ghosts beside or inside the halo and starburst are found. Measured on
  // every-5th-frame 640×427 captures, 0–30° (recall / precision / median PSNR / median centroid
  // error), against keeping out of the zone: Heliar 23.3 % / 69.5 % / 20.4 dB / 21.7 px against
  // 31.7 % / 88.9 % / 18.3 dB / 29.8 px, Tessar 40.4 % / 81.8 % / 19.5 dB / 7.8 px against
  // 40.4 % / 50 % / 13.6 dB / 33.3 px: without it, model ghosts drew the starburst.
  bool light_symmetry = true;
  double core_margin = 1.5;  // (≥ 1)
  // Gaussian smoothing of the residual before the symmetric part is taken, pixels (≥ 0; 0 =
  // none). The minimum of two noisy values is biased low by 0.56 σ, which smoothing would shrink,
  // but the starburst's lines are a pixel wide: frame − S then keeps their edges. Measured on the
  // Heliar capture (RMS of frame − S − true ghosts, 2°–6°): 0.46–0.52e-3 unsmoothed, 0.77–0.84e-3
  // at 0.5 px, 1.65–1.68e-3 at 1 px.
  double light_smoothing_px = 0;
  // With the pixel noise (FitOptions::pixel_noise), a blob's pixels must also stand above this
  // fraction of the light's estimated image there (estimateLightImage) (≥ 0; 0 = no such floor).
  // The frame minus that estimate keeps a residue that grows with the light (its shot noise, the
  // minimum's bias, wherever the light is not point-symmetric): near the core it stands far above
  // the frame's pixel noise, and without the floor the fits drew it as ghosts. 0.5 measured worse
  // than 0.25 (FitOptions::pixel_noise).
  double light_residue_fraction = 0.25;
  // Also seed veils that fill the frame (detectVeilEdges; `flarekit fit --veils`). Off by
  // default, because the fitter is chaotic (a 1 % change of λ moves its median PSNR by 3 dB) and,
  // over three fits each (λ × 0.99, 1, 1.01) of the 640×427 captures (0–30° at 0.2°), the veils
  // did not improve every figure. Means without → with:
  //   Heliar Tronnier: recall 50.7 → 57.3 %, precision 82.3 → 79.4 %, median PSNR 23.6 → 22.2 dB,
  //                    median centroid error 10.4 → 12.9 px;
  //   Brendel Tessar:  47.4 → 48.1 %, 80.7 → 81.5 %, 20.5 → 20.7 dB, 21.3 → 14.7 px.
  // And the physics ranking of the data_synthetic fit (tests/physics_ranking_test.cpp, ρ ≥ 0.9)
  // fell from 0.91 to 0.78, and to 0.42–0.98 under 1 % changes of λ and the shape prior
  // (0.92–0.97 without): veils seeded while the light was in the frame changed the model's mean flux
  // at 0–8° by up to 2× (7.4°: 0.042 against 0.021), where the renderer's falls steadily with θ.
  // (All measured with the fitter of commit fedfafa.) Measured again with that of 6441292, the
  // same way, they still do not: Heliar 64.7 → 67.1 %, 86.0 → 84.4 %, 26.1 → 25.2 dB,
  // 8.3 → 7.5 px; Tessar 52.9 → 53.7 %, 79.0 → 78.0 %, 23.6 → 23.1 dB, 11.1 → 12.4 px. Nor with
  // that of 484f1fe: Heliar 71.2 → 70.4 %, 86.5 → 86.5 %, 24.0 → 24.7 dB, 8.8 → 9.5 px;
  // Tessar 51.4 → 53.7 %, 78.0 → 77.2 %, 22.5 → 22.5 dB, 15.6 → 14.9 px. Nor with that of
  // fe2b4d2 and fit-eval's glare left out of the matching (fit/evaluation.h), means over λ × 0.98,
  // 0.99, 1, 1.01, 1.02: Heliar 68.5 → 73.2 %, 82.1 → 79.4 %, 25.4 → 24.5 dB, 7.4 → 6.3 px;
  // Tessar 66.9 → 66.3 %, 62.5 → 59.1 %, 25.2 → 25.6 dB, 11.1 → 13.0 px.
  bool find_veils = false;
  // Seed veiling glare (detectGlare; fit/cost.h isGlare) where the residual's median over the frame
  // is above glare_sigma noise σ and no glare is modelled yet.
  bool find_glare = true;
  double glare_sigma = 2;
  // The search: the residual is averaged over a band of 2 veil_band_px + 1 pixels across the
  // flare axis, a step is the difference of the means over veil_window_px on either side of a
  // point, and steps of at least veil_step_sigma noise σ seed a veil.
  int veil_band_px = 8;
  int veil_window_px = 12;
  double veil_step_sigma = 6;

  bool IsValid(std::string* error) const;
};

// The light's image in a frame.
struct LightImage {
  bool found = false;        // false: the light is outside the frame (no saturated core)
  cv::Point2d center;        // image pixels
  double zone_radius_px = 0; // core + halo + starburst: detection keeps out of this disc
  double core_radius_px = 0; // the clipped core (radius of a disc of its area)
  // The core is cut by the frame's border, and centre and radii come from the frames beside it
  // (followLight), not from this frame's saturated pixels.
  bool predicted = false;

  // The same light on a level of k×k pixel averages (positions and radii divided by k).
  LightImage atLevel(int factor) const {
    LightImage l = *this;
    l.center /= factor;
    l.zone_radius_px /= factor;
    l.core_radius_px /= factor;
    return l;
  }
};

// Distance of `point` from the flare axis of an image of `size`: the line through the light's
// image and the image centre (Walch et al. 2018 §3.2: ghosts are mirror-symmetric about it),
// horizontal when the light is outside the frame or within 5 % of the width from the centre.
double flareAxisOffset(cv::Point2d point, const LightImage& light, cv::Size size);

// Finds the light: the centroid of the largest saturated (or brightest) blob; its zone from the
// azimuthal median profile around it. `valid` is the frame's mask (0 = saturated / non-finite).
LightImage findLight(const cv::Mat& luminance, const cv::Mat& valid, double noise_sigma,
                     const DetectionOptions& options);

// The light in every frame of a sweep, from what findLight found in each (`found`, at the rig
// angles `angles_deg`, in degrees). Where the clipped core touches the frame's border, the
// centroid of its visible part is not the light's centre: on the Heliar 640×427 capture findLight
// put it at x = 13–33 px over 9.2–11.8° while the light left the frame by 6 px per 0.2°, and its y
// wandered by up to 30 px as the starburst's spikes became the largest clipped blob. S
// (estimateLightImage) about that centre left the spikes in the data, and they were fitted as
// ghosts 10–100× brighter than the flare (PSNR against the noise-free flare −6 to 18 dB at λ ×
// 0.99). There the light is the straight line through its centres in the (up to) 8 frames nearest
// in angle whose core, of at least the sweep's median core radius, is clear of the border by
// 2 px, within 3° (the image moves ∝ tan θ, nearly straight over a few degrees), with their mean
// core and zone radii; `predicted` is set. A frame whose predicted zone misses the image, or with
// too few clear frames near it, keeps what was found.
std::vector<LightImage> followLight(std::vector<LightImage> found, const std::vector<double>& angles_deg,
                                    cv::Size size);

// `valid` (CV_8U, the frame's mask) without the pixels where the light cannot be told from the
// ghosts: for a predicted light (followLight), those within its zone whose mirror point about the
// light lies outside the frame. S has no reflection to compare them with, and the radial profile
// it falls back on (estimateLightImage) does not hold where the core itself is cut. `valid` for a
// light that was found.
cv::Mat validBesideLight(const cv::Mat& valid, const LightImage& light);

// The light's own image in `residual` (CV_32FC1/3: the frame minus the ghosts modelled so far):
// its clipped core, halo and starburst. Those are point-symmetric about the light's image centre c
// (the starburst is the power spectrum of the aperture, |F|² of a real function; the halo is
// radial), while the ghosts lie elsewhere on the axis through c and the image centre (Walch et al.
// 2018 §3.2, Fig. 3) and are not, so the light is estimated as
//   S(p) = max(0, min(R̃(p), R̃(2c − p)))
// with R̃ the residual smoothed by light_smoothing_px: where a ghost covers p, its mirror point
// shows the light alone. Where 2c − p is saturated (the core's reflection: p is beside the core,
// ruled by the light) S = R̃(p). Where 2c − p is outside the frame (the light near its border)
// the light is taken as the same in every direction (a radial halo, spikes as long in every
// direction): S = min(R̃(p), P(|p − c|)), P the largest S over the pixels at that
// distance whose mirror point is in the frame, non-increasing outwards (0 where there are none).
// A ghost centred on c itself (θ ≈ 0) is symmetric too and goes into S; the fitter's tracks and
// shape prior carry ghosts through those frames. Returns zeros when the light
// is not found. S is kept only over the light's own region: the part of S > light_zone_sigma ×
// `noise_sigma` connected to the core (beyond it, the symmetric part is the veils'). Same size and
// type as `residual`.
cv::Mat estimateLightImage(const cv::Mat& residual, const cv::Mat& valid, const LightImage& light,
                           double noise_sigma, const DetectionOptions& options);

// A candidate ghost.
struct Detection {
  model::GhostParameters seed;
  cv::Rect blob;            // the blob's box
  cv::Mat mask;             // CV_8U over `blob`: the blob's pixels
  double peak = 0;          // its highest smoothed residual
  double level_sigma = 0;   // the level it was found at
};

// Blobs of `residual` (CV_32FC1 luminance; frame minus the modelled ghosts), brightest first.
// Seeds are grey (channels = 1); the caller spreads them over colour channels. Where `floor` is
// given (CV_32FC1, the residual's size), a blob's pixels must also stand above it.
std::vector<Detection> detectGhosts(const cv::Mat& residual, const cv::Mat& valid,
                                    double noise_sigma, const LightImage& light,
                                    const DetectionOptions& options,
                                    const cv::Mat& floor = cv::Mat());

// Veiling glare (fit/cost.h isGlare): when the median of `residual` over the valid pixels away from
// the light's clipped core is above glare_sigma × `noise_sigma`, a seed flat over the frame at
// that median (Ib = Ii), shaped for the residual's size by fit/cost.h shapeGlareSeed (centred on
// the flare axis at the image centre, its outline holding the frame within the glare's bounds);
// its blob is those pixels. Nothing otherwise.
std::optional<Detection> detectGlare(const cv::Mat& residual, const cv::Mat& valid, double noise_sigma,
                                     const LightImage& light, const DetectionOptions& options);

// Veils whose outline crosses the frame but whose body fills it: on the 640×427 captures the
// detection's largest misses (Heliar Tronnier ghosts 19 and 2, Brendel Tessar 2 and 4, between
// them three quarters of the missed ghosts over 0–30°) are discs and hexagons hundreds of pixels
// across of which the frame shows one arc or one vertex, on a pedestal of fainter veils. The
// residual has no blob there, only a step: every ghost is mirror-symmetric about the flare axis
// (Walch et al. 2018 §3.2), so its outline crosses the axis, and along the axis the residual
// rises by the veil's intensity where it does. A step whose bright side stays up to the frame's
// border (the veil goes on beyond it) seeds a disc of the frame's height there, reaching away
// from the step; its blob is the band on the bright side. Steps near the light's core are left
// out. Strongest first.
std::vector<Detection> detectVeilEdges(const cv::Mat& residual, const cv::Mat& valid,
                                       double noise_sigma, const LightImage& light,
                                       const DetectionOptions& options);

}  // namespace flarekit::fit
