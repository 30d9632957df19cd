#pragma once
// Noise-optimal HDR merge of bracketed linear RAW frames, per photosite, before demosaicing
// (docs/design.md, Hardware; Granados et al., CVPR 2010).
//
// For every photosite with samples vᵢ at exposure times tᵢ:
//   sᵢ = vᵢ − dᵢ          (dᵢ: the averaged dark frame for tᵢ, else the black level)
//   x̂  = Σ wᵢ sᵢ/tᵢ / Σ wᵢ,   wᵢ = tᵢ² / (g·tᵢ·x₀ + σ_r²)
// with g the gain (DN per electron = 1/gain_e_per_dn), σ_r the read noise in DN
// (read_noise_e/gain_e_per_dn), sᵢ in DN, and x₀ = Σ sᵢ / Σ tᵢ the
// shot-noise-optimal first estimate. Samples at or above `saturation_fraction` of the range
// (white − black) are excluded, and so are their immediate 8 neighbours (blooming). A photosite
// saturated in every exposure is flagged in the `saturated` mask and gets the lower bound
// (white − black)/t_min (never a silently wrong value). The result is x̂·gain_e_per_dn / output_scale:
// electrons per second, divided by a scale the rig gives (electrons per second per unit of scene
// radiance) so that simulated captures come out in the renderer's radiance units.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "acquisition/device.h"
#include "common/exr.h"

namespace flarekit::acquisition {

struct MergeOptions {
  // Conversion gain in photo-electrons per DN at the ISO used (> 0), from the rig's [sensor]
  // section (render/sensor.h: SensorModel::gainEPerDn()). Default 1.
  double gain_e_per_dn = 1.0;
  // Read noise in electrons RMS (≥ 0). Default 3.
  double read_noise_e = 3.0;
  // Samples with v − black ≥ saturation_fraction·(white − black) are saturated. In (0, 1],
  // default 0.95 (a margin below the clip for non-linearity close to full well).
  double saturation_fraction = 0.95;
  // Exclude the 8 neighbours of a saturated photosite too (blooming). Default true.
  bool exclude_neighbours = true;
  // Merged value = electrons per second / output_scale (> 0). Default 1 (electrons per second).
  double output_scale = 1.0;
  // Relative disagreement between measured and stated exposure ratios that triggers a warning
  // (> 0). Default 0.03.
  double ratio_tolerance = 0.03;
  // Photosites per exposure pair the ratio check needs before it judges (≥ 1). Default 1000.
  int ratio_min_samples = 1000;

  bool IsValid(std::string* error) const;
};

// One measured exposure ratio between consecutive exposures (sorted by time).
struct ExposureRatioCheck {
  double short_s = 0, long_s = 0;  // stated exposure times
  double stated_ratio = 0;         // long_s / short_s
  double measured_ratio = 0;       // median of per-photosite ratios on mid-tones; 0 = not enough
  long long samples = 0;           // photosites used
  bool agrees = true;              // within ratio_tolerance (or not enough samples to tell)
};

struct MergeResult {
  cv::Mat merged;     // CV_32FC1, one value per photosite (same layout as the input CFA)
  cv::Mat saturated;  // CV_8UC1, 1 where every exposure was saturated (merged is a lower bound)
  Cfa cfa = Cfa::kMono;
  std::vector<ExposureRatioCheck> ratio_checks;
  std::vector<std::string> warnings;  // one line each (ratio disagreements, ...)
  long long saturated_count = 0;
};

// Merges a bracket. Frames must share size, CFA, black and white levels; exposures must differ.
// `dark_frames` is empty or holds one CV_32FC1 averaged dark frame (DN, black included) per
// frame, in the same order. Throws InputError naming the problem (mismatched sizes, ...).
// Threads: TBB over rows.
MergeResult mergeBracket(const std::vector<RawFrame>& frames, const MergeOptions& options,
                         const std::vector<cv::Mat>& dark_frames = {});

// Simple bilinear demosaic of a merged CFA mosaic to CV_32FC3 (R,G,B). kMono gives CV_32FC1.
cv::Mat demosaicBilinear(const cv::Mat& mosaic, Cfa cfa);

// Metadata for the merged frame's EXR attributes (docs/design.md, Conventions).
struct FrameMetadata {
  double angle_deg = 0;                // flarekit.angle_deg (omitted when has_angle is false)
  bool has_angle = false;
  std::vector<double> exposures_s;     // flarekit.exposures_s; flarekit.exposure_s = the longest
  double iso = 0;                      // flarekit.iso
  double f_number = 0;                 // flarekit.f_number
  std::string camera, lens, rig;       // flarekit.camera, flarekit.lens, flarekit.rig
  double pixel_pitch_um = 0;           // flarekit.pixel_pitch_um (0 = unknown, omitted)
  double focal_length_mm = 0;          // flarekit.focal_length_mm (0 = unknown, omitted)
  std::string units = "electrons/s";   // flarekit.units
};

// The EXR of a merge: main layer Y (mono) or R,G,B (demosaiced), a one-channel `saturated`
// layer (1 where the value is a lower bound), and the flarekit.* attributes.
ExrImage mergedToExr(const MergeResult& result, const FrameMetadata& metadata);

}  // namespace flarekit::acquisition
