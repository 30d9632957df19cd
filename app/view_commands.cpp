// flarekit view, flarekit export-shader: parse options, call view/.
#include <cmath>
#include <iostream>

#include "app/commands.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "model/flare_model.h"
#include "view/flare_shader.h"
#include "view/viewer_page.h"

namespace flarekit::app {
namespace {

void registerView(CLI::App& app) {
  struct Options {
    std::string model, out;
    double theta_deg = std::numeric_limits<double>::quiet_NaN();
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "view", "Write a self-contained HTML page that draws a flare model in real time (WebGL2): "
              "the pointer moves the light");
  cmd->add_option("MODEL", o->model, "Flare model file (format flarekit.flare-model)")->required();
  cmd->add_option("--out", o->out, "Output HTML file")->required();
  cmd->add_option("--angle", o->theta_deg,
                  "Light angle θ of the first view, degrees (default: the middle of the model's range)");
  cmd->callback([o] {
    if (!std::isnan(o->theta_deg) && !std::isfinite(o->theta_deg))
      throw InputError("--angle must be a finite number of degrees");
    const model::FlareModel m = model::FlareModel::load(o->model);
    view::ViewerOptions options;
    options.theta_deg = o->theta_deg;
    options.source_name = std::filesystem::path(o->model).filename().string();
    writeTextFileAtomically(o->out, view::viewerPage(m, options));
    std::cout << o->out << "\n";
  });
}

void registerExportShader(CLI::App& app) {
  struct Options {
    std::string model, out;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "export-shader", "Write a flare model as a GLSL function flare(uv, theta, phi) with its "
                       "coefficients baked in, for an engine or compositor");
  cmd->add_option("MODEL", o->model, "Flare model file (format flarekit.flare-model)")->required();
  cmd->add_option("--out", o->out, "Output GLSL file")->required();
  cmd->callback([o] {
    const model::FlareModel m = model::FlareModel::load(o->model);
    view::FlareShaderOptions options;
    options.source_name = std::filesystem::path(o->model).filename().string();
    writeTextFileAtomically(o->out, view::flareShader(m, options));
    std::cout << o->out << "\n";
  });
}

}  // namespace

void registerViewCommands(CLI::App& app) {
  registerView(app);
  registerExportShader(app);
}

}  // namespace flarekit::app
