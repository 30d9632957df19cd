#pragma once
// Lab figures of a capture per light angle θ (`flarekit metrics`, docs/metrics.md): how much
// flare a lens makes around a point light, normalised by the light itself, and how far the
// capture can be trusted. The definitions follow ISO 9358 (the glare spread function of a small
// source, integrated outside its core), the Imatest stray-light metric image and its count metrics
// (the frame normalised by the light's direct image, pixels above thresholds), and IEEE Std
// 2020-2024's normalised flare; docs/metrics.md says which figure follows what and where FlareKit
// differs.
//
// Per frame (θ), on luminance:
//   flare flux ratio   Σ of the frame outside the light's core / the light's flux
//   ghost peak         the brightest point outside the light's own image (the light's pattern
//                      taken out, fit/horizon.h) / the light's peak, also in stops (log2)
//   share above k      of the frame's pixels outside the core, the share ≥ k × the light's peak,
//                      k = 1e-3, 1e-4, 1e-5
//   visible ghosts     the ghosts the fitter finds in the frame (fit/ghost_candidates.h); in the
//                      truth, ghosts whose peak exceeds visible_factor × the frame's noise σ (as
//                      fit-eval counts them); with a model, its ghosts above that
//   light flux ratio   the frame's own light flux (its light exposure) / the reference's: the
//                      lens's fall-off with θ, and any drift
//   ghost flux         with a model: each ghost's Σ / the light's flux (and in the truth, each
//                      true ghost's)
//
// The light's flux and peak (the normaliser): from the capture's light exposure (acquisition/
// capture.h) at the reference frame, the one whose light lies nearest the optical zero and whole
// in the frame; its flux is common/light_spot.h's (the disc of an eighth of the image diagonal).
// Without light exposures, the merged frame's clipped core only gives lower bounds: the figures
// are then upper bounds and say so. Inside the merged frames' clipped pixels the light exposure
// stands in for them (it does not clip there).
//
// The truth figures (simulated captures) are the same computations on truth/'s noise-free
// images, with the capture's geometry (light centres, core radius); besides, from the per-ghost
// truth layers, the flare of the ghosts alone.

#include <array>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::metrics {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The share thresholds, fractions of the light's peak.
inline constexpr std::array<double, 3> kShareLevels{1e-3, 1e-4, 1e-5};

struct MetricsOptions {
  // The light's core: a disc of core_factor × the radius of the light's half-maximum area (from
  // the light exposure) about its centre, at least min_core_radius_px (> 0 each).
  double core_factor = 2;
  double min_core_radius_px = 2;
  // A ghost is visible when its peak exceeds this × the frame's pixel noise σ (fit-eval's
  // visible_factor) (> 0).
  double visible_factor = 10;
  // The ghost peak is taken on box means of this many pixels a side (≥ 1, odd), against noise.
  int peak_box_px = 3;
  // The ghost peak is looked for where the light's pattern (taken out) is below this fraction of
  // what remains, (0, 1]: nearer the light, what remains may be the pattern's own error.
  double light_dominance = 0.1;

  bool IsValid(std::string* error) const;
};

// What every light-relative figure is divided by.
struct LightReference {
  // "light exposure", "light exposure through ND" (a declared filter), "merged frame (clipped:
  // lower bound)", "truth" or "none".
  std::string method = "none";
  std::string description;  // one line for people: what, where, how long
  int frame_index = -1;     // the capture's frame (plan index)
  double angle_deg = kNaN;  // its rig angle
  double flux = kNaN;       // common/light_spot.h's flux, frame units
  double peak = kNaN;       // the brightest pixel, frame units
  std::vector<double> exposures_s;  // the light exposures' times (none: empty)
  double nd_factor = 1;     // its declared filter
  bool lower_bound = false; // clipped: flux and peak are lower bounds, the figures upper ones
};

struct FrameFigures {
  int index = 0;            // the capture's frame (plan index); the model's step for a model
  double angle_deg = 0;     // rig angle θ
  bool light_known = false; // where the light is (in or beyond the frame) is known
  bool light_in_frame = false;
  cv::Point2d light_px{kNaN, kNaN};
  double flare_flux_ratio = kNaN;
  double ghost_flux_ratio = kNaN;   // the ghosts alone: truth layers, or the model's ghosts
  double ghost_peak_ratio = kNaN;
  double ghost_peak_stops = kNaN;
  // The truth only: the brightest point of the ghosts' own layers (Σ of ghost.<id>), on the same
  // pixels and boxes, in stops: what the ghost peak estimates.
  double ghost_layers_peak_stops = kNaN;
  std::array<double, 3> share_above{kNaN, kNaN, kNaN};
  int visible_ghosts = -1;          // -1: not measured
  double light_flux_ratio = kNaN;
  std::map<int, double> ghost_flux; // ghost id → its flux / the light's flux (model, truth)
  long long unknown_pixels = 0;     // clipped outside the core with nothing to stand in
};

// One curve set: the capture's figures, the truth's, or a model's.
struct Series {
  std::string source;               // "capture", "truth" or "model"
  std::vector<FrameFigures> frames; // in angle order
  std::vector<std::string> notes;   // how it was made, what it lacks

  bool empty() const { return frames.empty(); }
  // The frame with the largest flare flux ratio (else ghost peak), or nullptr.
  const FrameFigures* worst() const;
};

// The capture's light over the sweep, as the capture session recorded it (manifest
// light_stability).
struct LightStability {
  bool recorded = false;
  int frames = 0;
  int reference_frame_index = -1;
  double drift_pct = kNaN;    // the light check's flux against its frame's, %
  double scatter_pct = kNaN;  // RMS about a quadratic in θ, % of the mean
  std::string warning;        // empty when within 1 %
};

struct CaptureTrust {
  LightStability light;
  double settle_s = kNaN;       // the pause after each move (manifest plan.settle_s; NaN: none)
  double horizon_y_px = kNaN;   // fit/horizon.h
  double symmetry_rms = kNaN;
  bool optical_zero_measured = false;
  double angle_zero_deg = kNaN; // θ0
  double axis_x_px = kNaN;
  double light_rms_px = kNaN;   // the light's centres about their curve
  int optical_zero_ghosts = 0;  // ghost centre curves that took part
  int light_frames = 0;         // frames that show the light (fit/horizon.h)
  long long clipped_outside_core = 0;  // clipped pixels outside the core that nothing measured
  std::vector<std::string> warnings;
};

// Everything `flarekit metrics` says about one input.
struct Metrics {
  std::string name;                // for legends: the folder or file name
  std::filesystem::path input;
  std::string kind;                // "capture" or "model"
  std::filesystem::path model_file;  // with --model
  std::string lens;
  double f_number = 0;
  cv::Size size;
  std::string units;
  double core_radius_px = kNaN;
  double flux_radius_px = kNaN;
  LightReference light, truth_light;
  Series capture, truth, model;
  CaptureTrust trust;
  std::vector<std::string> notes;  // skipped figures and why
};

// The figures of a capture folder, with `model_file` (a fitted flare model of it; may be empty)
// for each ghost's flux. InputError (exit 2) for an unknown or bad file, a model of another image
// size, or one whose ghosts' angle ranges miss the capture's.
Metrics measureCapture(const std::filesystem::path& folder,
                       const std::filesystem::path& model_file = {},
                       const MetricsOptions& options = {});

// A model alone: each ghost's flux and peak in the model's units over its angle range (a model
// file holds no measurement of the light, so nothing is relative to it), and the ghosts present.
Metrics measureModel(const std::filesystem::path& model_file, const MetricsOptions& options = {});

// How far the capture's figures lie from the truth's (simulated captures): over the frames where
// both are measured, the largest relative difference of the flux ratios and the largest
// difference of the ghost peaks in stops (the targets: 5 % and 0.2 stops). Nothing
// (frames = 0) when the capture's light is a lower bound (clipped): its figures are bounds.
struct TruthAgreement {
  int frames = 0;                     // frames compared
  double light_flux_rel = kNaN;       // |capture − truth| / truth of the reference light's flux
  double light_peak_stops = kNaN;     // |log2(capture / truth)| of its peak
  double flare_flux_rel_max = kNaN;   // max over frames, flare flux ratio
  double flare_flux_rel_median = kNaN;
  double ghost_peak_stops_max = kNaN; // max |capture − truth| of the ghost peak, stops
  double ghost_peak_stops_median = kNaN;
  double light_flux_ratio_rel_max = kNaN;  // the frames' own light flux ratios
  std::array<double, 3> share_abs_max{kNaN, kNaN, kNaN};  // max |capture − truth| of the shares
  double worst_flux_angle_deg = kNaN, worst_peak_angle_deg = kNaN;
};
TruthAgreement compareWithTruth(const Metrics& m);

// InputError (exit 2) when `model_file` cannot go with the capture in `folder`: not a model, of
// another image size, or its ghosts' angle ranges miss the capture's angles. Reads the manifest
// and the model only (a quick check before any measuring).
void checkModelForCapture(const std::filesystem::path& folder, const std::filesystem::path& model_file);

// Whether `path` names a capture folder (manifest.json) or a model file, else InputError.
bool isCaptureFolder(const std::filesystem::path& path);

}  // namespace flarekit::metrics
