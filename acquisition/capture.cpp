#include "acquisition/capture.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "acquisition/dng_writer.h"
#include "acquisition/simulated_camera.h"
#include "common/atomic_file.h"
#include "common/config.h"
#include "common/folder_lock.h"
#include "common/light_spot.h"
#include "common/log.h"
#include "common/progress.h"

namespace flarekit::acquisition {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string CaptureSummary::BriefReport() const {
  std::ostringstream s;
  s << "Capture " << termination << ": " << (frames_already_done + frames_captured) << " of "
    << frames_planned << " frames";
  if (frames_already_done) s << " (" << frames_already_done << " from before the resume)";
  s << ", " << exposures_taken << " exposures in " << formatDuration(seconds);
  if (frames_captured > 0 && seconds > 0) {
    char buf[64];
    std::snprintf(buf, sizeof buf, " (%.2f frames/s)", frames_captured / seconds);
    s << buf;
  }
  s << "; " << camera_retries << " camera and " << head_retries << " head retries";
  if (saturated_photosites) s << "; " << saturated_photosites << " photosites saturated in every exposure";
  if (!warnings.empty()) s << "; " << warnings.size() << " warnings";
  s << ". Manifest: " << manifest.string() << ".";
  return s.str();
}

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string frameName(int index) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "frame_%04d", index);
  return buf;
}

std::string headName(HeadDriver d) {
  switch (d) {
    case HeadDriver::kSimulated: return "simulated";
    case HeadDriver::kGpioStepper: return "gpio_stepper";
    case HeadDriver::kTic: return "tic";
  }
  return "?";
}

class Session {
 public:
  Session(const Rig& rig, RigDevices& devices, const CapturePlan& plan, const fs::path& out,
          const CaptureOptions& options)
      : rig_(rig), dev_(devices), plan_(plan), out_(out), options_(options) {}

  CaptureSummary run();

 private:
  Json newManifest() const;
  void checkResume(const ConfigNode& old) const;
  void writeManifest() { writeJsonFile(out_ / "manifest.json", manifest_); }
  template <class F>
  auto retry(const std::string& what, bool camera, int index, F&& fn) -> decltype(fn());
  [[noreturn]] void failPersistently(const std::string& what, int index, const DeviceError& e);
  void captureDarks();
  void captureFrame(int index, double angle_deg);
  void settle() const;
  // The simulated light's drift at plan position `index` (−1: the end-of-capture check).
  void applyLightDrift(int index);
  // Takes the light exposures at the head's angle and writes them to `file` (none when empty):
  // their manifest entry. `take` > 0: a light check's k-th photograph at a frame's angle.
  Json takeLightExposure(int index, double angle_deg, const std::string& file, int take = 0);
  // What an EXR merged from `raws` at `angle_deg` records of the camera, lens and rig.
  FrameMetadata metadataOf(const std::vector<RawFrame>& raws, double angle_deg) const;
  // plan_.light_check_repeats light exposures at the head's angle (takes first_take, …): their
  // mean flux and peak, the fluxes' spread, clipped photosites.
  Json measureLightRepeatedly(int index, double angle_deg, int first_take);
  // The light check's start, at the first frame that shows the whole light (right after it).
  void startLightCheck(int index, double angle_deg);
  // The light check's end, back at that frame's angle after the last frame; the drift.
  void checkLight();
  void updateLightStability();

  const Rig& rig_;
  RigDevices& dev_;
  const CapturePlan& plan_;
  fs::path out_;
  CaptureOptions options_;
  Json manifest_;
  std::vector<double> angles_;
  std::vector<cv::Mat> darks_;
  MergeOptions merge_;
  CaptureSummary summary_;
  int attempts_ = 0;
  SimulatedCamera* sim_camera_ = nullptr;
  std::string lens_name_;
  double focal_length_mm_ = 0;  // 0 = unknown
  double pixel_pitch_um_ = 0;
};

Json Session::newManifest() const {
  Json m;
  m["format"] = "flarekit.capture";
  m["version"] = 1;
  m["status"] = "in_progress";
  m["rig"] = {{"name", rig_.name},
              {"file", rig_.file.string()},
              {"head", headName(rig_.head_driver)},
              {"camera", rig_.camera_driver == CameraDriver::kSimulated ? "simulated" : "gphoto2"},
              {"simulated", rig_.simulated()}};
  // What a fit of the rig's imperfections is measured against; absent = an ideal rig.
  const SimulationConfig& sim = rig_.simulation;
  if (rig_.camera_driver == CameraDriver::kSimulated &&
      (sim.optical_axis_offset_px != cv::Point2d(0, 0) || sim.angle_zero_offset_deg != 0.0 ||
       sim.light_drift_pct != 0.0)) {
    m["rig"]["simulation"] = {
        {"optical_axis_offset_px", {sim.optical_axis_offset_px.x, sim.optical_axis_offset_px.y}},
        {"angle_zero_offset_deg", sim.angle_zero_offset_deg}};
    if (sim.light_drift_pct != 0.0) m["rig"]["simulation"]["light_drift_pct"] = sim.light_drift_pct;
  }
  m["lens"] = {{"name", lens_name_},
               {"file", rig_.camera_driver == CameraDriver::kSimulated
                            ? rig_.simulation.lens.string()
                            : std::string()}};
  if (focal_length_mm_ > 0) m["lens"]["focal_length_mm"] = focal_length_mm_;
  const double white = rig_.sensor.white_level_dn > 0
                           ? rig_.sensor.white_level_dn
                           : std::ldexp(1.0, rig_.sensor.bit_depth) - 1;
  m["camera"] = {{"description", dev_.camera->describe()},
                 {"iso", plan_.iso},
                 {"f_number", plan_.f_number},
                 {"exposures_s", plan_.exposures_s},
                 {"cfa", std::string(cfaName(rig_.sensor.cfa))},
                 {"black_level_dn", rig_.sensor.black_level_dn},
                 {"white_level_dn", white},
                 {"gain_e_per_dn", merge_.gain_e_per_dn},
                 {"read_noise_e", merge_.read_noise_e}};
  m["head"] = dev_.head->describe();
  m["light"] = rig_.light;
  if (rig_.light_illuminance_lux > 0) m["light_illuminance_lux"] = rig_.light_illuminance_lux;
  // The merged value at which the longest exposure clips (merged = electrons/s / output_scale):
  // prediction expresses flare as a fraction of the camera's white level with it.
  const double t_max = *std::max_element(plan_.exposures_s.begin(), plan_.exposures_s.end());
  double clip_e = (white - rig_.sensor.black_level_dn) * merge_.gain_e_per_dn;
  if (rig_.sensor.full_well_e > 0) clip_e = std::min(clip_e, rig_.sensor.full_well_e);
  m["image"] = {{"width", 0},
                {"height", 0},
                {"channels", rig_.sensor.cfa == Cfa::kMono ? "Y" : "RGB"},
                {"pixel_pitch_um", pixel_pitch_um_},
                {"clip_level", clip_e / (t_max * merge_.output_scale)},
                {"pixel_type", options_.half_frames ? "half" : "float"},
                {"units", rig_.camera_driver == CameraDriver::kSimulated
                              ? "relative irradiance (render units)"
                              : "electrons/s"}};
  m["plan"] = {{"from_deg", plan_.from_deg}, {"to_deg", plan_.to_deg},
               {"step_deg", plan_.step_deg}, {"angles_deg", angles_},
               {"exposures_s", plan_.exposures_s}, {"dark_frames", plan_.dark_frames},
               {"keep_raw", plan_.keep_raw}};
  // Recorded only when used, so that captures without them keep their manifests.
  if (plan_.settle_s > 0) m["plan"]["settle_s"] = plan_.settle_s;
  if (!plan_.light_exposures_s.empty()) {
    m["plan"]["light_exposures_s"] = plan_.light_exposures_s;
    m["plan"]["light_nd_factor"] = plan_.light_nd_factor;
    m["plan"]["light_check_repeats"] = plan_.light_check_repeats;
    m["light_stability"] = {{"frames", 0}, {"reference_frame_index", nullptr},
                            {"drift_pct", nullptr}, {"scatter_pct", nullptr}};
  }
  m["truth"] = sim_camera_ != nullptr && options_.write_truth;
  m["frames"] = Json::array();
  m["darks"] = Json::array();
  m["frames_done"] = 0;
  m["frames_planned"] = static_cast<int>(angles_.size());
  return m;
}

void Session::checkResume(const ConfigNode& old) const {
  const std::string file = (out_ / "manifest.json").string();
  auto differs = [&](const std::string& what, const Json& a, const Json& b) {
    if (a != b)
      throw InputError(file, "cannot resume: the " + what + " differs from the stopped session (" +
                                 jsonText(a, -1) + " there, " + jsonText(b, -1) + " now); resume with the same "
                                 "rig and options, or capture into a new folder");
  };
  const Json fresh = newManifest();
  differs("rig name", old["rig"]["name"].json(), fresh["rig"]["name"]);
  differs("angle plan", old["plan"]["angles_deg"].json(), fresh["plan"]["angles_deg"]);
  differs("exposure bracket", old["plan"]["exposures_s"].json(), fresh["plan"]["exposures_s"]);
  differs("number of dark frames", old["plan"]["dark_frames"].json(), fresh["plan"]["dark_frames"]);
  differs("ISO", old["camera"]["iso"].json(), fresh["camera"]["iso"]);
  differs("f-number", old["camera"]["f_number"].json(), fresh["camera"]["f_number"]);
  const auto simulation = old["rig"].find("simulation");
  differs("rig's simulated axis offset, angle zero or light drift",
          simulation ? simulation->json() : Json(), fresh["rig"].value("simulation", Json()));
  for (const char* key : {"light_exposures_s", "light_nd_factor", "light_check_repeats", "settle_s"}) {
    const auto was = old["plan"].find(key);
    differs(std::string("plan's ") + key, was ? was->json() : Json(), fresh["plan"].value(key, Json()));
  }
}

template <class F>
auto Session::retry(const std::string& what, bool camera, int index, F&& fn) -> decltype(fn()) {
  for (int attempt = 0;; ++attempt) {
    try {
      ++attempts_;
      return fn();
    } catch (const DeviceError& e) {
      if (!e.transient() || attempt >= plan_.max_retries) failPersistently(what, index, e);
      logWarning(std::string(e.what()) + "; retrying " + what + " (" + std::to_string(attempt + 1) +
                 " of " + std::to_string(plan_.max_retries) + ")");
      (camera ? summary_.camera_retries : summary_.head_retries)++;
      if (plan_.retry_delay_s > 0)
        std::this_thread::sleep_for(std::chrono::duration<double>(plan_.retry_delay_s));
      try {
        if (camera)
          dev_.camera->reconnect();
        else
          dev_.head->reconnect();
      } catch (const DeviceError&) {
        // The next attempt reports the problem.
      }
    }
  }
}

void Session::failPersistently(const std::string& what, int index, const DeviceError& e) {
  std::ostringstream where;
  if (index >= 0)
    where << " at frame " << index << " (" << angles_[index] << "°)";
  std::string message = what + " failed" + where.str() + ": " + e.what() + ". The session in " +
                        out_.string() + " is saved (" +
                        std::to_string(manifest_["frames"].size()) + " of " +
                        std::to_string(angles_.size()) +
                        " frames done): fix the device, then run flarekit capture --rig " +
                        rig_.file.string() + " --out " + out_.string() + " --resume";
  manifest_["status"] = "failed";
  manifest_["error"] = message;
  writeManifest();
  throw RuntimeError(message);
}

void Session::captureDarks() {
  if (plan_.dark_frames <= 0) return;
  const auto& old = manifest_["darks"];
  if (old.size() == plan_.exposures_s.size()) {
    bool all = true;
    for (const auto& d : old) all = all && fs::exists(out_ / d["file"].get<std::string>());
    if (all) {
      for (const auto& d : old) darks_.push_back(readExrLayer(out_ / d["file"].get<std::string>(), ""));
      return;
    }
  }
  logInfo("Taking " + std::to_string(plan_.dark_frames) + " dark frames per exposure");
  createFolder(out_ / "darks");
  Json entries = Json::array();
  for (size_t k = 0; k < plan_.exposures_s.size(); ++k) {
    const double t = plan_.exposures_s[k];
    cv::Mat sum;
    for (int j = 0; j < plan_.dark_frames; ++j) {
      RawFrame f = retry("dark frame", true, -1, [&] {
        dev_.camera->setExposure(t);
        return dev_.camera->captureDark();
      });
      ++summary_.exposures_taken;
      cv::Mat v;
      f.data.convertTo(v, CV_32F);
      if (sum.empty())
        sum = v;
      else
        sum += v;
    }
    sum /= plan_.dark_frames;
    const std::string file = "darks/dark_" + std::to_string(k) + ".exr";
    writeExr(out_ / file, sum, {{"flarekit.exposure_s", t}, {"flarekit.units", std::string("DN")}});
    darks_.push_back(sum);
    entries.push_back({{"exposure_s", t}, {"file", file}, {"frames", plan_.dark_frames}});
  }
  manifest_["darks"] = entries;
  writeManifest();
}

void Session::settle() const {
  if (plan_.settle_s > 0)
    std::this_thread::sleep_for(std::chrono::duration<double>(plan_.settle_s));
}

void Session::applyLightDrift(int index) {
  if (!sim_camera_ || rig_.simulation.light_drift_pct == 0.0) return;
  const int n = static_cast<int>(angles_.size());
  const double progress = index < 0 ? 1.0 : n > 1 ? static_cast<double>(index) / (n - 1) : 0.0;
  sim_camera_->setLightScale(1.0 + rig_.simulation.light_drift_pct / 100.0 * progress);
}

FrameMetadata Session::metadataOf(const std::vector<RawFrame>& raws, double angle_deg) const {
  FrameMetadata meta;
  meta.angle_deg = angle_deg;
  meta.has_angle = true;
  for (const auto& r : raws) meta.exposures_s.push_back(r.exposure_s);
  meta.iso = raws[0].iso > 0 ? raws[0].iso : plan_.iso;
  meta.f_number = raws[0].f_number > 0 ? raws[0].f_number : plan_.f_number;
  meta.camera = raws[0].camera;
  meta.lens = lens_name_;
  meta.rig = rig_.name;
  meta.pixel_pitch_um = pixel_pitch_um_;
  meta.focal_length_mm = focal_length_mm_;
  meta.units = manifest_["image"]["units"].get<std::string>();
  return meta;
}

Json Session::takeLightExposure(int index, double angle_deg, const std::string& file, int take) {
  const double nd = plan_.light_nd_factor;
  std::vector<RawFrame> raws;
  for (double t : plan_.light_exposures_s) {
    raws.push_back(retry("capturing the " + std::to_string(t) + " s light exposure", true, index, [&] {
      dev_.camera->setExposure(t);
      if (!sim_camera_) return dev_.camera->capture();
      // The simulated camera sees the light through the declared filter for this exposure only.
      struct Filter {
        SimulatedCamera* c;
        ~Filter() { c->setLightExposure(false); }
      } filter{sim_camera_};
      sim_camera_->setLightExposure(true, nd, take);
      return dev_.camera->capture();
    }));
    ++summary_.exposures_taken;
  }
  // Merged as the frames are (demosaiced alike), then times what the filter took.
  MergeResult merged = mergeBracket(raws, merge_);
  const FrameMetadata meta = metadataOf(raws, angle_deg);
  ExrImage exr = mergedToExr(merged, meta);
  if (nd != 1.0) exr.layers.front().image *= nd;
  exr.attributes["flarekit.light_nd_factor"] = nd;
  exr.attributes["flarekit.light_exposure"] =
      std::string("the light's own exposures, merged apart from the frames; values times the ND factor");
  if (!file.empty()) {
    createFolder(out_ / "light");
    writeExr(out_ / file, exr);
  }
  const ExrLayer* sat = exr.find("saturated");
  const LightSpot spot = measureLightSpot(exr.main(), sat ? sat->image : cv::Mat());
  Json e = {{"file", file.empty() ? Json() : Json(file)},
            {"exposures_s", meta.exposures_s},
            {"nd_factor", nd},
            {"found", spot.found},
            {"center_px", {spot.center.x, spot.center.y}},
            {"peak", spot.peak},
            {"flux", spot.flux},
            {"flux_radius_px", spot.flux_radius_px},
            {"cut", spot.cut},
            {"saturated_photosites", merged.saturated_count}};
  if (file.empty()) e.erase("file");
  if (merged.saturated_count > 0) {
    const std::string w = "frame " + std::to_string(index) + (take > 0 ? " (light check)" : "") +
                          ": the light exposure clipped (" +
                          std::to_string(merged.saturated_count) +
                          " photosites): its flux and peak are lower bounds; shorten the "
                          "shortest light_exposure_s or declare a denser light_nd_factor";
    logWarning(w);
    summary_.warnings.push_back(w);
  }
  return e;
}

void Session::captureFrame(int index, double angle_deg) {
  attempts_ = 0;
  retry("moving the head to " + std::to_string(angle_deg) + "°", false, index,
        [&] { dev_.head->moveTo(angle_deg); });
  settle();
  applyLightDrift(index);
  std::vector<RawFrame> bracket;
  for (double t : plan_.exposures_s) {
    bracket.push_back(retry("capturing the " + std::to_string(t) + " s exposure", true, index, [&] {
      dev_.camera->setExposure(t);
      return dev_.camera->capture();
    }));
    ++summary_.exposures_taken;
  }
  const std::string name = frameName(index);
  Json light;
  if (!plan_.light_exposures_s.empty()) light = takeLightExposure(index, angle_deg, "light/" + name + ".exr");
  MergeResult merged = mergeBracket(bracket, merge_, darks_);
  for (const auto& w : merged.warnings) {
    logWarning("frame " + std::to_string(index) + ": " + w);
    summary_.warnings.push_back("frame " + std::to_string(index) + ": " + w);
  }
  const FrameMetadata meta = metadataOf(bracket, angle_deg);
  Json entry = {{"index", index},
                {"angle_deg", angle_deg},
                {"file", "frames/" + name + ".exr"},
                {"exposures_s", meta.exposures_s},
                {"saturated_photosites", merged.saturated_count}};
  Json ratios = Json::array();
  for (const auto& c : merged.ratio_checks) ratios.push_back(c.measured_ratio);
  entry["exposure_ratios"] = ratios;
  if (!light.is_null()) entry["light"] = light;
  if (!light.is_null() && !manifest_.contains("light_check") && light["found"].get<bool>() &&
      !light["cut"].get<bool>() && light["saturated_photosites"].get<long long>() == 0)
    startLightCheck(index, angle_deg);

  if (plan_.keep_raw) {
    createFolder(out_ / "raw");
    Json raws = Json::array();
    for (size_t k = 0; k < bracket.size(); ++k) {
      // Bayer frames as DNG (black/white levels and EXIF exposure travel with them, and
      // `flarekit merge` reads them back); mono frames as 16-bit PNG (LibRaw 0.20 cannot read
      // monochrome DNGs), their levels and exposure in the manifest.
      const bool dng = bracket[k].cfa != Cfa::kMono;
      const std::string file =
          "raw/" + name + "_e" + std::to_string(k) + (dng ? ".dng" : ".png");
      if (dng) {
        DngMetadata dng;
        dng.model = bracket[k].camera;
        dng.focal_length_mm = focal_length_mm_;
        writeDng(out_ / file, bracket[k], dng);
      } else {
        writeFileAtomically(out_ / file, [&](const fs::path& tmp) {
          if (!cv::imwrite(tmp.string(), bracket[k].data))
            throw RuntimeError(tmp.string() + ": cannot write the RAW frame");
        });
      }
      raws.push_back({{"file", file},
                      {"exposure_s", bracket[k].exposure_s},
                      {"black_level_dn", bracket[k].black_level},
                      {"white_level_dn", bracket[k].white_level}});
    }
    entry["raw_files"] = raws;
  }
  if (sim_camera_ && options_.write_truth) {
    ExrImage truth = sim_camera_->scene().truth(angle_deg, sim_camera_->fNumber());
    truth.attributes["flarekit.angle_deg"] = angle_deg;
    // A drifting light: the truth is what the frame saw.
    if (const double scale = sim_camera_->lightScale(); scale != 1.0) {
      for (auto& layer : truth.layers) layer.image *= scale;
      truth.attributes["flarekit.light_scale"] = scale;
    }
    // Half precision (3 significant digits, far below the frames' noise) keeps truth/ small;
    // float when a value would overflow half (the light's own image of a bright scene).
    double peak = 0;
    for (const auto& layer : truth.layers) {
      double lo, hi;
      cv::minMaxLoc(layer.image.reshape(1), &lo, &hi);
      peak = std::max({peak, std::abs(lo), std::abs(hi)});
    }
    ExrWriteOptions write;
    write.pixel_type = peak < 60000 ? ExrPixelType::kHalf : ExrPixelType::kFloat;
    createFolder(out_ / "truth");
    writeExr(out_ / ("truth/" + name + ".exr"), truth, write);
    entry["truth_file"] = "truth/" + name + ".exr";
  }
  // The frame last: the manifest lists a frame only after all its files are whole.
  ExrImage frame = mergedToExr(merged, meta);
  ExrWriteOptions frame_write;
  if (options_.half_frames) {
    double lo, hi;
    cv::minMaxLoc(frame.main().reshape(1), &lo, &hi);
    if (std::max(std::abs(lo), std::abs(hi)) < 60000) frame_write.pixel_type = ExrPixelType::kHalf;
  }
  writeExr(out_ / ("frames/" + name + ".exr"), frame, frame_write);
  // Device calls beyond the one move and one capture per exposure: the retries this frame took.
  entry["retries"] = attempts_ - 1 - static_cast<int>(plan_.exposures_s.size());
  manifest_["camera"]["white_level_dn"] = bracket[0].white_level;
  manifest_["camera"]["black_level_dn"] = bracket[0].black_level;
  manifest_["image"]["width"] = bracket[0].data.cols;
  manifest_["image"]["height"] = bracket[0].data.rows;
  manifest_["frames"].push_back(entry);
  manifest_["frames_done"] = static_cast<int>(manifest_["frames"].size());
  if (!plan_.light_exposures_s.empty()) updateLightStability();
  writeManifest();
  summary_.saturated_photosites += merged.saturated_count;
}

void Session::updateLightStability() {
  // The frames whose light exposure holds the whole light, in plan order.
  std::vector<double> angles, fluxes;
  int reference = -1;
  bool clipped = false;
  std::vector<Json> frames(manifest_["frames"].begin(), manifest_["frames"].end());
  std::sort(frames.begin(), frames.end(),
            [](const Json& a, const Json& b) { return a["index"] < b["index"]; });
  for (const Json& f : frames) {
    // Frames of a resumed session are as their manifest said: only well-formed entries count.
    const Json* l = f.contains("light") && f["light"].is_object() ? &f["light"] : nullptr;
    if (!l || !f["angle_deg"].is_number()) continue;
    const auto number = [&](const char* key) {
      return l->contains(key) && (*l)[key].is_number() ? (*l)[key].get<double>() : kNaN;
    };
    const auto flag = [&](const char* key, bool fallback) {
      return l->contains(key) && (*l)[key].is_boolean() ? (*l)[key].get<bool>() : fallback;
    };
    const double saturated = number("saturated_photosites"), flux = number("flux");
    if (saturated > 0) clipped = true;
    if (!flag("found", false) || flag("cut", true) || !(saturated == 0) || !std::isfinite(flux)) continue;
    if (reference < 0) reference = f["index"].get<int>();
    angles.push_back(f["angle_deg"].get<double>());
    fluxes.push_back(flux);
  }
  Json st = {{"frames", static_cast<int>(fluxes.size())},
             {"reference_frame_index", reference < 0 ? Json() : Json(reference)},
             {"drift_pct", nullptr},
             {"scatter_pct", nullptr}};
  // Scatter: RMS about a quadratic in the angle (the lens's own fall-off and a slow drift are
  // smooth in it; flicker is not), in % of the mean.
  if (fluxes.size() >= 5) {
    const int n = static_cast<int>(fluxes.size());
    double a_mean = 0, mean = 0;
    for (int i = 0; i < n; ++i) {
      a_mean += angles[i] / n;
      mean += fluxes[i] / n;
    }
    cv::Mat A(n, 3, CV_64F), b(n, 1, CV_64F), x;
    for (int i = 0; i < n; ++i) {
      const double u = angles[i] - a_mean;
      A.at<double>(i, 0) = 1;
      A.at<double>(i, 1) = u;
      A.at<double>(i, 2) = u * u;
      b.at<double>(i) = fluxes[i];
    }
    if (cv::solve(A, b, x, cv::DECOMP_SVD) && mean > 0) {
      const cv::Mat r = A * x - b;
      st["scatter_pct"] = 100.0 * std::sqrt(r.dot(r) / n) / mean;
    }
  }
  if (manifest_.contains("light_check")) {
    const Json& c = manifest_["light_check"];
    st["reference_frame_index"] = c["frame_index"];
    if (c.contains("end")) {
      const double f0 = c["start"]["flux"].get<double>(), f1 = c["end"]["flux"].get<double>();
      if (f0 > 0 && c["start"]["saturated_photosites"].get<long long>() == 0 &&
          c["end"]["saturated_photosites"].get<long long>() == 0)
        st["drift_pct"] = 100.0 * (f1 / f0 - 1.0);
      else
        clipped = true;
    }
  }
  std::vector<std::string> problems;
  if (st["drift_pct"].is_number() && std::abs(st["drift_pct"].get<double>()) > 1.0) {
    char b[96];
    std::snprintf(b, sizeof b, "the light drifted %+.2f %% over the capture", st["drift_pct"].get<double>());
    problems.push_back(b);
  }
  if (st["scatter_pct"].is_number() && st["scatter_pct"].get<double>() > 1.0) {
    char b[96];
    std::snprintf(b, sizeof b, "the light's flux scatters %.2f %% from frame to frame", st["scatter_pct"].get<double>());
    problems.push_back(b);
  }
  if (clipped) problems.push_back("a light exposure clipped (its flux is a lower bound)");
  if (!problems.empty()) {
    std::string w;
    for (const auto& p : problems) w += (w.empty() ? "" : "; ") + p;
    st["warning"] = w + " (more than 1 %: figures normalised by the light are less certain)";
  }
  manifest_["light_stability"] = st;
}

Json Session::measureLightRepeatedly(int index, double angle_deg, int first_take) {
  const int n = plan_.light_check_repeats;
  std::vector<double> fluxes;
  double peak = 0;
  long long clipped = 0;
  for (int k = 0; k < n; ++k) {
    const Json e = takeLightExposure(index, angle_deg, "", first_take + k);
    fluxes.push_back(e["flux"].get<double>());
    peak += e["peak"].get<double>() / n;
    clipped += e["saturated_photosites"].get<long long>();
  }
  double mean = 0, var = 0;
  for (double f : fluxes) mean += f / n;
  for (double f : fluxes) var += (f - mean) * (f - mean) / std::max(1, n - 1);
  return {{"flux", mean},
          {"flux_sd_pct", mean > 0 && n > 1 ? Json(100.0 * std::sqrt(var) / mean) : Json()},
          {"peak", peak},
          {"saturated_photosites", clipped},
          {"fluxes", fluxes}};
}

void Session::startLightCheck(int index, double angle_deg) {
  manifest_["light_check"] = {{"frame_index", index},
                              {"angle_deg", angle_deg},
                              {"repeats", plan_.light_check_repeats},
                              {"start", measureLightRepeatedly(index, angle_deg, 1)}};
}

void Session::checkLight() {
  if (plan_.light_exposures_s.empty()) return;
  if (!manifest_.contains("light_check")) {
    const std::string w = "no frame's light exposure holds the whole, unclipped light: the light's drift cannot "
                          "be measured (a sweep that passes the optical axis can)";
    logWarning(w);
    summary_.warnings.push_back(w);
    updateLightStability();
    return;
  }
  Json& check = manifest_["light_check"];
  const int index = check["frame_index"].get<int>();
  const double angle = angles_[index];
  attempts_ = 0;
  retry("moving the head back to " + std::to_string(angle) + "° for the light check", false, index,
        [&] { dev_.head->moveTo(angle); });
  settle();
  applyLightDrift(-1);
  check["end"] = measureLightRepeatedly(index, angle, 1 + plan_.light_check_repeats);
  updateLightStability();
  const Json& done = manifest_["light_stability"];
  if (done.contains("warning")) {
    logWarning(done["warning"].get<std::string>());
    summary_.warnings.push_back(done["warning"].get<std::string>());
  }
}

CaptureSummary Session::run() {
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  if (!plan_.IsValid(&error)) throw InputError("capture plan: " + error);
  angles_ = plan_.anglesDeg();
  checkPlanForRig(rig_, plan_);
  merge_ = mergeOptionsForRig(rig_, plan_.iso);
  sim_camera_ = dynamic_cast<SimulatedCamera*>(dev_.camera.get());
  if (sim_camera_) {
    lens_name_ = sim_camera_->scene().lensName();
    pixel_pitch_um_ = sim_camera_->scene().pixelPitchUm();
    focal_length_mm_ = sim_camera_->scene().focalLengthMm();
  } else {
    lens_name_ = rig_.lens.name;
    pixel_pitch_um_ = rig_.sensor.pixel_pitch_um;
    focal_length_mm_ = rig_.lens.focal_length_mm;
  }

  const fs::path manifest_path = out_ / "manifest.json";
  std::error_code ec;
  if (options_.resume && !fs::exists(manifest_path, ec))
    throw InputError(out_.string() + ": no capture to resume (no manifest.json)");
  if (fs::exists(out_, ec) && !fs::is_directory(out_, ec))
    throw InputError(out_.string() + ": exists and is not a folder");
  createFolder(out_);
  // Held until the session ends: one process per capture folder, and so per rig.
  const FolderLock lock(out_);
  std::set<int> done;
  if (options_.resume) {
    const ConfigNode root = loadJsonFile(manifest_path);
    checkFormat(root, "flarekit.capture", 1);
    checkResume(root);
    // Taken over from the stopped session: what it measured, each field read with its type so a
    // damaged manifest is named, not half used.
    manifest_ = newManifest();
    if (const auto image = root.find("image")) {
      manifest_["image"]["width"] = image->integer("width", 0);
      manifest_["image"]["height"] = image->integer("height", 0);
    }
    if (const auto darks = root.find("darks")) {
      for (size_t k = 0; k < darks->size(); ++k) {
        const ConfigNode d = (*darks)[k];
        manifest_["darks"].push_back({{"exposure_s", d["exposure_s"].number()},
                                      {"file", d["file"].string()},
                                      {"frames", d["frames"].integer()}});
      }
    }
    // The light check's start, taken at a frame of the stopped session.
    if (const auto check = root.find("light_check"); check && check->isObject() && !plan_.light_exposures_s.empty()) {
      // Each field read with its type, so that a damaged manifest is named, not half used.
      const long long index = (*check)["frame_index"].integer();
      const ConfigNode start = (*check)["start"];
      const Json fluxes = start["fluxes"].numbers();
      if (index >= 0 && index < static_cast<long long>(angles_.size()))
        manifest_["light_check"] = {{"frame_index", index},
                                    {"angle_deg", angles_[index]},
                                    {"repeats", (*check)["repeats"].integer()},
                                    {"start", {{"flux", start["flux"].number()},
                                               {"peak", start["peak"].number()},
                                               {"saturated_photosites", start["saturated_photosites"].integer()},
                                               {"fluxes", fluxes}}}};
    }
    const ConfigNode frames = root["frames"];
    for (size_t k = 0; k < frames.size(); ++k) {
      const ConfigNode f = frames[k];
      const long long index = f["index"].integer();
      const std::string file = f["file"].string();
      if (index < 0 || index >= static_cast<long long>(angles_.size()) || done.count(static_cast<int>(index)))
        continue;
      if (!fs::exists(out_ / file)) continue;  // lost: capture again
      done.insert(static_cast<int>(index));
      manifest_["frames"].push_back(f.json());
    }
    summary_.frames_already_done = static_cast<int>(done.size());
    logInfo("Resuming " + out_.string() + ": " + std::to_string(done.size()) + " of " +
            std::to_string(angles_.size()) + " frames done");
  } else {
    if (fs::exists(manifest_path, ec))
      throw InputError(out_.string() +
                       ": already holds a capture (manifest.json); add --resume to continue it, "
                       "or choose another folder");
    manifest_ = newManifest();
  }
  // A capture killed while writing leaves at worst stray temporaries of the atomic writes; they
  // belong to no frame. Resumed or not: a capture killed during its first manifest write has a
  // stray temporary and no manifest, and is started again without --resume.
  removeStrayTemporaries(out_);
  createFolder(out_ / "frames");
  manifest_["frames_done"] = static_cast<int>(manifest_["frames"].size());
  writeManifest();

  summary_.frames_planned = static_cast<int>(angles_.size());
  summary_.manifest = manifest_path;
  // Sorted frames in plan order (resume may have appended out of order).
  auto sortFrames = [&] {
    auto& frames = manifest_["frames"];
    std::sort(frames.begin(), frames.end(),
              [](const Json& a, const Json& b) { return a["index"] < b["index"]; });
  };

  retry("setting the camera", true, -1, [&] {
    dev_.camera->setIso(plan_.iso);
    dev_.camera->setAperture(plan_.f_number);
  });
  retry("homing the head", false, -1, [&] { dev_.head->home(); });
  captureDarks();

  const int remaining = static_cast<int>(angles_.size() - done.size());
  bool interrupted = false;
  {
    Progress progress("capture", remaining);
    for (int i = 0; i < static_cast<int>(angles_.size()); ++i) {
      if (done.count(i)) continue;
      if (options_.stop_requested && options_.stop_requested->load()) {
        interrupted = true;
        break;
      }
      captureFrame(i, angles_[i]);
      sortFrames();
      ++summary_.frames_captured;
      if (options_.progress) progress.advance();
    }
  }
  if (!interrupted) checkLight();
  summary_.termination = interrupted ? "interrupted" : "complete";
  manifest_["status"] = summary_.termination;
  manifest_.erase("error");
  writeManifest();
  summary_.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary_;
}

}  // namespace

CaptureSummary runCapture(const Rig& rig, RigDevices& devices, const CapturePlan& plan,
                          const fs::path& out, const CaptureOptions& options) {
  if (!devices.head || !devices.camera) throw std::logic_error("runCapture: devices not open");
  Session session(rig, devices, plan, out, options);
  return session.run();
}

}  // namespace flarekit::acquisition
