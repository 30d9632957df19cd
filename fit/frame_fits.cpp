#include "fit/frame_fits.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>

#include "common/config.h"

namespace flarekit::fit {

FrameFits FrameFits::fromResult(const FitResult& result, cv::Size image_size, int channels) {
  FrameFits f;
  f.image_size = image_size;
  f.channels = channels;
  for (const FrameFit& ff : result.frame_fits) {  // in angle order (FitResult), as at() needs them
    FittedFrame frame;
    frame.angle_deg = ff.angle_deg;
    for (size_t k = 0; k < ff.ghosts.size(); ++k) frame.ghosts.push_back({ff.ghost_ids[k], ff.ghosts[k]});
    frame.pedestal = ff.pedestal;
    f.frames.push_back(std::move(frame));
  }
  return f;
}

FrameFits FrameFits::parse(const std::string& text, const std::string& file) {
  return fromJson(parseJson(text, file));
}

FrameFits FrameFits::fromJson(const ConfigNode& root) {
  checkFormat(root, kFrameFitsFormat, kFrameFitsVersion);
  root.checkKnownKeys({"format", "version", "image_width", "image_height", "channels", "frames"});
  FrameFits f;
  auto positive = [](const ConfigNode& n) {
    const long long v = n.integer();
    if (v <= 0 || v > 1000000) n.fail("must be a positive integer, got " + std::to_string(v));
    return static_cast<int>(v);
  };
  f.image_size = {positive(root["image_width"]), positive(root["image_height"])};
  const ConfigNode ch = root["channels"];
  const long long channels = ch.integer();
  if (channels != 1 && channels != 3) ch.fail("must be 1 (grey) or 3 (RGB), got " + std::to_string(channels));
  f.channels = static_cast<int>(channels);
  const ConfigNode frames = root["frames"];
  if (!frames.isArray()) frames.fail("must be an array");
  const std::vector<std::string> names = model::parameterNames(f.channels);
  for (size_t i = 0; i < frames.size(); ++i) {
    const ConfigNode fr = frames[i];
    fr.checkKnownKeys({"angle_deg", "ghosts", "pedestal"});
    FittedFrame frame;
    frame.angle_deg = fr["angle_deg"].number();
    if (!f.frames.empty() && !(frame.angle_deg > f.frames.back().angle_deg))
      fr["angle_deg"].fail("frames must be in ascending angle order, each angle once");
    const ConfigNode ghosts = fr["ghosts"];
    if (!ghosts.isArray()) ghosts.fail("must be an array");
    for (size_t k = 0; k < ghosts.size(); ++k) {
      const ConfigNode g = ghosts[k];
      g.checkKnownKeys({"id", "parameters"});
      const long long id = g["id"].integer();
      if (id < 0 || id > 1000000000) g["id"].fail("must be a non-negative integer, got " + std::to_string(id));
      const ConfigNode params = g["parameters"];
      params.checkKnownKeys(names);
      std::vector<double> values;
      for (const std::string& name : names) values.push_back(params[name].number());
      model::GhostAtAngle ghost{static_cast<int>(id), model::fromParameterVector(values, f.channels)};
      std::string problem;
      if (!model::isValid(ghost.parameters, &problem)) params.fail(problem);
      frame.ghosts.push_back(ghost);
    }
    frame.pedestal.channels = f.channels;
    if (fr.has("pedestal")) {
      const ConfigNode p = fr["pedestal"];
      if (!p.isObject()) p.fail("must be a table of pedestal terms");
      p.checkKnownKeys(model::pedestalTermNames(f.channels));
      for (const std::string& name : model::pedestalTermNames(f.channels))
        frame.pedestal.coefficients.push_back(p[name].number());
    }
    f.frames.push_back(std::move(frame));
  }
  return f;
}

FrameFits FrameFits::load(const std::filesystem::path& path) {
  return fromJson(loadJsonFile(path));
}

nlohmann::json FrameFits::toJson() const {
  nlohmann::json j;
  j["format"] = kFrameFitsFormat;
  j["version"] = kFrameFitsVersion;
  j["image_width"] = image_size.width;
  j["image_height"] = image_size.height;
  j["channels"] = channels;
  const std::vector<std::string> names = model::parameterNames(channels);
  nlohmann::json list = nlohmann::json::array();
  for (const FittedFrame& frame : frames) {
    nlohmann::json ghosts = nlohmann::json::array();
    for (const model::GhostAtAngle& g : frame.ghosts) {
      nlohmann::json params = nlohmann::json::object();
      const std::vector<double> values = model::toParameterVector(g.parameters);
      for (size_t k = 0; k < values.size(); ++k) params[names[k]] = values[k];
      ghosts.push_back({{"id", g.id}, {"parameters", params}});
    }
    nlohmann::json entry = {{"angle_deg", frame.angle_deg}, {"ghosts", ghosts}};
    if (!frame.pedestal.empty()) {
      nlohmann::json terms = nlohmann::json::object();
      for (size_t k = 0; k < frame.pedestal.coefficients.size(); ++k)
        terms[model::pedestalTermName(static_cast<int>(k), channels)] =
            frame.pedestal.coefficients[k];
      entry["pedestal"] = terms;
    }
    list.push_back(entry);
  }
  j["frames"] = list;
  return j;
}

void FrameFits::save(const std::filesystem::path& path) const { writeJsonFile(path, toJson()); }

const FrameFits::FittedFrame* FrameFits::at(double angle_deg) const {
  const auto it = std::lower_bound(frames.begin(), frames.end(), angle_deg - 1e-9,
                                   [](const FittedFrame& f, double a) { return f.angle_deg < a; });
  if (it == frames.end() || std::abs(it->angle_deg - angle_deg) > 1e-9) return nullptr;
  return &*it;
}

}  // namespace flarekit::fit
