#include "predict/prediction.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "common/log.h"
#include "predict/report.h"
#include "view/viewer_page.h"

namespace flarekit::predict {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

ExposureSettings captureExposure(const model::FlareModel& m) {
  return {m.capture.f_number, m.capture.iso, m.capture.exposure_s};
}
ExposureSettings sceneExposure(const SceneCamera& c) { return {c.f_number, c.iso, c.exposure_s}; }

// The colour scaled to Rec. 709 luminance 1, so the tint changes hue, not brightness.
cv::Vec3d normalisedColor(const Vec3& c) {
  const double y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
  if (!(y > 0)) return {1, 1, 1};
  return {c[0] / y, c[1] / y, c[2] / y};
}

// Estimators of a small (map-size) overlay, with the sum scaled to the full image's pixel count so
// the values compare with full-size ones (the other estimators are means or extremes).
Estimators smallEstimators(const cv::Mat& overlay, const cv::Mat& scene, double pixel_ratio,
                           const EstimatorOptions& options) {
  Estimators e = computeEstimators(overlay, scene, options);
  e.sum *= pixel_ratio;
  return e;
}

// θ samples over the model's range at the capture's angle step, thinned to `max_samples`.
std::vector<double> sweepAngles(const model::FlareModel& m, int max_samples) {
  const AngleRange r = sampledRange(m);
  if (m.ghosts.empty()) return {};
  const double span = r.max_deg - r.min_deg;
  int n = static_cast<int>(std::floor(span / m.capture.angle_step_deg + 1e-9)) + 1;
  n = std::clamp(n, 1, max_samples);
  std::vector<double> out;
  for (int k = 0; k < n; ++k) out.push_back(n == 1 ? r.min_deg : r.min_deg + span * k / (n - 1));
  return out;
}

// The model at each swept angle, roll 0, brightness 1, white, at `size`.
std::vector<cv::Mat> sweepOverlays(const model::FlareModel& m, cv::Size size, const PredictOptions& options) {
  const std::vector<double> angles = sweepAngles(m, options.rating_samples_max);
  std::vector<cv::Mat> out(angles.size());
  model::RenderOptions ro = options.render;
  ro.parallel = false;
  tbb::parallel_for(size_t{0}, angles.size(), [&](size_t k) {
    out[k] = renderLight(m, angles[k], 0.0, 1.0, {1, 1, 1}, size, ro);
  });
  return out;
}

std::vector<std::vector<double>> distributionsFromSweep(const std::vector<cv::Mat>& sweep,
                                                        const cv::Mat& scene_small, double brightness,
                                                        double pixel_ratio, const EstimatorOptions& eo) {
  std::vector<std::vector<double>> out(allEstimators().size());
  for (const cv::Mat& o : sweep) {
    const Estimators e = smallEstimators(o * brightness, scene_small, pixel_ratio, eo);
    for (size_t k = 0; k < allEstimators().size(); ++k) out[k].push_back(value(e, allEstimators()[k]));
  }
  return out;
}

double jsonNumber(double v) { return v; }

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(jsonNumber(v)) : nlohmann::json(); }

}  // namespace

bool PredictOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (image_width_px < 0 || image_width_px > 16384) return fail("image_width_px must be in [0, 16384]");
  if (!(capture_illuminance_lux >= 0) || !std::isfinite(capture_illuminance_lux))
    return fail("capture_illuminance_lux must be ≥ 0 (0 = the model's)");
  if (map_angle_steps < 2 || map_angle_steps > 180) return fail("map_angle_steps must be in [2, 180]");
  if (map_roll_steps < 2 || map_roll_steps > 360) return fail("map_roll_steps must be in [2, 360]");
  if (map_image_width_px < 16 || map_image_width_px > 4096) return fail("map_image_width_px must be in [16, 4096]");
  if (rating_samples_max < 2 || rating_samples_max > 10000) return fail("rating_samples_max must be in [2, 10000]");
  std::string sub;
  if (!estimators.IsValid(&sub)) return fail("estimators: " + sub);
  if (!render.IsValid(&sub)) return fail("render: " + sub);
  return true;
}

std::string cameraMismatch(const model::FlareModel& m, const Scene& scene, double tolerance) {
  const auto& c = m.capture;
  if (!(c.focal_length_mm > 0) || !(c.pixel_pitch_um > 0) || c.image_size.width <= 0) return "";
  const double capture_width_mm = c.image_size.width * c.pixel_pitch_um * 1e-3;
  const double capture = c.focal_length_mm / capture_width_mm;
  const double seen = scene.camera.focal_length_mm / scene.camera.sensor_width_mm;
  if (std::abs(seen / capture - 1) <= tolerance) return "";
  auto fov = [](double f_per_width) { return 2 * std::atan(0.5 / f_per_width) * 180 / M_PI; };
  return cv::format(
      "%s: the scene camera (%.4g mm on a %.3g mm wide sensor, %.1f° across) does not see as the "
      "capture's did (%.4g mm on %.3g mm, %.1f°): ghosts are drawn where the capture's lens put them, "
      "%.2f× the size and offset this camera would show; capture the scene's lens, or give the "
      "scene the capture's focal length",
      scene.file.string().c_str(), scene.camera.focal_length_mm, scene.camera.sensor_width_mm, fov(seen),
      c.focal_length_mm, capture_width_mm, fov(capture), capture / seen);
}

AngleRange sampledRange(const model::FlareModel& m) {
  if (m.ghosts.empty()) return {0, 0};
  AngleRange r{std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
  for (const auto& g : m.ghosts) {
    r.min_deg = std::min(r.min_deg, g.angle_min_deg);
    r.max_deg = std::max(r.max_deg, g.angle_max_deg);
  }
  return r;
}

cv::Size predictionImageSize(const model::FlareModel& m, const Scene& scene, int width_px) {
  const int w = width_px > 0 ? width_px : m.capture.image_size.width;
  const double h = std::round(w * scene.camera.sensor_height_mm / scene.camera.sensor_width_mm);
  if (!(h <= 16384))
    throw InputError(scene.file.string() + ": camera: the sensor's aspect ratio gives an image " +
                     cv::format("%.0f", h) + " px high for " + std::to_string(w) + " px wide (at most 16384)");
  return {w, std::max(1, static_cast<int>(h))};
}

cv::Mat sceneImage(const Scene& scene, cv::Size size) {
  if (scene.background.empty()) return cv::Mat(size, CV_32FC3, cv::Scalar::all(scene.background_level));
  cv::Mat bg = scene.background;
  if (bg.channels() == 1) cv::cvtColor(bg, bg, cv::COLOR_GRAY2BGR);  // grey to three equal channels
  cv::Mat out;
  cv::resize(bg, out, size, 0, 0, bg.cols > size.width ? cv::INTER_AREA : cv::INTER_LINEAR);
  return out;
}

double captureIlluminance(const model::FlareModel& m, const PredictOptions& options, std::string* source) {
  auto from = [&](const char* what, double lux) {
    if (source) *source = what;
    return lux;
  };
  if (options.capture_illuminance_lux > 0) return from("option", options.capture_illuminance_lux);
  if (m.capture.light_illuminance_lux > 0) return from("model", m.capture.light_illuminance_lux);
  return from("assumed", kAssumedCaptureIlluminanceLux);
}

cv::Mat renderLight(const model::FlareModel& m, double model_angle_deg, double model_roll_deg, double brightness,
                    const cv::Vec3d& color, cv::Size image_size, const model::RenderOptions& options) {
  // Walch 2018 §3.4.1: the rendering is rotated about the optical axis to the light's roll.
  cv::Mat img = m.render(model_angle_deg, model_roll_deg, image_size, options);
  // A model value of clip_level clips in a capture frame; after Eq. 2's B (the scene's exposure
  // against the capture's), model·B / clip_level is the fraction of the scene camera's white.
  if (m.capture.clip_level > 0) brightness /= m.capture.clip_level;
  cv::Mat rgb;
  if (m.channels == 1) {
    cv::Mat planes[3] = {img * (brightness * color[0]), img * (brightness * color[1]), img * (brightness * color[2])};
    cv::merge(planes, 3, rgb);
  } else {
    rgb = img.mul(cv::Scalar(brightness * color[0], brightness * color[1], brightness * color[2]));
  }
  return rgb;
}

namespace {

// Every light's prediction at `pose` and, when `images` is given, its own overlay (empty when it
// has no ghosts); returns the sum of the overlays.
cv::Mat renderLights(const model::FlareModel& m, const Scene& scene, const CameraPose& pose, cv::Size size,
                     const PredictOptions& options, std::vector<LightPrediction>* lights, std::vector<cv::Mat>* images) {
  const AngleRange range = sampledRange(m);
  cv::Mat overlay(size, CV_32FC3, cv::Scalar::all(0));
  if (lights) lights->clear();
  if (images) images->clear();
  for (const SceneLight& light : scene.lights) {
    LightPrediction p;
    p.name = light.name;
    p.geometry = lightGeometry(light, pose, scene.camera, range, size);
    p.illuminance_lux = Scene::illuminanceAt(light, pose);
    if (p.illuminance_lux > 0) {
      p.brightness = brightnessScale(captureExposure(m), sceneExposure(scene.camera),
                                     {captureIlluminance(m, options), p.illuminance_lux});
    }
    cv::Mat own;
    if (p.geometry.status == LightStatus::kInRange && p.illuminance_lux > 0) {
      p.ghost_count = static_cast<int>(m.ghostsAt(p.geometry.model_angle_deg).size());
      if (p.ghost_count > 0 || !m.pedestalAt(p.geometry.model_angle_deg).empty()) {
        // Walch 2018 §3.4.1: each light's ghosts at its θ and roll, scaled by Eq. 2, added.
        own = renderLight(m, p.geometry.model_angle_deg, p.geometry.model_roll_deg, p.brightness.scale,
                          normalisedColor(light.color), size, options.render);
        overlay += own;
      }
    }
    if (lights) lights->push_back(p);
    if (images) images->push_back(own);
  }
  return overlay;
}

}  // namespace

cv::Mat renderOverlay(const model::FlareModel& m, const Scene& scene, const CameraPose& pose, cv::Size size,
                      const PredictOptions& options, std::vector<LightPrediction>* lights) {
  return renderLights(m, scene, pose, size, options, lights, nullptr);
}

std::vector<std::vector<double>> ratingDistributions(const model::FlareModel& m, const cv::Mat& scene_image,
                                                     double brightness, const PredictOptions& options) {
  const int w = std::min(options.map_image_width_px, scene_image.cols);
  const cv::Size small(w, std::max(1, static_cast<int>(std::lround(static_cast<double>(w) * scene_image.rows / scene_image.cols))));
  cv::Mat scene_small;
  cv::resize(scene_image, scene_small, small, 0, 0, cv::INTER_AREA);
  const double ratio = static_cast<double>(scene_image.total()) / static_cast<double>(scene_small.total());
  return distributionsFromSweep(sweepOverlays(m, small, options), scene_small, brightness, ratio, options.estimators);
}

SeverityMap severityMap(const model::FlareModel& m, const cv::Mat& scene_image, double brightness,
                        const PredictOptions& options) {
  SeverityMap map;
  map.estimator = options.severity_estimator;
  map.brightness = brightness;
  const AngleRange range = sampledRange(m);
  map.max_angle_deg = std::min(89.0, std::max(std::abs(range.min_deg), std::abs(range.max_deg)));
  if (!(map.max_angle_deg > 0)) map.max_angle_deg = 1.0;
  for (int i = 0; i < options.map_angle_steps; ++i)
    map.angles_deg.push_back(map.max_angle_deg * (i + 0.5) / options.map_angle_steps);
  for (int j = 0; j < options.map_roll_steps; ++j) map.rolls_deg.push_back(360.0 * (j + 0.5) / options.map_roll_steps);

  const int w = std::min(options.map_image_width_px, scene_image.cols);
  const cv::Size small(w, std::max(1, static_cast<int>(std::lround(static_cast<double>(w) * scene_image.rows / scene_image.cols))));
  cv::Mat scene_small;
  cv::resize(scene_image, scene_small, small, 0, 0, cv::INTER_AREA);
  const double ratio = static_cast<double>(scene_image.total()) / static_cast<double>(scene_small.total());
  SceneCamera camera;  // only the image projection is used, which the map does not need
  map.values.assign(map.angles_deg.size(), std::vector<double>(map.rolls_deg.size(), 0.0));
  model::RenderOptions ro = options.render;
  ro.parallel = false;
  const size_t cells = map.angles_deg.size() * map.rolls_deg.size();
  tbb::parallel_for(size_t{0}, cells, [&](size_t c) {
    const size_t i = c / map.rolls_deg.size(), j = c % map.rolls_deg.size();
    const LightGeometry g = geometryFromCameraDirection(cameraDirectionFromAngles(map.angles_deg[i], map.rolls_deg[j]),
                                                        range, camera, small);
    cv::Mat overlay(small, CV_32FC3, cv::Scalar::all(0));
    if (g.status == LightStatus::kInRange)
      overlay = renderLight(m, g.model_angle_deg, g.model_roll_deg, brightness, {1, 1, 1}, small, ro);
    map.values[i][j] = value(smallEstimators(overlay, scene_small, ratio, options.estimators), map.estimator);
  });
  return map;
}

PredictionSummary analyze(const model::FlareModel& m, const Scene& scene, const PredictOptions& options,
                          cv::Mat* overlay_out, cv::Mat* composite_out) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError("predict options: " + error);
  if (!m.IsValid(&error)) throw InputError("flare model: " + error);
  const auto start = std::chrono::steady_clock::now();
  PredictionSummary s;
  s.scene_name = scene.name;
  s.scene_file = scene.file;
  s.image_size = predictionImageSize(m, scene, options.image_width_px);
  s.capture_illuminance_lux = captureIlluminance(m, options, &s.capture_illuminance_source);
  s.overlay_in_white_units = m.capture.clip_level > 0;
  if (std::string w = cameraMismatch(m, scene); !w.empty()) {
    logWarning(w);
    s.warnings.push_back(w);
  }
  const cv::Mat scene_img = sceneImage(scene, s.image_size);

  // Overlay, light by light (Walch 2018 §3.4.1: ghosts scaled by Eq. 2 and added).
  std::vector<cv::Mat> own_images;
  cv::Mat overlay = renderLights(m, scene, scene.camera.pose, s.image_size, options, &s.lights, &own_images);
  s.estimators = computeEstimators(overlay, scene_img, options.estimators);
  for (size_t k = 0; k < s.lights.size(); ++k) {
    LightPrediction& p = s.lights[k];
    const cv::Mat own = own_images[k].empty() ? cv::Mat(s.image_size, CV_32FC3, cv::Scalar::all(0)) : own_images[k];
    p.estimators = computeEstimators(own, scene_img, options.estimators);
    p.severity = value(p.estimators, options.severity_estimator);
    p.severity_percentile = kNaN;
  }

  // §3.5: rate each estimator against its distribution over the sampled range, for a light as
  // bright as the scene's brightest flaring light (each light: its own brightness).
  const int w = std::min(options.map_image_width_px, s.image_size.width);
  const cv::Size small(w, std::max(1, static_cast<int>(std::lround(static_cast<double>(w) * s.image_size.height / s.image_size.width))));
  cv::Mat scene_small;
  cv::resize(scene_img, scene_small, small, 0, 0, cv::INTER_AREA);
  const double ratio = static_cast<double>(scene_img.total()) / static_cast<double>(scene_small.total());
  const std::vector<cv::Mat> sweep = sweepOverlays(m, small, options);
  double reference_b = 0;
  for (const auto& p : s.lights)
    if (p.ghost_count > 0) reference_b = std::max(reference_b, p.brightness.scale);
  if (!(reference_b > 0))
    for (const auto& p : s.lights) reference_b = std::max(reference_b, p.brightness.scale);
  if (!(reference_b > 0)) reference_b = 1.0;
  const auto dist = distributionsFromSweep(sweep, scene_small, reference_b, ratio, options.estimators);
  for (size_t k = 0; k < allEstimators().size(); ++k) {
    RatedEstimator r;
    r.estimator = allEstimators()[k];
    r.value = value(s.estimators, r.estimator);
    r.distribution = dist[k];
    r.percentile = percentile(r.distribution, r.value);
    s.ratings.push_back(std::move(r));
  }
  const size_t sev_index = static_cast<size_t>(
      std::find(allEstimators().begin(), allEstimators().end(), options.severity_estimator) - allEstimators().begin());
  for (auto& p : s.lights) {
    if (p.ghost_count == 0) continue;
    const auto d = distributionsFromSweep(sweep, scene_small, p.brightness.scale, ratio, options.estimators);
    p.severity_percentile = percentile(d[sev_index], p.severity);
  }

  // Ranking: lights with ghosts by severity (worst first), then the others in scene order.
  std::vector<size_t> order(s.lights.size());
  std::iota(order.begin(), order.end(), 0);
  const bool larger_worse = largerIsWorse(options.severity_estimator);
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    const auto& pa = s.lights[a];
    const auto& pb = s.lights[b];
    if ((pa.ghost_count > 0) != (pb.ghost_count > 0)) return pa.ghost_count > 0;
    if (pa.ghost_count == 0) return false;
    return larger_worse ? pa.severity > pb.severity : pa.severity < pb.severity;
  });
  for (size_t r = 0; r < order.size(); ++r) s.lights[order[r]].rank = static_cast<int>(r + 1);

  s.map = severityMap(m, scene_img, reference_b, options);

  if (!scene.camera_path.empty()) {
    std::vector<TimelinePoint> points(scene.camera_path.size());
    PredictOptions small_options = options;
    small_options.render.parallel = false;
    tbb::parallel_for(size_t{0}, scene.camera_path.size(), [&](size_t k) {
      const CameraPose& pose = scene.camera_path[k];
      std::vector<LightPrediction> lp;
      const cv::Mat o = renderOverlay(m, scene, pose, small, small_options, &lp);
      points[k].time_s = pose.time_s;
      points[k].severity = value(smallEstimators(o, scene_small, ratio, options.estimators), options.severity_estimator);
      points[k].lights_in_range = static_cast<int>(std::count_if(lp.begin(), lp.end(), [](const LightPrediction& p) {
        return p.geometry.status == LightStatus::kInRange;
      }));
    });
    s.timeline = std::move(points);
  }

  if (composite_out) *composite_out = scene_img + overlay;
  if (overlay_out) *overlay_out = overlay;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return s;
}

PredictionSummary predict(const model::FlareModel& m, const Scene& scene, const PredictOptions& options,
                          const std::filesystem::path& out_dir, const std::filesystem::path& model_file) {
  createFolder(out_dir);  // before the work, so a wrong --out fails at once
  cv::Mat overlay, composite;
  PredictionSummary s = analyze(m, scene, options, &overlay, &composite);
  const auto start = std::chrono::steady_clock::now();
  s.model_file = model_file;
  s.out_dir = out_dir;
  namespace fs = std::filesystem;
  const std::vector<std::string> names = {"overlay.exr", "composite.png", "estimators.json", "report.html",
                                          "view.html"};
  for (const auto& name : names) s.files.push_back(out_dir / name);
  std::error_code ec;

  // The files are made in a staging folder inside out_dir and moved in only when all are whole:
  // a failure on the way (a full disk, an interrupt) leaves out_dir as it was.
  const fs::path staging = out_dir / (".predict.tmp-" + std::to_string(::getpid()));
  fs::remove_all(staging, ec);
  if (!fs::create_directory(staging, ec))
    throw RuntimeError("cannot write in " + out_dir.string() + ": " + ec.message() + " (is it writable?)");
  try {
    ExrAttributes attributes;
    attributes["flarekit.scene"] = scene.file.string();
    attributes["flarekit.model"] = model_file.string();
    attributes["flarekit.f_number"] = scene.camera.f_number;
    attributes["flarekit.iso"] = scene.camera.iso;
    attributes["flarekit.exposure_s"] = scene.camera.exposure_s;
    writeExr(staging / names[0], overlay, attributes);
    writePreviewPng(staging / names[1], composite);
    writeJsonFile(staging / names[2], toJson(s));
    writeTextFileAtomically(staging / names[3], reportHtml(s, m, scene, composite, overlay));
    view::ViewerOptions viewer;
    viewer.source_name = model_file.filename().string();
    writeTextFileAtomically(staging / names[4], view::viewerPage(m, viewer));
    for (const auto& name : names) {
      fs::rename(staging / name, out_dir / name, ec);
      if (ec) throw RuntimeError("cannot move " + name + " into " + out_dir.string() + ": " + ec.message());
    }
  } catch (...) {
    fs::remove_all(staging, ec);
    throw;
  }
  fs::remove(staging, ec);
  s.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return s;
}

std::string PredictionSummary::BriefReport() const {
  int in = 0, out = 0, behind = 0, flaring = 0;
  const LightPrediction* worst = nullptr;
  for (const auto& p : lights) {
    if (p.geometry.status == LightStatus::kInRange) ++in;
    if (p.geometry.status == LightStatus::kOutOfRange) ++out;
    if (p.geometry.status == LightStatus::kBehindCamera) ++behind;
    if (p.ghost_count > 0) ++flaring;
    if (p.rank == 1 && p.ghost_count > 0) worst = &p;
  }
  std::ostringstream o;
  o << "Scene \"" << scene_name << "\" (" << image_size.width << " x " << image_size.height << " px): "
    << lights.size() << " lights, " << in << " within the model's range (" << flaring << " with ghosts), " << out
    << " out of range, " << behind << " behind the camera. ";
  if (worst) {
    o << "Worst light: \"" << worst->name << "\" at θ = " << cv::format("%.1f", worst->geometry.angle_deg)
      << "°, φ = " << cv::format("%.0f", worst->geometry.roll_deg) << "°, B = " << cv::format("%.3g", worst->brightness.scale)
      << " (log2 B = " << cv::format("%+.2f", worst->brightness.log2_scale) << "). ";
  } else {
    o << "No light produces ghosts. ";
  }
  if (capture_illuminance_source == "assumed")
    o << "The model does not record its capture light's illuminance: " << cv::format("%.3g", capture_illuminance_lux)
      << " lx assumed (--capture-illuminance), so absolute brightness is uncalibrated. ";
  o << "Overlay " << toString(map.estimator) << " = " << cv::format("%.4g", value(estimators, map.estimator));
  for (const auto& r : ratings)
    if (r.estimator == map.estimator && std::isfinite(r.percentile))
      o << " (percentile " << cv::format("%.0f", r.percentile) << " of the model's sampled range)";
  o << "; contrast ratio " << cv::format("%.3g", estimators.contrast_ratio) << ". Computed in "
    << cv::format("%.2f", seconds) << " s.";
  return o.str();
}

nlohmann::json toJson(const PredictionSummary& s) {
  using nlohmann::json;
  json j;
  j["format"] = "flarekit.prediction";
  j["version"] = 1;
  j["scene"] = {{"name", s.scene_name}, {"file", s.scene_file.string()}};
  j["model_file"] = s.model_file.string();
  j["capture_illuminance_lux"] = s.capture_illuminance_lux;
  j["capture_illuminance_source"] = s.capture_illuminance_source;
  j["overlay_units"] = s.overlay_in_white_units ? "fraction of the scene camera's white level" : "capture units";
  j["image_size"] = {s.image_size.width, s.image_size.height};
  j["warnings"] = s.warnings;
  j["severity_estimator"] = toString(s.map.estimator);
  j["estimators"] = toJson(s.estimators);
  json ratings = json::object();
  for (const auto& r : s.ratings) {
    ratings[toString(r.estimator)] = {{"value", number(r.value)},
                                      {"percentile", number(r.percentile)},
                                      {"larger_is_worse", largerIsWorse(r.estimator)},
                                      {"distribution", r.distribution}};
  }
  j["ratings"] = ratings;
  json lights = json::array();
  for (const auto& p : s.lights) {
    lights.push_back({{"name", p.name},
                      {"status", toString(p.geometry.status)},
                      {"angle_deg", p.geometry.angle_deg},
                      {"roll_deg", p.geometry.roll_deg},
                      {"model_angle_deg", p.geometry.model_angle_deg},
                      {"model_roll_deg", p.geometry.model_roll_deg},
                      {"image_px", {p.geometry.image_px.x, p.geometry.image_px.y}},
                      {"in_frame", p.geometry.in_frame},
                      {"illuminance_lux", p.illuminance_lux},
                      {"brightness_scale", p.brightness.scale},
                      {"log2_brightness_scale", p.illuminance_lux > 0 ? number(p.brightness.log2_scale) : json()},
                      {"ev100_capture", number(p.brightness.ev100_capture)},
                      {"ev100_scene", number(p.brightness.ev100_scene)},
                      {"ghost_count", p.ghost_count},
                      {"estimators", toJson(p.estimators)},
                      {"severity", number(p.severity)},
                      {"severity_percentile", number(p.severity_percentile)},
                      {"rank", p.rank}});
  }
  j["lights"] = lights;
  j["severity_map"] = {{"estimator", toString(s.map.estimator)},
                       {"brightness_scale", s.map.brightness},
                       {"max_angle_deg", s.map.max_angle_deg},
                       {"angles_deg", s.map.angles_deg},
                       {"rolls_deg", s.map.rolls_deg},
                       {"values", s.map.values}};
  json timeline = json::array();
  for (const auto& t : s.timeline)
    timeline.push_back({{"time_s", t.time_s}, {"severity", number(t.severity)}, {"lights_in_range", t.lights_in_range}});
  j["timeline"] = timeline;
  j["seconds"] = s.seconds;
  return j;
}

}  // namespace flarekit::predict
