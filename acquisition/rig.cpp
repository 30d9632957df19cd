#include "acquisition/rig.h"

#include <arpa/inet.h>

#include <cmath>
#include <cstdlib>
#include <sstream>

#include "common/config.h"
#include "common/shipped_file.h"

namespace flarekit::acquisition {
namespace {

double positive(const ConfigNode& n, std::string_view key, double fallback) {
  if (!n.has(key)) return fallback;
  double v = n[key].number();
  if (!(v > 0)) n[key].fail("must be positive, got " + std::to_string(v));
  return v;
}
double nonNegative(const ConfigNode& n, std::string_view key, double fallback) {
  if (!n.has(key)) return fallback;
  double v = n[key].number();
  if (!(v >= 0)) n[key].fail("must be ≥ 0, got " + std::to_string(v));
  return v;
}
double probability(const ConfigNode& n, std::string_view key) {
  if (!n.has(key)) return 0;
  double v = n[key].number();
  if (!(v >= 0 && v <= 1)) n[key].fail("must be a probability in [0, 1], got " + std::to_string(v));
  return v;
}
int integerIn(const ConfigNode& n, std::string_view key, int fallback, long long lo, long long hi) {
  if (!n.has(key)) return fallback;
  long long v = n[key].integer();
  if (v < lo || v > hi)
    n[key].fail("must be an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                "], got " + std::to_string(v));
  return static_cast<int>(v);
}
std::string text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}
int sign(const ConfigNode& n, std::string_view key, int fallback) {
  if (!n.has(key)) return fallback;
  std::string s = n[key].string();
  if (s == "positive" || s == "+") return +1;
  if (s == "negative" || s == "-") return -1;
  n[key].fail("must be \"positive\" or \"negative\", got \"" + s + "\"");
}

void parseGeometry(const ConfigNode& h, StepperGeometry& g) {
  g.full_steps_per_rev = integerIn(h, "full_steps_per_rev", g.full_steps_per_rev, 1, 100000);
  if (h.has("microsteps")) {
    long long m = h["microsteps"].integer();
    if (m < 1 || m > 256 || (m & (m - 1)))
      h["microsteps"].fail("must be a power of two from 1 to 256, got " + std::to_string(m));
    g.microsteps = static_cast<int>(m);
  }
  g.gear_ratio = positive(h, "gear_ratio", g.gear_ratio);
  g.max_speed_deg_s = positive(h, "max_speed_deg_s", g.max_speed_deg_s);
  g.accel_deg_s2 = positive(h, "accel_deg_s2", g.accel_deg_s2);
  g.backlash_deg = nonNegative(h, "backlash_deg", g.backlash_deg);
  g.approach_sign = sign(h, "approach", g.approach_sign);
  if (h.has("soft_limits_deg")) {
    auto v = h["soft_limits_deg"].numbers();
    if (v.size() != 2 || !(v[0] < v[1]))
      h["soft_limits_deg"].fail("must be [min, max] with min < max");
    g.min_deg = v[0];
    g.max_deg = v[1];
  }
  g.home_angle_deg = h.number("home_angle_deg", g.home_angle_deg);
  g.home_direction = sign(h, "home_direction", g.home_direction);
  g.home_search_deg = positive(h, "home_search_deg", g.home_search_deg);
  g.home_speed_deg_s = positive(h, "home_speed_deg_s", g.home_speed_deg_s);
  g.home_backoff_deg = nonNegative(h, "home_backoff_deg", g.home_backoff_deg);
  if (g.home_angle_deg < g.min_deg || g.home_angle_deg > g.max_deg)
    h["home_angle_deg"].fail("lies outside soft_limits_deg");
}

const std::vector<std::string> kGeometryKeys = {
    "full_steps_per_rev", "microsteps", "gear_ratio", "max_speed_deg_s", "accel_deg_s2",
    "backlash_deg", "approach", "soft_limits_deg", "home_angle_deg", "home_direction",
    "home_search_deg", "home_speed_deg_s", "home_backoff_deg"};

std::vector<std::string> with(std::vector<std::string> a, const std::vector<std::string>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

void parseHead(const ConfigNode& h, Rig& rig) {
  std::string driver = h["driver"].string();
  if (h.has("settle_s")) {
    const double s = h["settle_s"].number();
    if (!(s >= 0 && s <= 60)) h["settle_s"].fail("must be in [0, 60] seconds, got " + text(s));
    rig.settle.settle_s = s;
  }
  if (driver == "simulated") {
    rig.head_driver = HeadDriver::kSimulated;
    h.checkKnownKeys({"driver", "speed_deg_s", "settle_s"});
    rig.simulated_head.speed_deg_s = nonNegative(h, "speed_deg_s", 0);
  } else if (driver == "gpio_stepper") {
    rig.head_driver = HeadDriver::kGpioStepper;
    h.checkKnownKeys(with({"driver", "settle_s", "chip", "step_line", "dir_line", "enable_line",
                           "enable_active_low", "dir_high_is_positive", "home_line",
                           "home_active_low", "step_pulse_us", "dir_setup_us"},
                          kGeometryKeys));
    auto& g = rig.gpio;
    g.chip = h["chip"].string();
    if (g.chip.empty()) h["chip"].fail("must name a gpiochip (\"gpiochip0\", a path or a label)");
    g.step_line = integerIn(h, "step_line", -1, 0, 1023);
    g.dir_line = integerIn(h, "dir_line", -1, 0, 1023);
    if (!h.has("step_line")) h["step_line"];  // throws "missing key"
    if (!h.has("dir_line")) h["dir_line"];
    g.enable_line = integerIn(h, "enable_line", -1, -1, 1023);
    g.home_line = integerIn(h, "home_line", -1, -1, 1023);
    g.enable_active_low = h.boolean("enable_active_low", g.enable_active_low);
    g.dir_high_is_positive = h.boolean("dir_high_is_positive", g.dir_high_is_positive);
    g.home_active_low = h.boolean("home_active_low", g.home_active_low);
    g.step_pulse_us = positive(h, "step_pulse_us", g.step_pulse_us);
    g.dir_setup_us = nonNegative(h, "dir_setup_us", g.dir_setup_us);
    std::vector<int> used = {g.step_line, g.dir_line};
    if (g.step_line == g.dir_line) h["dir_line"].fail("must differ from step_line");
    for (auto [key, line] : {std::pair{"enable_line", g.enable_line}, {"home_line", g.home_line}})
      if (line >= 0 && (line == g.step_line || line == g.dir_line))
        h[key].fail("must differ from step_line and dir_line");
    parseGeometry(h, g.geometry);
  } else if (driver == "tic") {
    rig.head_driver = HeadDriver::kTic;
    h.checkKnownKeys(with({"driver", "settle_s", "serial", "step_mode_microsteps",
                           "command_timeout_s", "move_timeout_s"},
                          kGeometryKeys));
    auto& t = rig.tic;
    t.serial = h.string("serial", "");
    parseGeometry(h, t.geometry);
    t.step_mode_microsteps = t.geometry.microsteps;
    t.command_timeout_s = positive(h, "command_timeout_s", t.command_timeout_s);
    t.move_timeout_s = positive(h, "move_timeout_s", t.move_timeout_s);
  } else {
    h["driver"].fail("must be \"simulated\", \"gpio_stepper\" or \"tic\", got \"" + driver + "\"");
  }
}

// "ptpip:192.168.1.1" or "ptpip:192.168.1.1:15740": what libgphoto2's PTP/IP port connects to.
bool validPtpIpPort(const std::string& port) {
  std::string rest = port.substr(6);
  const auto colon = rest.find(':');
  if (colon != std::string::npos) {
    const std::string number = rest.substr(colon + 1);
    rest = rest.substr(0, colon);
    if (number.empty() || number.size() > 5 ||
        number.find_first_not_of("0123456789") != std::string::npos)
      return false;
    const int p = std::atoi(number.c_str());
    if (p < 1 || p > 65535) return false;
  }
  in_addr address{};
  return inet_pton(AF_INET, rest.c_str(), &address) == 1;
}

void parseCamera(const ConfigNode& c, Rig& rig) {
  std::string driver = c["driver"].string();
  if (driver == "simulated") {
    rig.camera_driver = CameraDriver::kSimulated;
    c.checkKnownKeys({"driver"});
  } else if (driver == "gphoto2") {
    rig.camera_driver = CameraDriver::kGphoto2;
    c.checkKnownKeys({"driver", "model", "port", "imageformat", "capture_timeout_s"});
    rig.gphoto2.model = c.string("model", "");
    rig.gphoto2.port = c.string("port", "");
    if (rig.gphoto2.port.rfind("ptpip:", 0) == 0 && !validPtpIpPort(rig.gphoto2.port))
      c["port"].fail("must be \"ptpip:IPV4\" or \"ptpip:IPV4:PORT\" (libgphoto2 takes a numeric "
                     "IPv4 address, port 1..65535; default 15740), got \"" + rig.gphoto2.port + "\"");
    rig.gphoto2.imageformat = c.string("imageformat", "RAW");
    rig.gphoto2.capture_timeout_s =
        positive(c, "capture_timeout_s", rig.gphoto2.capture_timeout_s);
  } else {
    c["driver"].fail("must be \"simulated\" or \"gphoto2\", got \"" + driver + "\"");
  }
}

void parseSensor(const ConfigNode& s, Rig& rig) {
  s.checkKnownKeys({"cfa", "bit_depth", "black_level_dn", "white_level_dn", "base_iso",
                    "gain_e_per_dn", "read_noise_e", "full_well_e", "electrons_per_unit_s",
                    "pixel_pitch_um"});
  auto& x = rig.sensor;
  if (s.has("cfa") && !parseCfa(s["cfa"].string(), &x.cfa))
    s["cfa"].fail("must be \"mono\" or \"RGGB\", got \"" + s["cfa"].string() + "\"");
  x.bit_depth = integerIn(s, "bit_depth", x.bit_depth, 8, 16);
  x.black_level_dn = nonNegative(s, "black_level_dn", x.black_level_dn);
  x.white_level_dn = nonNegative(s, "white_level_dn", x.white_level_dn);
  const double max_dn = std::ldexp(1.0, x.bit_depth) - 1;
  if (x.white_level_dn > max_dn)
    s["white_level_dn"].fail("exceeds the " + std::to_string(x.bit_depth) + "-bit range");
  const double white = x.white_level_dn > 0 ? x.white_level_dn : max_dn;
  if (x.black_level_dn >= white)
    s["black_level_dn"].fail("must be below the white level (" + std::to_string(white) + ")");
  x.base_iso = positive(s, "base_iso", x.base_iso);
  x.base_gain_e_per_dn = positive(s, "gain_e_per_dn", x.base_gain_e_per_dn);
  x.read_noise_e = nonNegative(s, "read_noise_e", x.read_noise_e);
  x.full_well_e = nonNegative(s, "full_well_e", x.full_well_e);
  x.electrons_per_unit_s = positive(s, "electrons_per_unit_s", x.electrons_per_unit_s);
  x.pixel_pitch_um = nonNegative(s, "pixel_pitch_um", x.pixel_pitch_um);
}

void parseSimulation(const ConfigNode& s, Rig& rig) {
  s.checkKnownKeys({"lens", "width_px", "height_px", "sensor_width_mm", "sensor_height_mm",
                    "grid_size", "spectral_samples", "light_irradiance", "starburst_radius_px",
                    "max_ghosts", "seed", "optical_axis_offset_px", "angle_zero_offset_deg",
                    "light_drift_pct"});
  auto& x = rig.simulation;
  x.lens = s["lens"].string();
  x.width_px = integerIn(s, "width_px", x.width_px, 8, 20000);
  x.height_px = integerIn(s, "height_px", x.height_px, 8, 20000);
  x.sensor_width_mm = positive(s, "sensor_width_mm", x.sensor_width_mm);
  x.sensor_height_mm = positive(s, "sensor_height_mm", x.sensor_height_mm);
  x.grid_size = integerIn(s, "grid_size", x.grid_size, 4, 1024);
  x.spectral_samples = integerIn(s, "spectral_samples", x.spectral_samples, 0, 200);
  if (x.spectral_samples > 0 && x.spectral_samples < 3)
    s["spectral_samples"].fail("must be 0 (RGB) or at least 3");
  x.light_irradiance = positive(s, "light_irradiance", x.light_irradiance);
  x.starburst_radius_px = nonNegative(s, "starburst_radius_px", x.starburst_radius_px);
  x.max_ghosts = integerIn(s, "max_ghosts", x.max_ghosts, 0, 100000);
  x.seed = static_cast<uint64_t>(integerIn(s, "seed", 1, 0, INT32_MAX));
  if (s.has("optical_axis_offset_px")) {
    const ConfigNode n = s["optical_axis_offset_px"];
    const std::vector<double> v = n.numbers();  // each finite, or an error naming the element
    if (v.size() != 2)
      n.fail("must be [dx, dy] in pixels, got " + std::to_string(v.size()) + " numbers");
    const double max_x = x.width_px / 4.0, max_y = x.height_px / 4.0;
    if (std::abs(v[0]) > max_x || std::abs(v[1]) > max_y)
      n.fail("must lie within a quarter of the image (|dx| ≤ " + text(max_x) + ", |dy| ≤ " +
             text(max_y) + " px), got [" + text(v[0]) + ", " + text(v[1]) + "]");
    x.optical_axis_offset_px = {v[0], v[1]};
  }
  if (s.has("angle_zero_offset_deg")) {
    const double o = s["angle_zero_offset_deg"].number();
    if (std::abs(o) > 5.0)
      s["angle_zero_offset_deg"].fail("must be within ±5 degrees, got " + text(o));
    x.angle_zero_offset_deg = o;
  }
  if (s.has("light_drift_pct")) {
    const double d = s["light_drift_pct"].number();
    if (std::abs(d) > 50.0)
      s["light_drift_pct"].fail("must be within ±50 percent, got " + text(d));
    x.light_drift_pct = d;
  }
}

void parseLens(const ConfigNode& l, Rig& rig) {
  l.checkKnownKeys({"name", "focal_length_mm"});
  rig.lens.name = l.string("name", "");
  rig.lens.focal_length_mm = nonNegative(l, "focal_length_mm", 0);
}

void parseFaults(const ConfigNode& f, Rig& rig) {
  f.checkKnownKeys({"camera_transient_probability", "camera_timeout_probability", "timeout_s",
                    "head_transient_probability", "camera_disconnect_after_frames",
                    "head_disconnect_after_moves", "seed"});
  auto& x = rig.faults;
  x.camera_transient_probability = probability(f, "camera_transient_probability");
  x.camera_timeout_probability = probability(f, "camera_timeout_probability");
  x.timeout_s = nonNegative(f, "timeout_s", x.timeout_s);
  x.head_transient_probability = probability(f, "head_transient_probability");
  x.camera_disconnect_after_frames = integerIn(f, "camera_disconnect_after_frames", -1, -1, INT32_MAX);
  x.head_disconnect_after_moves = integerIn(f, "head_disconnect_after_moves", -1, -1, INT32_MAX);
  x.seed = static_cast<uint64_t>(integerIn(f, "seed", 7, 0, INT32_MAX));
}

void parseCapture(const ConfigNode& c, Rig& rig) {
  c.checkKnownKeys({"from_deg", "to_deg", "step_deg", "exposures_s", "dark_frames", "iso",
                    "f_number", "max_retries", "retry_delay_s", "light_exposure_s",
                    "light_nd_factor", "light_check_repeats"});
  auto& x = rig.capture;
  x.from_deg = c.number("from_deg", x.from_deg);
  x.to_deg = c.number("to_deg", x.to_deg);
  x.step_deg = positive(c, "step_deg", x.step_deg);
  if (c.has("exposures_s")) {
    x.exposures_s = c["exposures_s"].numbers();
    if (x.exposures_s.empty()) c["exposures_s"].fail("must list at least one exposure time");
    for (double t : x.exposures_s)
      if (!(t > 0)) c["exposures_s"].fail("exposure times must be positive");
  }
  x.dark_frames = integerIn(c, "dark_frames", 0, 0, 1000);
  x.iso = positive(c, "iso", x.iso);
  x.f_number = positive(c, "f_number", x.f_number);
  x.max_retries = integerIn(c, "max_retries", x.max_retries, 0, 100);
  x.retry_delay_s = nonNegative(c, "retry_delay_s", x.retry_delay_s);
  if (c.has("light_exposure_s")) {
    const ConfigNode t = c["light_exposure_s"];
    std::vector<double> times = t.isArray() ? t.numbers() : std::vector<double>{t.number()};
    if (!t.isArray() && times[0] == 0) times.clear();  // 0 = none
    if (times.size() > 8) t.fail("takes at most 8 exposure times");
    for (size_t i = 0; i < times.size(); ++i) {
      if (!(times[i] > 0 && times[i] <= 60))
        t.fail("exposure times must be in (0, 60] seconds (a single 0 = none), got " + text(times[i]));
      for (size_t j = 0; j < i; ++j)
        if (times[j] == times[i]) t.fail("exposure times must differ");
    }
    x.light_exposures_s = times;
  }
  x.light_check_repeats = integerIn(c, "light_check_repeats", x.light_check_repeats, 1, 256);
  if (c.has("light_nd_factor")) {
    const double k = c["light_nd_factor"].number();
    if (!(k >= 1 && k <= 1e12))
      c["light_nd_factor"].fail("must be a filter's attenuation in [1, 1e12] (10^density), got " +
                                text(k));
    if (x.light_exposures_s.empty() && k != 1)
      c["light_nd_factor"].fail("declares the filter of the light exposure: set light_exposure_s too");
    x.light_nd_factor = k;
  }
}

}  // namespace

Rig loadRig(const std::filesystem::path& path) {
  ConfigNode root = loadTomlFile(path);
  Rig rig;
  rig.file = path;
  root.checkKnownKeys({"name", "description", "light", "light_illuminance_lux", "head", "camera", "sensor", "lens",
                       "simulation", "faults", "capture"});
  rig.name = root["name"].string();
  if (rig.name.empty()) root["name"].fail("must not be empty");
  rig.description = root.string("description", "");
  rig.light = root.string("light", "");
  rig.light_illuminance_lux = nonNegative(root, "light_illuminance_lux", 0);
  parseHead(root["head"], rig);
  parseCamera(root["camera"], rig);
  if (root.has("sensor")) parseSensor(root["sensor"], rig);
  if (rig.camera_driver == CameraDriver::kSimulated) {
    parseSimulation(root["simulation"], rig);
    if (root.has("lens")) root["lens"].fail("a simulated camera's lens is [simulation] lens");
  } else {
    if (root.has("simulation")) root["simulation"].fail("only a simulated camera takes a [simulation] section");
    if (root.has("lens")) parseLens(root["lens"], rig);
  }
  if (root.has("faults")) {
    if (!rig.simulated()) root["faults"].fail("fault injection needs a simulated head and camera");
    parseFaults(root["faults"], rig);
  }
  if (root.has("capture")) parseCapture(root["capture"], rig);
  if (rig.head_driver == HeadDriver::kSimulated && rig.camera_driver != CameraDriver::kSimulated)
    root["head"]["driver"].fail("a simulated head needs a simulated camera");
  return rig;
}

std::filesystem::path findRig(const std::string& name_or_path) {
  namespace fs = std::filesystem;
  const fs::path p(name_or_path);
  std::error_code ec;
  if (fs::exists(fs::symlink_status(p, ec))) return p;  // even a broken link: loading names it
  const std::string file = p.has_extension() ? name_or_path : name_or_path + ".toml";
  if (p.parent_path().empty()) {
    std::vector<fs::path> preferred;
    if (const char* env = std::getenv("FLAREKIT_RIGS")) preferred.push_back(fs::path(env) / file);
    if (auto found = findShippedFile(fs::path("rigs") / file, preferred)) return *found;
  }
  throw InputError(name_or_path + ": no such rig file (give a path, or a name from rigs/ such as "
                                  "sim-heliar)");
}

std::filesystem::path resolveLensPath(const Rig& rig) {
  const std::filesystem::path& lens = rig.simulation.lens;
  const std::filesystem::path dir = rig.file.parent_path();
  if (auto found = findShippedFile(lens, {dir / lens, dir.parent_path() / lens})) return *found;
  throw InputError(rig.file.string(), "simulation.lens: no such lens file \"" + lens.string() +
                                          "\" (looked beside the rig file, in its parent folder "
                                          "and in the working folder)");
}

}  // namespace flarekit::acquisition
