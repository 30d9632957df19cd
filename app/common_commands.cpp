// flarekit exr-info
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "common/config.h"
#include "common/exr.h"

namespace flarekit::app {

CLI::App& benchCommand(CLI::App& app) {
  // Created by the first layer that registers a benchmark, so it exists only when one does.
  for (auto* sub : app.get_subcommands([](CLI::App* s) { return s->get_name() == "bench"; }))
    return *sub;
  auto* bench = app.add_subcommand("bench", "Measure speed; each benchmark prints one JSON object");
  bench->require_subcommand(1);
  return *bench;
}

void registerCommonCommands(CLI::App& app) {
  struct Options {
    std::vector<std::string> files;
    bool json = false;
    std::string layer;
    bool require_finite = false;
  };
  auto options = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "exr-info", "Show an OpenEXR file's size, layers, channels with statistics, and attributes");
  cmd->add_option("FILE", options->files, "EXR files")->required();
  cmd->add_flag("--json", options->json, "Print one JSON array of file descriptions");
  cmd->add_option("--layer", options->layer,
                  "Describe only this layer (e.g. ghost.3; \"\" for the main layer); "
                  "an error when the file has none");
  cmd->add_flag("--require-finite", options->require_finite,
                "Fail on NaN or infinite values in the described channels");
  cmd->callback([options, cmd] {
    ExrDescribeOptions describe;
    if (cmd->count("--layer")) describe.layer = options->layer;
    describe.require_finite = options->require_finite;
    nlohmann::json all = nlohmann::json::array();
    for (const auto& f : options->files) {
      ExrFileInfo info = describeExr(f, describe);
      if (options->json)
        all.push_back(toJson(info));
      else
        std::cout << toText(info);
    }
    if (options->json) std::cout << jsonText(all) << "\n";
  });
}

}  // namespace flarekit::app
