// flarekit metrics: parse options, call metrics/.
#include <memory>

#include <tbb/global_control.h>

#include "app/commands.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "metrics/capture_metrics.h"
#include "metrics/report.h"
#include "model/flare_model.h"

namespace flarekit::app {
namespace {

namespace fs = std::filesystem;

void registerMetrics(CLI::App& app) {
  struct Options {
    std::vector<std::string> inputs, models;
    std::string out;
    int threads = 2;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "metrics",
      "Lab figures per light angle (flare flux outside the light's core, the brightest ghost's peak in "
      "stops, shares of the frame above 1e-3/1e-4/1e-5 of the light's peak, visible ghosts, each model "
      "ghost's flux) and the capture's trust (light stability, optical zero, horizon): metrics.csv, "
      "metrics.json, PNG plots and metrics.html (docs/metrics.md). Several inputs share the plots.");
  cmd->add_option("INPUT", o->inputs, "Capture folders (manifest.json) or flare-model files")->required();
  cmd->add_option("--model", o->models,
                  "A fitted model of a capture input, for each ghost's flux over θ; repeat it for "
                  "several captures (the k-th --model goes with the k-th capture)")
      ->allow_extra_args(false);  // one file per --model: the inputs after it stay inputs
  cmd->add_option("--out", o->out, "Folder for the files")->required();
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  cmd->callback([o] {
    if (o->threads < 1) throw InputError("metrics: --threads must be ≥ 1");
    // Every input named before any work: an unknown file fails at once.
    std::vector<bool> capture(o->inputs.size());
    int captures = 0;
    for (size_t i = 0; i < o->inputs.size(); ++i) {
      capture[i] = metrics::isCaptureFolder(o->inputs[i]);
      captures += capture[i];
    }
    for (const auto& m : o->models) {
      std::error_code ec;
      if (!fs::exists(m, ec)) throw InputError(m, "no such model file (--model)");
    }
    if (static_cast<int>(o->models.size()) > captures)
      throw InputError("metrics: " + std::to_string(o->models.size()) + " --model files for " +
                       std::to_string(captures) + " capture inputs (each --model goes with one capture)");
    // Each model against its capture, and the models given alone, before any measuring.
    for (size_t i = 0, k = 0; i < o->inputs.size(); ++i) {
      if (capture[i] && k < o->models.size()) metrics::checkModelForCapture(o->inputs[i], o->models[k++]);
      if (!capture[i]) (void)model::FlareModel::load(o->inputs[i]);
    }
    std::error_code ec;
    if (fs::exists(o->out, ec) && !fs::is_directory(o->out, ec))
      throw InputError(o->out, "--out names a file: give a folder");
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, o->threads);
    std::vector<metrics::Metrics> results;
    size_t next_model = 0;
    for (size_t i = 0; i < o->inputs.size(); ++i) {
      if (capture[i]) {
        const fs::path model = next_model < o->models.size() ? fs::path(o->models[next_model++]) : fs::path();
        logInfo("Measuring " + o->inputs[i] + (model.empty() ? "" : " with " + model.string()));
        results.push_back(metrics::measureCapture(o->inputs[i], model));
      } else {
        logInfo("Measuring the model " + o->inputs[i]);
        results.push_back(metrics::measureModel(o->inputs[i]));
      }
    }
    // Names tell the inputs apart on the plots.
    for (size_t i = 0; i < results.size(); ++i)
      for (size_t j = 0; j < i; ++j)
        if (results[j].name == results[i].name) results[i].name += " (" + std::to_string(i + 1) + ")";
    const auto files = metrics::writeMetricsReport(o->out, results);
    for (const auto& line : metrics::briefReport(results)) logInfo(line);
    for (const auto& m : results)
      for (const auto& w : m.trust.warnings) logWarning(m.name + ": " + w);
    logInfo("Wrote " + std::to_string(files.size()) + " files to " + o->out + " (open " +
            (fs::path(o->out) / "metrics.html").string() + ")");
  });
}

}  // namespace

void registerMetricsCommands(CLI::App& app) { registerMetrics(app); }

}  // namespace flarekit::app
