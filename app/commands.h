#pragma once
// Each library registers its own subcommands; app/ only parses options and calls the libraries.

#include <CLI/CLI.hpp>

namespace flarekit::app {

// Options every subcommand shares.
struct GlobalOptions {
  bool quiet = false;
  bool verbose = false;
};

void registerCommonCommands(CLI::App& app);
void registerRenderCommands(CLI::App& app);       // app/render_commands.cpp
void registerAcquisitionCommands(CLI::App& app);  // app/acquisition_commands.cpp
void registerModelCommands(CLI::App& app);        // app/model_commands.cpp
void registerFitCommands(CLI::App& app);          // app/fit_commands.cpp
void registerPredictCommands(CLI::App& app);      // app/predict_commands.cpp
void registerViewCommands(CLI::App& app);         // app/view_commands.cpp
void registerDatasetCommands(CLI::App& app);      // app/dataset_commands.cpp
void registerMetricsCommands(CLI::App& app);      // app/metrics_commands.cpp
void registerDemoCommand(CLI::App& app);          // app/demo_command.cpp

// The "bench" subcommand that layers add their benchmarks to ("flarekit bench render ...").
CLI::App& benchCommand(CLI::App& app);

}  // namespace flarekit::app
