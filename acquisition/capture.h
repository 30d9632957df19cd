#pragma once
// Capture sessions (Walch et al. 2018 §3.1): rotate the camera in steps away from a point light,
// bracket exposures at every step, merge them to HDR and store one OpenEXR frame per angle.
//
// ── Capture folder layout ─────────────────────────────────────────────────────────────────────
//   DIR/manifest.json            the session (below); rewritten atomically after every frame
//   DIR/.flarekit.lock           locked (flock) while a session runs in DIR: one at a time
//                                  (common/folder_lock.h); holds the last holder's process id
//   DIR/frames/frame_NNNN.exr    merged HDR frame of plan angle NNNN (0-based, plan order):
//                                  main layer "Y" (mono sensor) or "R","G","B" (Bayer sensor,
//                                  bilinear demosaic of the merged mosaic), float32 (half with
//                                  --half-frames; manifest image.pixel_type), zip;
//                                  layer "saturated": 1 where every exposure clipped (the value
//                                  is then only a lower bound), else 0;
//                                  attributes flarekit.angle_deg, flarekit.exposure_s (longest),
//                                  flarekit.exposures_s, flarekit.iso, flarekit.f_number,
//                                  flarekit.camera, flarekit.lens, flarekit.rig,
//                                  flarekit.pixel_pitch_um, flarekit.focal_length_mm (when
//                                  known), flarekit.units, flarekit.cfa
//   DIR/truth/frame_NNNN.exr     simulated rigs only: the renderer's noise-free radiance in the
//                                  frames' units and channels (main layer "Y" or "R","G","B")
//                                  and one layer per rendered ghost, "ghost.<id>.Y" (or
//                                  .R/.G/.B), same units; half precision (float when a value
//                                  exceeds 60000), zip; attributes flarekit.angle_deg (the
//                                  head's, as in the frame) and
//                                  flarekit.ghost.<id>.surfaces/.centroid_px/.bbox_px/.energy;
//                                  flarekit.true_angle_deg (the angle rendered) when the rig's
//                                  angle_zero_offset_deg is not 0, and
//                                  flarekit.optical_axis_offset_px when that is not (0, 0)
//   DIR/light/frame_NNNN.exr     with light exposures (plan.light_exposures_s): the frame's light
//                                  exposures merged apart from its bracket (a bracket of their own,
//                                  the shortest short enough not to clip the light), in the
//                                  frames' units and channels, times the declared
//                                  light_nd_factor; float, zip; layer "saturated" as in the
//                                  frames; attributes as a frame's, and flarekit.light_nd_factor
//   DIR/darks/dark_K.exr         averaged dark frame for exposure K (float DN), --dark-frames
//   DIR/raw/frame_NNNN_eK.dng    --keep-raw: the RAW exposures; DNG for Bayer sensors (levels and
//                                  EXIF exposure inside), 16-bit PNG (.png) for mono sensors
//
// ── manifest.json (format "flarekit.capture", version 1) ─────────────────────────────────────
//   status            "in_progress" | "complete" | "interrupted" (Ctrl-C) | "failed" (+ "error")
//   rig               {name, file (as given on the command line), head, camera: driver names,
//                      simulated: bool, simulation?: {optical_axis_offset_px: [dx, dy],
//                      angle_zero_offset_deg, light_drift_pct?}} (simulation: a simulated
//                      camera's imperfections, rig file [simulation]; present only when one is
//                      not 0; light_drift_pct only when it is not 0)
//   head              description of the rotation head
//   lens              {name, file, focal_length_mm}  (name and file "" when the rig does not know
//                      its lens; focal_length_mm, the simulated lens's paraxial EFL or the real
//                      rig's [lens] focal_length_mm, left out when unknown)
//   camera            {description, iso, f_number, exposures_s: [...], cfa, black_level_dn,
//                      white_level_dn, gain_e_per_dn, read_noise_e}
//   light             description from the rig file
//   image             {width, height, channels: "Y" | "RGB", pixel_pitch_um, units,
//                      pixel_type: "float" | "half" (of the frames)}
//                      units: "relative irradiance (render units)" for simulated rigs, else
//                      "electrons/s" (merged value = electrons per second per photosite)
//   plan              {from_deg, to_deg, step_deg, angles_deg: [...], exposures_s: [...],
//                      dark_frames, keep_raw, settle_s?, light_exposures_s?, light_nd_factor?,
//                      light_check_repeats?} (settle_s: the pause after each move before
//                      exposing, rig [head] settle_s, when not 0; the light keys, rig [capture]
//                      light_exposure_s, light_nd_factor and light_check_repeats, when there are
//                      light exposures)
//   truth             true when truth/ holds ground truth for every frame
//   frames            [{index, angle_deg, file, truth_file?,
//                       raw_files?: [{file, exposure_s, black_level_dn, white_level_dn}],
//                       exposures_s, saturated_photosites,
//                       exposure_ratios: [measured long/short ratio of consecutive exposures;
//                                         0 = too few mid-tone photosites to tell],
//                       retries,
//                       light?: the frame's light exposures (with plan.light_exposures_s):
//                               {file, exposures_s, nd_factor, found (the light's image is in
//                               it), center_px: [x, y], peak, flux, flux_radius_px, cut (the flux
//                               disc leaves the image: flux is partial), saturated_photosites}
//                               (peak: the brightest pixel; flux: the sum over the disc of
//                               flux_radius_px = image diagonal / 8 about the light's centre;
//                               both in the frames' units, common/light_spot.h)
//                      }] in plan order, one entry per finished frame, never twice
//   light_check       with light exposures: right after the first frame whose light was whole
//                      (found, not cut, unclipped), plan.light_check_repeats more light exposures
//                      there (start); once the plan is done, the head goes back to that angle and
//                      takes as many again (end): {frame_index, angle_deg, repeats, start: {flux
//                      (their mean), flux_sd_pct (one exposure's spread), peak (mean),
//                      saturated_photosites, fluxes: [...]}, end?: the same}; no image files
//   light_stability   with light exposures (rewritten after every frame): {frames (whole light
//                      measurements), reference_frame_index (the light check's frame), drift_pct
//                      (100·(end flux / start flux − 1); null until the end), scatter_pct (RMS of
//                      the frames' fluxes about a quadratic in the angle, % of their mean: flicker,
//                      and each one exposure's shot noise; null below 5 frames), warning? (either
//                      beyond ±1 %, or a light exposure clipped)}. The lens passes less light at
//                      wider angles, so the drift is measured by returning to one angle, not along
//                      the sweep (docs/metrics.md)
//   darks             [{exposure_s, file, frames}] when dark frames were taken
//   frames_done, frames_planned
// A frame file is written before the manifest lists it: a frame listed is whole and readable;
// a frame file not yet listed is captured again on --resume.

#include <atomic>
#include <filesystem>
#include <string>
#include <vector>

#include "acquisition/capture_plan.h"
#include "acquisition/rig.h"

namespace flarekit::acquisition {

struct CaptureOptions {
  bool resume = false;  // continue the session in the output folder
  // Checked after every frame: when set, the session stops cleanly (status "interrupted").
  const std::atomic<bool>* stop_requested = nullptr;
  bool progress = true;  // progress bar / lines on stderr (also subject to --quiet)
  // Write truth/ for simulated rigs (default true).
  bool write_truth = true;
  // Store frames in half precision (3 significant digits; for small shareable captures such as
  // data_synthetic/, whose noise is far above that). A frame with a value beyond the half range
  // is stored as float anyway. Default false: float32. The EXR header says which.
  bool half_frames = false;
};

struct CaptureSummary {
  std::string termination;  // "complete" or "interrupted"
  int frames_planned = 0;
  int frames_already_done = 0;  // found in the manifest when resuming
  int frames_captured = 0;      // captured by this run
  int exposures_taken = 0;
  int camera_retries = 0, head_retries = 0;
  long long saturated_photosites = 0;  // over the frames of this run
  std::vector<std::string> warnings;
  double seconds = 0;
  std::filesystem::path manifest;

  std::string BriefReport() const;
};

// Runs (or resumes) a capture into `out`. Returns when every angle is done or after the frame
// during which a stop was requested. Throws InputError for a bad plan, a folder that holds
// something else, or a resume whose plan differs; RuntimeError after a device failed
// persistently (the manifest then says "failed" and the session can be resumed).
CaptureSummary runCapture(const Rig& rig, RigDevices& devices, const CapturePlan& plan,
                          const std::filesystem::path& out, const CaptureOptions& options = {});

}  // namespace flarekit::acquisition
