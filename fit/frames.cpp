#include "fit/frames.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include <tbb/parallel_for.h>

#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/log.h"

namespace flarekit::fit {
namespace fs = std::filesystem;

namespace {

std::string fmt(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Sorts by angle and rejects repeated angles, naming both files.
void sortAndCheckAngles(std::vector<Frame>& frames) {
  std::stable_sort(frames.begin(), frames.end(),
                   [](const Frame& a, const Frame& b) { return a.angle_deg < b.angle_deg; });
  for (size_t i = 1; i < frames.size(); ++i) {
    if (std::abs(frames[i].angle_deg - frames[i - 1].angle_deg) <= kAngleToleranceDeg)
      throw InputError(frames[i].file.string(),
                       "angle " + fmt(frames[i].angle_deg) + "° repeats that of " +
                           frames[i - 1].file.string());
  }
}

// Reads pixels into each frame, checks sizes and channel counts, drops all-black frames.
void readPixels(FrameStack& stack, const FrameLoadOptions& options) {
  // Decoding the frames (zlib) is most of loading: in parallel, each into its own frame; a frame
  // that cannot be read keeps its error, and the checks below go in frame order, so the error
  // reported is the one a serial loop would have met first.
  std::vector<std::exception_ptr> failed(stack.frames.size());
  tbb::parallel_for(size_t{0}, stack.frames.size(), [&](size_t i) {
    Frame& f = stack.frames[i];
    try {
      readFrameImage(f.file, options.layer, f.image, f.valid);
    } catch (...) {
      failed[i] = std::current_exception();
    }
  });
  std::vector<Frame> kept;
  for (size_t i = 0; i < stack.frames.size(); ++i) {
    if (failed[i]) std::rethrow_exception(failed[i]);
    Frame& f = stack.frames[i];
    if (stack.size.area() == 0) {
      stack.size = f.image.size();
      stack.channels = f.image.channels();
    }
    if (f.image.size() != stack.size)
      throw InputError(f.file.string(), "image is " + std::to_string(f.image.cols) + "x" +
                                            std::to_string(f.image.rows) + ", other frames are " +
                                            std::to_string(stack.size.width) + "x" +
                                            std::to_string(stack.size.height));
    if (f.image.channels() != stack.channels)
      throw InputError(f.file.string(), "has " + std::to_string(f.image.channels()) +
                                            " channels, other frames have " +
                                            std::to_string(stack.channels));
    double max_value = 0;
    cv::minMaxLoc(f.image.reshape(1), nullptr, &max_value);
    if (!(max_value > options.black_threshold)) {
      std::string w = f.file.string() + ": all-black frame (θ = " + fmt(f.angle_deg) +
                      "°), left out of the fit";
      logWarning(w);
      stack.warnings.push_back(w);
      continue;
    }
    kept.push_back(std::move(f));
  }
  stack.frames = std::move(kept);
  if (stack.frames.empty())
    throw InputError(stack.source.string(), "every frame is black: nothing to fit");
}

void fillInfoDefaults(model::CaptureInfo& info, cv::Size size, const std::vector<Frame>& frames) {
  if (info.camera.empty()) info.camera = "unknown";
  if (info.lens.empty()) info.lens = "unknown";
  if (info.light.empty()) info.light = "unknown";
  if (info.f_number <= 0) info.f_number = 1;
  if (info.iso <= 0) info.iso = 100;
  if (info.exposure_s <= 0) info.exposure_s = 1;
  if (info.pixel_pitch_um <= 0) info.pixel_pitch_um = 1;
  info.image_size = size;
  if (info.angle_step_deg <= 0) {
    double step = 0;
    for (size_t i = 1; i < frames.size(); ++i) {
      double d = frames[i].angle_deg - frames[i - 1].angle_deg;
      if (step == 0 || d < step) step = d;
    }
    info.angle_step_deg = step > 0 ? step : 1;
  }
}

}  // namespace

bool FrameLoadOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!angle_pattern.empty()) {
    try {
      std::regex re(angle_pattern);
      if (re.mark_count() < 1) return fail("--angle-pattern needs one capture group for the angle");
    } catch (const std::regex_error& e) {
      return fail("--angle-pattern is not a valid regular expression: " + std::string(e.what()));
    }
  }
  if (!angles_csv.empty() && !angle_pattern.empty())
    return fail("give the angles either by --angles-csv or by --angle-pattern, not both");
  if (!(black_threshold >= 0)) return fail("black_threshold must be ≥ 0");
  if (!(info.focal_length_mm >= 0) || !std::isfinite(info.focal_length_mm))
    return fail("--focal-length-mm must be > 0");
  return true;
}

int FrameStack::findAngle(double angle_deg) const {
  for (size_t i = 0; i < frames.size(); ++i)
    if (std::abs(frames[i].angle_deg - angle_deg) <= kAngleToleranceDeg) return static_cast<int>(i);
  return -1;
}

double FrameStack::medianStepDeg() const {
  std::vector<double> steps;
  for (size_t i = 1; i < frames.size(); ++i) steps.push_back(frames[i].angle_deg - frames[i - 1].angle_deg);
  if (steps.empty()) return 1;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  return steps[steps.size() / 2];
}

void readFrameImage(const fs::path& file, const std::string& layer, cv::Mat& image,
                    cv::Mat& valid) {
  if (!fs::exists(file)) throw InputError(file.string(), "frame file is missing");
  ExrImage exr = readExr(file);
  const ExrLayer* main = exr.find(layer);
  if (main == nullptr) {
    std::string names;
    for (const auto& l : exr.layers) names += (names.empty() ? "" : ", ") + (l.name.empty() ? std::string("(main)") : l.name);
    throw InputError(file.string(), (layer.empty() ? std::string("no main layer (Y or R,G,B)")
                                                    : "no layer \"" + layer + "\"") +
                                        "; layers: " + (names.empty() ? "none" : names));
  }
  image = main->image.clone();
  if (image.type() != CV_32FC1 && image.type() != CV_32FC3)
    throw InputError(file.string(), "layer must have 1 or 3 float channels");
  // Valid: every channel finite; non-finite values become 0 so filters stay finite.
  valid = cv::Mat(image.size(), CV_8U, cv::Scalar(255));
  const int c = image.channels();
  for (int y = 0; y < image.rows; ++y) {
    float* p = image.ptr<float>(y);
    uchar* v = valid.ptr<uchar>(y);
    for (int x = 0; x < image.cols; ++x)
      for (int k = 0; k < c; ++k)
        if (!std::isfinite(p[x * c + k])) {
          p[x * c + k] = 0;
          v[x] = 0;
        }
  }
  if (const ExrLayer* sat = exr.find("saturated"); sat != nullptr && layer != "saturated") {
    cv::Mat s = sat->image;
    if (s.channels() != 1) cv::extractChannel(s, s, 0);
    valid.setTo(0, s > 0.5);
  }
}

std::vector<GhostTruth> readGhostTruth(const fs::path& ghosts_file) {
  ExrImage exr = readExr(ghosts_file);
  std::vector<GhostTruth> out;
  for (const auto& l : exr.layers) {
    if (l.name.rfind("ghost.", 0) != 0) continue;
    GhostTruth g;
    try {
      g.id = std::stoi(l.name.substr(6));
    } catch (const std::exception&) {
      throw InputError(ghosts_file.string(), "layer \"" + l.name + "\" has no ghost id");
    }
    g.image = l.image;  // the layer's own pixels: `exr` goes out of scope
    cv::patchNaNs(g.image, 0);
    out.push_back(std::move(g));
  }
  return out;
}

FrameStack loadCapture(const fs::path& folder, const FrameLoadOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError(error);
  const fs::path manifest_path = folder / "manifest.json";
  if (!fs::exists(manifest_path))
    throw InputError(folder.string(), "not a capture folder (no manifest.json)");
  ConfigNode root = loadJsonFile(manifest_path);
  checkFormat(root, "flarekit.capture", 1);
  FrameStack stack;
  stack.source = folder;
  const std::string status = root.string("status", "complete");
  if (status != "complete") {
    std::string w = manifest_path.string() + ": capture status is \"" + status +
                    "\"; fitting the frames it lists";
    logWarning(w);
    stack.warnings.push_back(w);
  }
  model::CaptureInfo& info = stack.info;
  if (auto lens = root.find("lens")) {
    info.lens = lens->string("name", "");
    info.focal_length_mm = lens->number("focal_length_mm", 0);
    if (!(info.focal_length_mm >= 0) || !std::isfinite(info.focal_length_mm))
      (*lens)["focal_length_mm"].fail("must be > 0 (or left out when unknown)");
  }
  if (auto cam = root.find("camera")) {
    info.camera = cam->string("description", "");
    info.iso = cam->number("iso", 0);
    info.f_number = cam->number("f_number", 0);
    if (auto ex = cam->find("exposures_s"); ex && ex->isArray() && ex->size() > 0) {
      auto v = ex->numbers();
      info.exposure_s = *std::max_element(v.begin(), v.end());
    }
  }
  if (auto light = root.find("light"); light && !light->isNull())
    info.light = light->isObject() ? jsonText(light->json(), -1) : light->string();
  ConfigNode image = root["image"];
  const int width = static_cast<int>(image["width"].integer());
  const int height = static_cast<int>(image["height"].integer());
  const std::string channels = image.string("channels", "Y");
  if (channels != "Y" && channels != "RGB") image["channels"].fail("must be \"Y\" or \"RGB\"");
  info.pixel_pitch_um = image.number("pixel_pitch_um", 0);
  info.clip_level = image.number("clip_level", 0);
  info.light_illuminance_lux = root.number("light_illuminance_lux", 0);
  if (!(info.clip_level >= 0) || !std::isfinite(info.clip_level)) image["clip_level"].fail("must be ≥ 0");
  if (!(info.light_illuminance_lux >= 0) || !std::isfinite(info.light_illuminance_lux))
    root["light_illuminance_lux"].fail("must be ≥ 0");
  if (auto plan = root.find("plan")) info.angle_step_deg = plan->number("step_deg", 0);
  ConfigNode frames = root["frames"];
  if (frames.size() == 0) frames.fail("lists no frames");
  bool truth = root.boolean("truth", false);
  std::map<long long, bool> seen_index;
  for (size_t i = 0; i < frames.size(); ++i) {
    ConfigNode e = frames[i];
    Frame f;
    f.index = static_cast<int>(e["index"].integer());
    if (seen_index.count(f.index)) e["index"].fail("frame index repeats");
    seen_index[f.index] = true;
    f.angle_deg = e["angle_deg"].number();
    f.file = folder / e["file"].string();
    if (!fs::exists(f.file)) e["file"].fail("frame file " + f.file.string() + " is missing");
    // The manifest and the file must agree on the angle: a mismatch means a mixed-up capture.
    ExrAttributes attrs = readExrAttributes(f.file);
    if (auto a = numericAttribute(attrs, "flarekit.angle_deg");
        a && std::abs(*a - f.angle_deg) > 1e-4)
      e["angle_deg"].fail("manifest says " + fmt(f.angle_deg) + "° but " + f.file.string() +
                          " says " + fmt(*a) + "°");
    if (auto t = e.find("truth_file")) f.truth_file = folder / t->string();
    if (auto g = e.find("ghosts_file")) f.ghosts_file = folder / g->string();
    // Newer captures keep the per-ghost layers ("ghost.<id>.*") in the truth file itself.
    if (f.ghosts_file.empty()) f.ghosts_file = f.truth_file;
    if (truth && (f.truth_file.empty() || !fs::exists(f.truth_file) || !fs::exists(f.ghosts_file))) {
      // Evaluation against the truth needs every frame's: say which is missing rather than
      // quietly measuring against the frames only.
      const std::string missing = f.truth_file.empty() ? "frames[" + std::to_string(i) + "] names no truth_file"
                                  : !fs::exists(f.truth_file) ? f.truth_file.string() + " is missing"
                                                              : f.ghosts_file.string() + " is missing";
      const std::string w = manifest_path.string() + ": the capture has ground truth, but " + missing +
                            "; nothing will be compared with the truth";
      logWarning(w);
      stack.warnings.push_back(w);
      truth = false;
    }
    stack.frames.push_back(std::move(f));
  }
  stack.has_truth = truth;
  sortAndCheckAngles(stack.frames);
  readPixels(stack, options);
  if (stack.size != cv::Size(width, height))
    throw InputError(manifest_path.string(),
                     "image: manifest says " + std::to_string(width) + "x" +
                         std::to_string(height) + " but the frames are " +
                         std::to_string(stack.size.width) + "x" + std::to_string(stack.size.height));
  if ((channels == "RGB") != (stack.channels == 3) && options.layer.empty())
    throw InputError(manifest_path.string(), "image.channels: manifest says " + channels +
                                                 " but the frames have " +
                                                 std::to_string(stack.channels) + " channel(s)");
  fillInfoDefaults(info, stack.size, stack.frames);
  return stack;
}

namespace {

std::map<std::string, double> readAnglesCsv(const fs::path& csv) {
  std::ifstream in(csv);
  if (!in) throw InputError(csv.string(), "cannot read the angles file");
  std::map<std::string, double> angles;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const auto comma = line.find(',');
    const std::string where = csv.string() + ":" + std::to_string(line_no);
    if (comma == std::string::npos) throw InputError(where, "expected \"file,angle_deg\"");
    std::string name = line.substr(0, comma), value = line.substr(comma + 1);
    auto trim = [](std::string& s) {
      s.erase(0, s.find_first_not_of(" \t\""));
      s.erase(s.find_last_not_of(" \t\"") + 1);
    };
    trim(name);
    trim(value);
    char* end = nullptr;
    const double a = std::strtod(value.c_str(), &end);
    if (end == value.c_str() || *end != '\0' || !std::isfinite(a)) {
      if (line_no == 1) continue;  // a header line
      throw InputError(where, "angle \"" + value + "\" is not a number");
    }
    const std::string key = fs::path(name).filename().string();
    if (angles.count(key)) throw InputError(where, "file " + key + " is listed twice");
    angles[key] = a;
  }
  return angles;
}

}  // namespace

FrameStack loadExrStack(const std::vector<fs::path>& inputs, const FrameLoadOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError(error);
  if (inputs.empty()) throw InputError("no input frames given");
  std::vector<fs::path> files;
  for (const auto& in : inputs) {
    if (fs::is_directory(in)) {
      std::vector<fs::path> found;
      for (const auto& e : fs::directory_iterator(in))
        if (e.is_regular_file() && e.path().extension() == ".exr") found.push_back(e.path());
      if (found.empty()) throw InputError(in.string(), "folder holds no .exr files");
      std::sort(found.begin(), found.end());
      files.insert(files.end(), found.begin(), found.end());
    } else {
      if (!fs::exists(in)) throw InputError(in.string(), "file is missing");
      files.push_back(in);
    }
  }
  FrameStack stack;
  stack.source = files.front();
  std::map<std::string, double> csv;
  if (!options.angles_csv.empty()) csv = readAnglesCsv(options.angles_csv);
  std::optional<std::regex> pattern;
  if (!options.angle_pattern.empty()) pattern.emplace(options.angle_pattern);
  for (size_t i = 0; i < files.size(); ++i) {
    Frame f;
    f.index = static_cast<int>(i);
    f.file = files[i];
    const std::string name = files[i].filename().string();
    ExrAttributes attrs = readExrAttributes(files[i]);
    if (!options.angles_csv.empty()) {
      auto it = csv.find(name);
      if (it == csv.end())
        throw InputError(files[i].string(), "no angle for this file in " + options.angles_csv.string());
      f.angle_deg = it->second;
    } else if (pattern) {
      std::smatch m;
      if (!std::regex_search(name, m, *pattern) || m.size() < 2)
        throw InputError(files[i].string(), "file name does not match --angle-pattern \"" +
                                                options.angle_pattern + "\"");
      char* end = nullptr;
      const std::string v = m[1].str();
      f.angle_deg = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end != '\0' || !std::isfinite(f.angle_deg))
        throw InputError(files[i].string(), "angle \"" + v + "\" from the file name is not a number");
    } else {
      auto a = numericAttribute(attrs, "flarekit.angle_deg");
      if (!a)
        throw InputError(files[i].string(),
                         "no flarekit.angle_deg attribute; give angles with --angles-csv or "
                         "--angle-pattern");
      f.angle_deg = *a;
    }
    if (i == 0) {
      model::CaptureInfo& info = stack.info;
      info = options.info;
      auto num = [&](const char* key, double& out) {
        if (out <= 0)
          if (auto v = numericAttribute(attrs, key)) out = *v;
      };
      auto str = [&](const char* key, std::string& out) {
        if (out.empty())
          if (auto v = stringAttribute(attrs, key)) out = *v;
      };
      num("flarekit.f_number", info.f_number);
      num("flarekit.iso", info.iso);
      num("flarekit.exposure_s", info.exposure_s);
      num("flarekit.pixel_pitch_um", info.pixel_pitch_um);
      num("flarekit.focal_length_mm", info.focal_length_mm);
      str("flarekit.camera", info.camera);
      str("flarekit.lens", info.lens);
    }
    stack.frames.push_back(std::move(f));
  }
  sortAndCheckAngles(stack.frames);
  readPixels(stack, options);
  fillInfoDefaults(stack.info, stack.size, stack.frames);
  return stack;
}

FrameStack loadFrames(const std::vector<fs::path>& inputs, const FrameLoadOptions& options) {
  if (inputs.size() == 1 && fs::is_directory(inputs[0]) && fs::exists(inputs[0] / "manifest.json"))
    return loadCapture(inputs[0], options);
  return loadExrStack(inputs, options);
}

}  // namespace flarekit::fit
