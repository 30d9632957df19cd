#pragma once
// The flare model of a lens (Walch et al. 2018 §3.3.2, §3.4): per ghost, every parameter of
// ghost_shape.h as a polynomial in the rig angle θ, valid over the ghost's angle range; stored as
// `model.json` (format "flarekit.flare-model", version 2):
//
//   {
//     "format": "flarekit.flare-model", "version": 2,
//     "capture": {
//       "camera": "Canon EOS 5D Mark II", "lens": "EF 24mm f/1.4L", "f_number": 1.4,
//       "iso": 100, "exposure_s": 1.0, "light": "Olympus CLV-S",
//       "image_width": 1280, "image_height": 720, "pixel_pitch_um": 6.4, "angle_step_deg": 0.2,
//       "angle_zero_deg": 0.12, "optical_axis_px": [641.3, 359.8]          // optional
//     },
//     "channels": 1,                       // 1 (grey) or 3 (R, G, B)
//     "ghosts": [
//       { "id": 3, "angle_min_deg": -20.0, "angle_max_deg": 25.0,
//         "parameters": { "Mx": [c0, c1, c2], "My": [...], "L": [...], ..., "Eo": [...] } }
//     ],
//     "pedestal": { "angle_min_deg": 0.0, "angle_max_deg": 30.0,     // optional
//                   "terms": { "P00": [c0, ...], "P10": [...], ..., "P02": [...] } }
//   }
//
// Parameters are named as parameterName() says ("Ib_R" etc. for RGB) and all must be present.
// Coefficient k multiplies θ^k with θ in degrees (the file's unit): p(θ) = c0 + c1·θ + c2·θ² + …
// (evaluated by Horner's rule, degree ≤ 10). Lengths are in capture pixels. The pedestal (the
// smooth glow under the ghosts, model/pedestal.h) is a polynomial in θ per term likewise; a file
// without one has none.
//
// Angles: θ is the field angle of the light (positive moves the light image to −x): the rig
// angle less the capture's optical zero, angle_zero_deg (the rig angle at which the light lay on
// the optical axis, measured by the fit; 0 when not recorded). φ is the roll about the optical
// axis (optical_axis_px; the image centre when not recorded). Both in degrees at this API, as in
// files and on the command line. Version 1 files have neither key and load as before.

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "model/ghost_shape.h"
#include "model/model_renderer.h"
#include "model/pedestal.h"

namespace flarekit {
class ConfigNode;  // common/config.h
}

namespace flarekit::model {

inline constexpr char kFlareModelFormat[] = "flarekit.flare-model";
inline constexpr int kFlareModelVersion = 2;
inline constexpr int kMaxPolynomialDegree = 10;

// How the captures the model was fitted to were taken (what prediction scales brightness by).
struct CaptureInfo {
  std::string camera;          // camera model
  std::string lens;            // lens name
  double f_number = 0;         // N (> 0)
  double iso = 0;              // ISO speed (> 0)
  double exposure_s = 0;       // exposure time, seconds (> 0)
  std::string light;           // the light source used
  cv::Size image_size;         // capture size, pixels (> 0 each)
  double pixel_pitch_um = 0;   // sensor pixel pitch, micrometres (> 0)
  double angle_step_deg = 0;   // rig step between captures, degrees (> 0)
  // Optional calibration (0 = not recorded; key left out of the file):
  // the illuminance the capture's light gave at the lens, lux: l_F·α_F of Walch 2018 Eq. 2.
  double light_illuminance_lux = 0;
  // the model value at which a frame exposed for exposure_s at this f-number and ISO clips (the
  // sensor's white level in the capture's units): prediction divides by it so that its overlays
  // are fractions of the scene camera's white level.
  double clip_level = 0;
  // the lens's focal length, mm: with the pixel pitch it fixes where a light at θ images (f·tan θ)
  // and how large the ghosts are, so a prediction can tell a scene camera that differs.
  double focal_length_mm = 0;
  // The optical zero (fit/horizon.h): the rig angle with the light on the optical axis, degrees
  // (the model's angles are rig angles less this), and where the optical axis meets the image,
  // capture pixels (nullopt: the image centre).
  double angle_zero_deg = 0;
  std::optional<cv::Point2d> optical_axis_px;

  // The optical axis in capture pixels.
  cv::Point2d opticalAxis() const {
    return optical_axis_px.value_or(cv::Point2d(0.5 * image_size.width, 0.5 * image_size.height));
  }
  // The field angle θ of a frame taken at rig angle `rig_angle_deg`.
  double fieldAngle(double rig_angle_deg) const { return rig_angle_deg - angle_zero_deg; }
};

// p(θ) = Σ coefficients[k]·θ^k.
struct Polynomial {
  std::vector<double> coefficients;  // c0 first; empty means the zero polynomial

  // Horner's rule: (…(c_n·θ + c_{n−1})·θ + …)·θ + c0; exact as a function of the coefficients
  // (no other rounding than Horner's).
  double evaluate(double theta) const;
};

// One ghost of the model.
struct GhostTrack {
  int id = 0;                     // unique within the model, ≥ 0
  double angle_min_deg = 0;       // θmin: the ghost exists for θmin ≤ θ ≤ θmax
  double angle_max_deg = 0;       // θmax (≥ θmin)
  // One polynomial per parameter, in the flat order of ghost_shape.h (parameterCount(channels)).
  std::vector<Polynomial> parameters;

  bool covers(double angle_deg) const { return angle_deg >= angle_min_deg && angle_deg <= angle_max_deg; }
  // Its parameters at θ (degrees; range not checked), clamped to the parameters' bounds.
  GhostParameters at(double angle_deg, int channels) const;
};

// The pedestal of the model (model/pedestal.h): one polynomial per term over an angle range.
struct PedestalTrack {
  double angle_min_deg = 0;
  double angle_max_deg = 0;
  std::vector<Polynomial> terms;  // kPedestalTerms × channels, in pedestalTermName order

  bool covers(double angle_deg) const {
    return angle_deg >= angle_min_deg && angle_deg <= angle_max_deg;
  }
  // The pedestal at θ (degrees; range not checked).
  Pedestal at(double angle_deg, int channels) const;
};

// A ghost evaluated at one angle.
struct GhostAtAngle {
  int id = 0;
  GhostParameters parameters;
};

class FlareModel {
 public:
  CaptureInfo capture;
  int channels = 1;                 // 1 or 3
  std::vector<GhostTrack> ghosts;
  std::optional<PedestalTrack> pedestal;

  // Reads and validates a model file. Throws InputError "<file>: <key path>: <problem>" for
  // anything wrong: syntax, format or version, missing or unknown keys, wrong types, non-finite
  // numbers, non-positive sizes, an empty angle range (θmax < θmin), duplicate ids, missing
  // parameters, degree above kMaxPolynomialDegree, or a parameter outside its allowed range
  // (parameterBounds) at any of 65 evenly spaced angles across the ghost's range; likewise for the
  // pedestal's range and terms (which have no bounds).
  static FlareModel load(const std::filesystem::path& path);
  // Parses the JSON text of a model file; `file` names it in errors.
  static FlareModel parse(const std::string& text, const std::string& file);
  // The same, from a parsed document (its file and key paths name errors).
  static FlareModel fromJson(const ConfigNode& root);

  // Writes the model atomically. Throws std::invalid_argument if !IsValid(), RuntimeError on I/O.
  void save(const std::filesystem::path& path) const;
  nlohmann::json toJson() const;

  // The same checks as load, on an in-memory model.
  bool IsValid(std::string* error) const;

  // Every ghost whose range covers θ, with its parameters evaluated at θ (degrees) and clamped to
  // parameterBounds (polynomials can stray between the angles load checked). Ghosts outside their
  // range are absent.
  std::vector<GhostAtAngle> ghostsAt(double angle_deg) const;
  // The pedestal at θ, empty where the model has none or its range does not cover θ.
  Pedestal pedestalAt(double angle_deg) const;

  // The ghosts at θ as rendered into an image of `size` (default: the capture size) at roll φ
  // about the optical axis: the view maps the optical axis, scaled by W / capture width, to the
  // capture's optical axis (the flare keeps its size relative to the image width).
  ViewTransform viewAt(double roll_deg, std::optional<cv::Size> size = std::nullopt) const;

  // Renders all ghosts and the pedestal at θ and roll φ (degrees) into an image of `size`
  // (default: the capture size), CV_32FC(channels), through viewAt: the roll turns the flare
  // exactly about the optical axis.
  cv::Mat render(double angle_deg, double roll_deg = 0, std::optional<cv::Size> size = std::nullopt,
                 const RenderOptions& options = {}) const;
};

}  // namespace flarekit::model
