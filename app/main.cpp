// The flarekit command: parses arguments, calls the libraries, maps errors to exit codes
// (0 success, 1 runtime failure, 2 bad usage or input, 130 interrupted).
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>

#include "app/commands.h"
#include "common/error.h"
#include "common/log.h"

#ifndef FLAREKIT_VERSION
#define FLAREKIT_VERSION "unknown"
#endif

int main(int argc, char** argv) {
  using namespace flarekit;
  CLI::App app{"FlareKit: measure the lens flare of a real lens, fit a model of every ghost, "
               "and predict flare for light planning.",
               "flarekit"};
  app.set_version_flag("--version", "flarekit " FLAREKIT_VERSION);
  app.require_subcommand(1);
  app.fallthrough();
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Print only warnings and errors, no progress");
  app.add_flag("-v,--verbose", verbose, "Print debugging detail");
  app.parse_complete_callback([&] {
    if (quiet) setLogLevel(LogLevel::kWarning);
    if (verbose) setLogLevel(LogLevel::kDebug);
  });

  app::registerCommonCommands(app);
  app::registerRenderCommands(app);
  app::registerAcquisitionCommands(app);
  app::registerModelCommands(app);
  app::registerFitCommands(app);
  app::registerPredictCommands(app);
  app::registerViewCommands(app);
  app::registerDatasetCommands(app);
  app::registerMetricsCommands(app);
  app::registerDemoCommand(app);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
    std::cerr << "flarekit: error: " << oneLine(e.what()) << " (see flarekit --help)\n";
    return 2;
  } catch (const InputError& e) {
    logError(e.what());
    return 2;
  } catch (const Interrupted& e) {
    logError(e.what());
    return 130;
  } catch (const RuntimeError& e) {
    logError(e.what());
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // A path the libraries stat or list without their own check: a name that cannot be resolved
    // is the user's input (2), anything else (permissions, a full disk) the environment's (1).
    const std::error_code c = e.code();
    const bool input = c == std::errc::no_such_file_or_directory || c == std::errc::too_many_symbolic_link_levels ||
                       c == std::errc::not_a_directory || c == std::errc::filename_too_long;
    logError(e.path1().string() + ": " + c.message() + (input ? "" : " (check the folder's permissions and free space)"));
    return input ? 2 : 1;
  } catch (const std::exception& e) {
    logError(std::string("unexpected failure: ") + e.what());
    return 1;
  }
  return 0;
}
