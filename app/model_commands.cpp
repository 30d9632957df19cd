// flarekit render, flarekit model-info, flarekit bench model: parse options, call model/.
#include <cmath>
#include <iostream>
#include <optional>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "model/flare_model.h"
#include "model/render_benchmark.h"

namespace flarekit::app {
namespace {

void checkFinite(double value, const char* option) {
  if (!std::isfinite(value)) throw InputError(std::string(option) + " must be a finite number of degrees");
}

std::optional<cv::Size> outputSize(int width, int height, bool has_width, bool has_height) {
  if (has_width != has_height) throw InputError("--width and --height go together");
  if (!has_width) return std::nullopt;
  if (width < 1 || height < 1 || width > 65536 || height > 65536)
    throw InputError("--width and --height must be between 1 and 65536 pixels");
  return cv::Size(width, height);
}

void registerRender(CLI::App& app) {
  struct Options {
    std::string model, out, preview;
    double angle_deg = 0, roll_deg = 0;
    int width = 0, height = 0;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "render", "Render a flare model (model.json) at a light angle and roll into a linear EXR image");
  cmd->add_option("MODEL", o->model, "Flare model file (format flarekit.flare-model)")->required();
  cmd->add_option("--angle", o->angle_deg, "Light angle θ from the optical axis (the rig angle less the model's optical zero), degrees")->required();
  cmd->add_option("--roll", o->roll_deg, "Roll φ about the optical axis, degrees (default 0)");
  cmd->add_option("--width", o->width, "Output width, pixels (default: the capture's; with --height)");
  cmd->add_option("--height", o->height, "Output height, pixels (default: the capture's; with --width)");
  cmd->add_option("--out", o->out, "Output OpenEXR file (float, R,G,B or Y)")->required();
  cmd->add_option("--preview", o->preview, "Also write a tone-mapped PNG preview for people");
  cmd->callback([o, cmd] {
    checkFinite(o->angle_deg, "--angle");
    checkFinite(o->roll_deg, "--roll");
    const auto size = outputSize(o->width, o->height, cmd->count("--width") > 0, cmd->count("--height") > 0);
    const model::FlareModel m = model::FlareModel::load(o->model);
    const cv::Mat image = m.render(o->angle_deg, o->roll_deg, size);
    ExrAttributes attributes;
    attributes["flarekit.angle_deg"] = o->angle_deg;
    attributes["flarekit.roll_deg"] = o->roll_deg;
    attributes["flarekit.exposure_s"] = m.capture.exposure_s;
    attributes["flarekit.iso"] = m.capture.iso;
    attributes["flarekit.f_number"] = m.capture.f_number;
    attributes["flarekit.lens"] = m.capture.lens;
    attributes["flarekit.camera"] = m.capture.camera;
    attributes["flarekit.ghosts"] = static_cast<int>(m.ghostsAt(o->angle_deg).size());
    writeExr(o->out, image, attributes);
    if (!o->preview.empty()) writePreviewPng(o->preview, image);
  });
}

nlohmann::json ghostJson(const model::FlareModel& m, const model::GhostTrack& g,
                         const std::optional<model::GhostParameters>& at) {
  nlohmann::json j = {{"id", g.id}, {"angle_min_deg", g.angle_min_deg}, {"angle_max_deg", g.angle_max_deg}};
  int degree = 0;
  for (const auto& p : g.parameters) degree = std::max(degree, static_cast<int>(p.coefficients.size()) - 1);
  j["degree"] = degree;
  j["present"] = at.has_value();
  if (at) {
    const std::vector<double> v = model::toParameterVector(*at);
    nlohmann::json params = nlohmann::json::object();
    for (size_t k = 0; k < v.size(); ++k) params[model::parameterName(static_cast<int>(k), m.channels)] = v[k];
    j["parameters"] = params;
  }
  return j;
}

void registerModelInfo(CLI::App& app) {
  struct Options {
    std::string model;
    double angle_deg = 0;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("model-info",
                                 "Show a flare model: capture, ghosts, their angle ranges, and their "
                                 "parameters at an angle");
  cmd->add_option("MODEL", o->model, "Flare model file")->required();
  cmd->add_option("--angle", o->angle_deg, "Show the parameters at this light angle θ from the optical axis, degrees (default 0)");
  cmd->add_flag("--json", o->json, "Print one JSON object");
  cmd->callback([o] {
    checkFinite(o->angle_deg, "--angle");
    const model::FlareModel m = model::FlareModel::load(o->model);
    nlohmann::json ghosts = nlohmann::json::array();
    for (const auto& g : m.ghosts) {
      std::optional<model::GhostParameters> at;
      for (const auto& a : m.ghostsAt(o->angle_deg))
        if (a.id == g.id) at = a.parameters;
      ghosts.push_back(ghostJson(m, g, at));
    }
    const nlohmann::json capture = m.toJson()["capture"];
    // The pedestal's terms at θ (model/pedestal.h), or null where the model draws none.
    nlohmann::json pedestal = nullptr;
    if (const model::Pedestal p = m.pedestalAt(o->angle_deg); !p.empty()) {
      pedestal = nlohmann::json::object();
      for (size_t k = 0; k < p.coefficients.size(); ++k)
        pedestal[model::pedestalTermName(static_cast<int>(k), m.channels)] = p.coefficients[k];
    }
    if (o->json) {
      nlohmann::json j = {{"file", o->model},   {"channels", m.channels},
                          {"capture", capture}, {"angle_deg", o->angle_deg},
                          {"ghosts", ghosts},   {"pedestal", pedestal}};
      std::cout << jsonText(j) << "\n";
      return;
    }
    const auto& c = m.capture;
    std::cout << o->model << ": flare model, " << m.ghosts.size() << " ghosts, "
              << (m.channels == 3 ? "RGB" : "grey") << "\n"
              << "  capture: " << c.camera << ", " << c.lens
              << (c.focal_length_mm > 0 ? " (" + cv::format("%.4g", c.focal_length_mm) + " mm)" : std::string())
              << ", f/" << c.f_number << ", ISO " << c.iso
              << ", " << c.exposure_s << " s, light " << c.light << ", " << c.image_size.width << "x"
              << c.image_size.height << " px, pitch " << c.pixel_pitch_um << " um, step "
              << c.angle_step_deg << " deg\n";
    const std::vector<std::string> names = model::parameterNames(m.channels);
    std::cout << "  at " << o->angle_deg << " deg:\n";
    for (const auto& g : ghosts) {
      std::cout << "  ghost " << g["id"] << ": " << g["angle_min_deg"] << " .. " << g["angle_max_deg"]
                << " deg, degree " << g["degree"];
      if (!g["present"].get<bool>()) {
        std::cout << ", absent\n";
        continue;
      }
      std::cout << "\n   ";
      for (const auto& name : names) std::cout << " " << name << "=" << g["parameters"][name].get<double>();
      std::cout << "\n";
    }
    if (!pedestal.is_null()) {
      std::cout << "  pedestal: " << m.pedestal->angle_min_deg << " .. "
                << m.pedestal->angle_max_deg << " deg\n   ";
      for (const auto& [name, value] : pedestal.items())
        std::cout << " " << name << "=" << value.get<double>();
      std::cout << "\n";
    }
  });
}

void registerBench(CLI::App& app) {
  auto o = std::make_shared<model::RenderBenchmarkOptions>();
  auto json = std::make_shared<bool>(false);
  auto* cmd = benchCommand(app).add_subcommand(
      "model", "Time the ghost-model renderer: a frame of random ghosts, with and without derivative images");
  cmd->add_option("--ghosts", o->ghosts, "Number of ghosts (default 100)");
  cmd->add_option("--width", o->width, "Frame width, pixels (default 1280)");
  cmd->add_option("--height", o->height, "Frame height, pixels (default 720)");
  cmd->add_option("--channels", o->channels, "1 (grey) or 3 (RGB) (default 1)");
  cmd->add_option("--min-radius", o->min_radius, "Smallest ghost radius, pixels (default 20)");
  cmd->add_option("--max-radius", o->max_radius, "Largest ghost radius, pixels (default 80)");
  cmd->add_option("--repeats", o->repeats, "Timed runs per figure; the median is reported (default 7)");
  cmd->add_option("--threads", o->threads, "TBB threads (default: all cores)");
  cmd->add_option("--seed", o->seed, "Random ghost set (default 1)");
  cmd->add_flag("--json", *json, "Print one JSON object (the default output is one line)");
  cmd->callback([o, json] {
    std::string error;
    if (!o->IsValid(&error)) throw InputError("bench model: " + error);
    const model::RenderBenchmarkResult r = model::runRenderBenchmark(*o);
    if (*json)
      std::cout << jsonText(model::toJson(r)) << "\n";
    else
      std::cout << r.BriefReport() << "\n";
  });
}

}  // namespace

void registerModelCommands(CLI::App& app) {
  registerRender(app);
  registerModelInfo(app);
  registerBench(app);
}

}  // namespace flarekit::app
