#pragma once
// Flare prediction for a scene (Walch et al. 2018 §3.4.1, §3.5): every light's ghosts from the
// fitted model at the light's θ and roll φ, scaled by Eq. 2, added into one overlay; the overlay
// over the scene's background; the occurrence estimators, each rated as a percentile of its
// distribution over the model's sampled range; a severity map over all light directions; a
// severity timeline along the camera path; and the files of `flarekit predict`.
//
// Units: overlay, background and composite are linear values of the scene camera's image (the
// model's capture units times B). Images are CV_32FC3 (R, G, B), the scene's sensor aspect ratio.
//
// Thread safety: the functions are pure (rendering uses TBB inside); they may run concurrently.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "model/flare_model.h"
#include "predict/brightness.h"
#include "predict/estimators.h"
#include "predict/geometry.h"
#include "predict/scene.h"

namespace flarekit::predict {

// The l_F·α_F assumed when neither the model nor the options give one: a placeholder of the right
// order for a fibre-optic source (~1e6 cd/m²) seen under ~1e-5 sr on the rig.
inline constexpr double kAssumedCaptureIlluminanceLux = 10.0;

struct PredictOptions {
  // Width of the predicted images, pixels (0 = the model's capture width); the height follows the
  // scene's sensor aspect ratio.
  int image_width_px = 0;
  // l_F·α_F of Eq. 2: the illuminance the capture's light gave at the lens, lux (≥ 0). 0 = the
  // value the model records (the rig's light_illuminance_lux); a model without one falls back to
  // kAssumedCaptureIlluminanceLux and the report says the absolute scale is assumed. Every B
  // scales with 1 / this value.
  double capture_illuminance_lux = 0;
  // The estimator shown in the severity map and timeline and used to rank lights.
  Estimator severity_estimator = Estimator::kMean;
  // Severity map grid: θ steps from 0 to the model's largest |θ|, φ steps all round (≥ 2 each).
  int map_angle_steps = 16;
  int map_roll_steps = 36;
  // Width of the images rendered for maps, ratings and timelines, pixels (≥ 16): small, because
  // hundreds are rendered; the estimators are means and extremes, which survive downsampling.
  int map_image_width_px = 192;
  // Most angles rendered for the rating distributions (the model's sampled range at its angle step,
  // thinned to at most this many; ≥ 2).
  int rating_samples_max = 121;
  EstimatorOptions estimators;
  // Render settings for the model (model/model_renderer.h).
  model::RenderOptions render;

  bool IsValid(std::string* error) const;
};

// What prediction found about one light.
struct LightPrediction {
  std::string name;
  LightGeometry geometry;
  double illuminance_lux = 0;   // l_R·α_R at the camera
  BrightnessScale brightness;   // B of Eq. 2 for this light
  int ghost_count = 0;          // ghosts the model has at this light's θ (0 unless in range)
  Estimators estimators;        // of this light's overlay alone over the scene
  double severity = 0;          // value(estimators, severity_estimator)
  double severity_percentile = 0;  // of severity against the rating distribution (NaN: no flare)
  int rank = 0;                 // 1 = most severe; lights without ghosts rank last
};

// The estimators of the whole overlay and their ratings.
struct RatedEstimator {
  Estimator estimator = Estimator::kMean;
  double value = 0;
  double percentile = 0;               // 0–100 against `distribution`
  std::vector<double> distribution;    // over the model's sampled range (see ratingDistributions)
};

// Severity over light directions, for the polar map.
struct SeverityMap {
  Estimator estimator = Estimator::kMean;
  std::vector<double> angles_deg;   // θ of each ring (centre), ascending from 0
  std::vector<double> rolls_deg;    // φ of each sector (centre), ascending from 0
  // values[i][j] at angles_deg[i], rolls_deg[j]: the estimator for one light of brightness
  // `brightness` at that direction over the scene's background.
  std::vector<std::vector<double>> values;
  double max_angle_deg = 0;         // outer radius of the map
  double brightness = 1;            // B used
};

struct TimelinePoint {
  double time_s = 0;
  double severity = 0;        // the whole overlay's severity at this pose
  int lights_in_range = 0;
};

struct PredictionSummary {
  std::string scene_name;
  std::filesystem::path scene_file, model_file, out_dir;
  cv::Size image_size;
  double capture_illuminance_lux = 0;    // l_F·α_F used (captureIlluminance)
  std::string capture_illuminance_source;  // "model", "option" or "assumed"
  // Overlay units: true = fractions of the scene camera's white level (the model records its
  // capture's clip level); false = the capture's own units (uncalibrated).
  bool overlay_in_white_units = false;
  std::vector<LightPrediction> lights;   // in scene order (rank tells the order of severity)
  Estimators estimators;                 // of the whole overlay over the scene
  std::vector<RatedEstimator> ratings;   // one per estimator, allEstimators() order
  SeverityMap map;
  std::vector<TimelinePoint> timeline;   // empty when the scene has no camera path
  std::vector<std::filesystem::path> files;  // written files
  // What makes the prediction less trustworthy than it looks (cameraMismatch), one line each.
  std::vector<std::string> warnings;
  double seconds = 0;
  // A paragraph: lights in range / out / behind, the worst light, severity and its percentile.
  std::string BriefReport() const;
};

// The overlay of all lights of `scene` seen from `pose`, CV_32FC3 of `image_size`, each light's
// ghosts scaled by its B and tinted by its colour. `lights` (optional) receives the per-light
// geometry and brightness (estimators left empty).
cv::Mat renderOverlay(const model::FlareModel& model, const Scene& scene, const CameraPose& pose,
                      cv::Size image_size, const PredictOptions& options,
                      std::vector<LightPrediction>* lights = nullptr);

// The l_F·α_F prediction uses (lux) and where it comes from ("option", "model" or "assumed"; see
// PredictOptions::capture_illuminance_lux).
double captureIlluminance(const model::FlareModel& model, const PredictOptions& options,
                          std::string* source = nullptr);

// The overlay of one light of brightness `brightness` at model angle θ and roll φ (CV_32FC3): its
// ghosts and the pedestal under them (model/pedestal.h), in fractions of the white level when the
// model records its capture's clip level (the model's values divided by it), else in the model's
// units.
cv::Mat renderLight(const model::FlareModel& model, double model_angle_deg, double model_roll_deg,
                    double brightness, const cv::Vec3d& color, cv::Size image_size,
                    const model::RenderOptions& options);

// A warning when the scene's camera does not see the scene as the capture's camera saw the rig:
// the model draws every ghost where the capture's lens put it, at the capture's focal length per
// sensor width (Walch 2018 §3.4 renders a model of one lens), while the scene camera images a light
// at θ at its own f·tan θ. Empty when the two agree within `tolerance` (relative) or the model
// does not record its lens's focal length.
std::string cameraMismatch(const model::FlareModel& model, const Scene& scene, double tolerance = 0.02);

// The model's sampled range (union of the ghosts' ranges); {0, 0} for a model without ghosts.
AngleRange sampledRange(const model::FlareModel& model);

// The image size for a scene: width from options (or the capture), height by the sensor aspect.
cv::Size predictionImageSize(const model::FlareModel& model, const Scene& scene, int width_px);

// The scene image R at `size` (background resized, or the uniform level), CV_32FC3.
cv::Mat sceneImage(const Scene& scene, cv::Size size);

// Every estimator for one light of brightness `brightness` moved over the model's sampled range
// (at roll 0, the rig's own sweep), over `scene_image`: one vector per estimator in allEstimators()
// order. What §3.5's "estimators over the whole sampled range" rates a constellation against.
std::vector<std::vector<double>> ratingDistributions(const model::FlareModel& model,
                                                     const cv::Mat& scene_image, double brightness,
                                                     const PredictOptions& options);

// The severity map of one light of brightness `brightness` over all directions.
SeverityMap severityMap(const model::FlareModel& model, const cv::Mat& scene_image, double brightness,
                        const PredictOptions& options);

// The whole computation of `flarekit predict` (no files).
PredictionSummary analyze(const model::FlareModel& model, const Scene& scene,
                          const PredictOptions& options, cv::Mat* overlay = nullptr,
                          cv::Mat* composite = nullptr);

// `flarekit predict`: analyze(), then writes into `out_dir` (created if missing) overlay.exr
// (linear overlay, float), composite.png (tone-mapped background + overlay), estimators.json,
// report.html (report.h) and view.html (the real-time viewer the report links its lights to,
// view/viewer_page.h). Throws InputError for invalid options, RuntimeError on I/O failure.
PredictionSummary predict(const model::FlareModel& model, const Scene& scene,
                          const PredictOptions& options, const std::filesystem::path& out_dir,
                          const std::filesystem::path& model_file = {});

nlohmann::json toJson(const PredictionSummary& summary);

}  // namespace flarekit::predict
