#include "model/flare_model.h"

#include <cmath>
#include <numbers>
#include <set>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "common/config.h"
#include "common/error.h"

namespace flarekit::model {
namespace {

constexpr int kCheckAngles = 65;  // angles per ghost at which load checks the parameter ranges

std::string formatNumber(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

double positiveNumber(const ConfigNode& node) {
  const double v = node.number();
  if (!(v > 0)) node.fail("must be positive, got " + formatNumber(v));
  return v;
}

std::string text(const ConfigNode& node) {
  if (!node.json().is_string()) node.fail("must be a string");
  return node.string();
}

CaptureInfo parseCapture(const ConfigNode& c) {
  if (!c.isObject()) c.fail("must be a table");
  c.checkKnownKeys({"camera", "lens", "f_number", "iso", "exposure_s", "light", "image_width",
                    "image_height", "pixel_pitch_um", "angle_step_deg", "light_illuminance_lux",
                    "clip_level", "focal_length_mm", "angle_zero_deg", "optical_axis_px"});
  CaptureInfo info;
  info.camera = text(c["camera"]);
  info.lens = text(c["lens"]);
  info.f_number = positiveNumber(c["f_number"]);
  info.iso = positiveNumber(c["iso"]);
  info.exposure_s = positiveNumber(c["exposure_s"]);
  info.light = text(c["light"]);
  for (const char* key : {"image_width", "image_height"}) {
    const ConfigNode n = c[key];
    const long long v = n.integer();
    if (v <= 0 || v > 1000000) n.fail("must be a positive number of pixels, got " + std::to_string(v));
    (std::string(key) == "image_width" ? info.image_size.width : info.image_size.height) =
        static_cast<int>(v);
  }
  info.pixel_pitch_um = positiveNumber(c["pixel_pitch_um"]);
  info.angle_step_deg = positiveNumber(c["angle_step_deg"]);
  if (c.has("light_illuminance_lux")) info.light_illuminance_lux = positiveNumber(c["light_illuminance_lux"]);
  if (c.has("clip_level")) info.clip_level = positiveNumber(c["clip_level"]);
  if (c.has("focal_length_mm")) info.focal_length_mm = positiveNumber(c["focal_length_mm"]);
  if (c.has("angle_zero_deg")) {
    info.angle_zero_deg = c["angle_zero_deg"].number();
    if (!(std::abs(info.angle_zero_deg) <= 90)) c["angle_zero_deg"].fail("must be within ±90°");
  }
  if (c.has("optical_axis_px")) {
    const ConfigNode axis = c["optical_axis_px"];
    const std::vector<double> v = axis.numbers();
    if (v.size() != 2 || !std::isfinite(v[0]) || !std::isfinite(v[1]))
      axis.fail("must be [x, y], two finite numbers of pixels");
    info.optical_axis_px = cv::Point2d(v[0], v[1]);
  }
  return info;
}

// The first problem of polynomials in θ over [angle_min_deg, angle_max_deg] named `names` under
// `list_key` (a ghost's parameters, the pedestal's terms), or "": their count, the range, and each
// polynomial's coefficients. `key` gets the key the problem is at.
std::string polynomialsProblem(double angle_min_deg, double angle_max_deg,
                               const std::vector<Polynomial>& polynomials,
                               const std::vector<std::string>& names, const std::string& list_key,
                               std::string* key) {
  if (polynomials.size() != names.size()) {
    *key = list_key;
    return "has " + std::to_string(polynomials.size()) + " polynomials, expected " +
           std::to_string(names.size());
  }
  if (!std::isfinite(angle_min_deg)) {
    *key = "angle_min_deg";
    return "must be finite";
  }
  if (!std::isfinite(angle_max_deg)) {
    *key = "angle_max_deg";
    return "must be finite";
  }
  if (angle_max_deg < angle_min_deg) {
    *key = "angle_max_deg";
    return "empty angle range: " + formatNumber(angle_max_deg) + " is below angle_min_deg " +
           formatNumber(angle_min_deg);
  }
  for (size_t k = 0; k < names.size(); ++k) {
    const auto& c = polynomials[k].coefficients;
    *key = list_key + "." + names[k];
    if (c.empty()) return "needs at least one coefficient";
    if (static_cast<int>(c.size()) > kMaxPolynomialDegree + 1)
      return "has degree " + std::to_string(c.size() - 1) + ", at most " +
             std::to_string(kMaxPolynomialDegree) + " is supported";
    for (size_t i = 0; i < c.size(); ++i)
      if (!std::isfinite(c[i])) return "coefficient " + std::to_string(i) + " is not finite";
  }
  return {};
}

// The first problem of a ghost track (the checks load makes after parsing), or "".
std::string trackProblem(const GhostTrack& g, int channels, std::string* key) {
  const int n = parameterCount(channels);
  if (std::string problem = polynomialsProblem(g.angle_min_deg, g.angle_max_deg, g.parameters,
                                               parameterNames(channels), "parameters", key);
      !problem.empty())
    return problem;
  // Every parameter within its allowed range across the ghost's angle range.
  for (int k = 0; k < n; ++k) {
    const ParameterBounds b = parameterBounds(k, channels);
    for (int i = 0; i < kCheckAngles; ++i) {
      const double a = g.angle_min_deg + (g.angle_max_deg - g.angle_min_deg) * i / (kCheckAngles - 1);
      const double v = g.parameters[k].evaluate(a);
      if (!(v >= b.lower && v <= b.upper)) {
        *key = "parameters." + parameterName(k, channels);
        std::string range = "[" + formatNumber(b.lower) + ", " +
                            (b.upper == kUnbounded ? std::string("inf") : formatNumber(b.upper)) + "]";
        return "evaluates to " + formatNumber(v) + " at " + formatNumber(a) +
               " deg, outside the allowed range " + range;
      }
    }
  }
  return {};
}

// The first problem of a pedestal track, or "": as a ghost track's, without bounds on the values
// (the pedestal may be negative where it corrects the ghosts under it).
std::string pedestalProblem(const PedestalTrack& p, int channels, std::string* key) {
  return polynomialsProblem(p.angle_min_deg, p.angle_max_deg, p.terms, pedestalTermNames(channels),
                            "terms", key);
}

PedestalTrack parsePedestal(const ConfigNode& node, int channels) {
  if (!node.isObject()) node.fail("must be a table");
  node.checkKnownKeys({"angle_min_deg", "angle_max_deg", "terms"});
  PedestalTrack p;
  p.angle_min_deg = node["angle_min_deg"].number();
  p.angle_max_deg = node["angle_max_deg"].number();
  const ConfigNode terms = node["terms"];
  if (!terms.isObject()) terms.fail("must be a table of polynomials");
  terms.checkKnownKeys(pedestalTermNames(channels));
  for (const std::string& name : pedestalTermNames(channels)) {
    const ConfigNode t = terms[name];
    if (!t.isArray()) t.fail("must be an array of polynomial coefficients");
    p.terms.push_back(Polynomial{t.numbers()});
  }
  std::string key;
  const std::string problem = pedestalProblem(p, channels, &key);
  if (!problem.empty()) {
    if (key.rfind("terms.", 0) == 0) terms[key.substr(6)].fail(problem);
    node[key].fail(problem);
  }
  return p;
}

GhostTrack parseGhost(const ConfigNode& node, int channels) {
  if (!node.isObject()) node.fail("must be a table");
  node.checkKnownKeys({"id", "angle_min_deg", "angle_max_deg", "parameters"});
  GhostTrack g;
  const ConfigNode id = node["id"];
  const long long v = id.integer();
  if (v < 0 || v > 1000000000) id.fail("must be a non-negative integer, got " + std::to_string(v));
  g.id = static_cast<int>(v);
  g.angle_min_deg = node["angle_min_deg"].number();
  g.angle_max_deg = node["angle_max_deg"].number();
  const ConfigNode params = node["parameters"];
  if (!params.isObject()) params.fail("must be a table of polynomials");
  params.checkKnownKeys(parameterNames(channels));
  for (const std::string& name : parameterNames(channels)) {
    const ConfigNode p = params[name];
    if (!p.isArray()) p.fail("must be an array of polynomial coefficients");
    g.parameters.push_back(Polynomial{p.numbers()});
  }
  std::string key;
  const std::string problem = trackProblem(g, channels, &key);
  if (!problem.empty()) {
    if (key.rfind("parameters.", 0) == 0) node["parameters"][key.substr(11)].fail(problem);
    if (node.has(key)) node[key].fail(problem);
    node.fail(key + ": " + problem);
  }
  return g;
}

}  // namespace

double Polynomial::evaluate(double theta) const {
  double v = 0;
  for (size_t i = coefficients.size(); i-- > 0;) v = v * theta + coefficients[i];
  return v;
}

FlareModel FlareModel::parse(const std::string& text, const std::string& file) {
  return fromJson(parseJson(text, file));
}

FlareModel FlareModel::fromJson(const ConfigNode& root) {
  checkFormat(root, kFlareModelFormat, kFlareModelVersion);
  root.checkKnownKeys({"format", "version", "capture", "channels", "ghosts", "pedestal"});
  FlareModel m;
  m.capture = parseCapture(root["capture"]);
  const ConfigNode ch = root["channels"];
  const long long channels = ch.integer();
  if (channels != 1 && channels != 3) ch.fail("must be 1 (grey) or 3 (RGB), got " + std::to_string(channels));
  m.channels = static_cast<int>(channels);
  const ConfigNode ghosts = root["ghosts"];
  if (!ghosts.isArray()) ghosts.fail("must be an array");
  std::set<int> ids;
  for (size_t i = 0; i < ghosts.size(); ++i) {
    GhostTrack g = parseGhost(ghosts[i], m.channels);
    if (!ids.insert(g.id).second) ghosts[i]["id"].fail("duplicate ghost id " + std::to_string(g.id));
    m.ghosts.push_back(std::move(g));
  }
  if (root.has("pedestal")) m.pedestal = parsePedestal(root["pedestal"], m.channels);
  return m;
}

FlareModel FlareModel::load(const std::filesystem::path& path) {
  return fromJson(loadJsonFile(path));
}

bool FlareModel::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  const CaptureInfo& c = capture;
  if (!(c.f_number > 0) || !(c.iso > 0) || !(c.exposure_s > 0) || !(c.pixel_pitch_um > 0) ||
      !(c.angle_step_deg > 0) || !std::isfinite(c.f_number) || !std::isfinite(c.iso) ||
      !std::isfinite(c.exposure_s) || !std::isfinite(c.pixel_pitch_um) || !std::isfinite(c.angle_step_deg))
    return fail("capture: f_number, iso, exposure_s, pixel_pitch_um and angle_step_deg must be positive");
  if (c.image_size.width <= 0 || c.image_size.height <= 0) return fail("capture: image size must be positive");
  if (!(std::abs(c.angle_zero_deg) <= 90)) return fail("capture: angle_zero_deg must be within ±90°");
  if (c.optical_axis_px && (!std::isfinite(c.optical_axis_px->x) || !std::isfinite(c.optical_axis_px->y)))
    return fail("capture: optical_axis_px must be finite");
  if (!(c.light_illuminance_lux >= 0) || !std::isfinite(c.light_illuminance_lux) || !(c.clip_level >= 0) ||
      !std::isfinite(c.clip_level) || !(c.focal_length_mm >= 0) || !std::isfinite(c.focal_length_mm))
    return fail("capture: light_illuminance_lux, clip_level and focal_length_mm must be positive (or 0 = "
                "not recorded)");
  if (channels != 1 && channels != 3) return fail("channels must be 1 or 3");
  std::set<int> ids;
  for (size_t i = 0; i < ghosts.size(); ++i) {
    const GhostTrack& g = ghosts[i];
    if (g.id < 0) return fail("ghosts[" + std::to_string(i) + "].id must be non-negative");
    if (!ids.insert(g.id).second) return fail("ghosts[" + std::to_string(i) + "].id is a duplicate");
    std::string key;
    const std::string problem = trackProblem(g, channels, &key);
    if (!problem.empty()) return fail("ghosts[" + std::to_string(i) + "]." + key + ": " + problem);
  }
  if (pedestal) {
    std::string key;
    const std::string problem = pedestalProblem(*pedestal, channels, &key);
    if (!problem.empty()) return fail("pedestal." + key + ": " + problem);
  }
  return true;
}

nlohmann::json FlareModel::toJson() const {
  nlohmann::json j;
  j["format"] = kFlareModelFormat;
  j["version"] = kFlareModelVersion;
  j["capture"] = {{"camera", capture.camera},
                  {"lens", capture.lens},
                  {"f_number", capture.f_number},
                  {"iso", capture.iso},
                  {"exposure_s", capture.exposure_s},
                  {"light", capture.light},
                  {"image_width", capture.image_size.width},
                  {"image_height", capture.image_size.height},
                  {"pixel_pitch_um", capture.pixel_pitch_um},
                  {"angle_step_deg", capture.angle_step_deg}};
  if (capture.light_illuminance_lux > 0) j["capture"]["light_illuminance_lux"] = capture.light_illuminance_lux;
  if (capture.clip_level > 0) j["capture"]["clip_level"] = capture.clip_level;
  if (capture.focal_length_mm > 0) j["capture"]["focal_length_mm"] = capture.focal_length_mm;
  if (capture.angle_zero_deg != 0) j["capture"]["angle_zero_deg"] = capture.angle_zero_deg;
  if (capture.optical_axis_px)
    j["capture"]["optical_axis_px"] = {capture.optical_axis_px->x, capture.optical_axis_px->y};
  j["channels"] = channels;
  nlohmann::json list = nlohmann::json::array();
  for (const GhostTrack& g : ghosts) {
    nlohmann::json params = nlohmann::json::object();
    for (size_t k = 0; k < g.parameters.size(); ++k)
      params[parameterName(static_cast<int>(k), channels)] = g.parameters[k].coefficients;
    list.push_back({{"id", g.id},
                    {"angle_min_deg", g.angle_min_deg},
                    {"angle_max_deg", g.angle_max_deg},
                    {"parameters", params}});
  }
  j["ghosts"] = list;
  if (pedestal) {
    nlohmann::json terms = nlohmann::json::object();
    for (size_t k = 0; k < pedestal->terms.size(); ++k)
      terms[pedestalTermName(static_cast<int>(k), channels)] = pedestal->terms[k].coefficients;
    j["pedestal"] = {{"angle_min_deg", pedestal->angle_min_deg},
                     {"angle_max_deg", pedestal->angle_max_deg},
                     {"terms", terms}};
  }
  return j;
}

void FlareModel::save(const std::filesystem::path& path) const {
  std::string error;
  if (!IsValid(&error)) throw std::invalid_argument("flare model: " + error);
  writeJsonFile(path, toJson());
}

GhostParameters GhostTrack::at(double angle_deg, int channels) const {
  std::vector<double> v(parameters.size());
  for (size_t k = 0; k < v.size(); ++k) v[k] = parameters[k].evaluate(angle_deg);
  return clampToBounds(fromParameterVector(v, channels));
}

std::vector<GhostAtAngle> FlareModel::ghostsAt(double angle_deg) const {
  std::vector<GhostAtAngle> out;
  for (const GhostTrack& g : ghosts)
    if (g.covers(angle_deg)) out.push_back({g.id, g.at(angle_deg, channels)});
  return out;
}

Pedestal PedestalTrack::at(double angle_deg, int channels) const {
  Pedestal p;
  p.channels = channels;
  for (const Polynomial& t : terms) p.coefficients.push_back(t.evaluate(angle_deg));
  return p;
}

Pedestal FlareModel::pedestalAt(double angle_deg) const {
  if (!pedestal || !pedestal->covers(angle_deg)) return Pedestal{channels, {}};
  return pedestal->at(angle_deg, channels);
}

ViewTransform FlareModel::viewAt(double roll_deg, std::optional<cv::Size> size) const {
  const cv::Size s = size.value_or(capture.image_size);
  ViewTransform v;
  v.roll_rad = roll_deg * std::numbers::pi / 180.0;
  v.scale = static_cast<double>(s.width) / capture.image_size.width;
  // The image's middle shows the capture's middle; the roll turns about the optical axis.
  const cv::Point2d capture_middle(0.5 * capture.image_size.width, 0.5 * capture.image_size.height);
  v.model_center = capture.opticalAxis();
  v.image_center = cv::Point2d(0.5 * s.width, 0.5 * s.height) + (v.model_center - capture_middle) * v.scale;
  return v;
}

cv::Mat FlareModel::render(double angle_deg, double roll_deg, std::optional<cv::Size> size,
                           const RenderOptions& options) const {
  const cv::Size s = size.value_or(capture.image_size);
  std::vector<GhostParameters> params;
  for (const GhostAtAngle& g : ghostsAt(angle_deg)) params.push_back(g.parameters);
  const ViewTransform view = viewAt(roll_deg, size);
  cv::Mat image = renderGhosts(params, s, channels, options, view);
  pedestalAt(angle_deg).addTo(image, capture.image_size, view);
  return image;
}

}  // namespace flarekit::model
