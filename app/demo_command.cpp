// flarekit demo: the whole workflow on the embedded default, as a newcomer's first run —
// a simulated capture on the default rig (acquisition/), the fit of every ghost (fit/), and a
// light-planning report for the bundled example scene (predict/). Each step only calls its
// library; rerunning continues a capture that was stopped (the capture is resumable).
#include <filesystem>
#include <iostream>

#include <tbb/global_control.h>

#include "acquisition/capture.h"
#include "acquisition/rig.h"
#include "app/commands.h"
#include "common/atomic_file.h"
#include "common/error.h"
#include "common/log.h"
#include "common/shipped_file.h"
#include "fit/flare_fitter.h"
#include "fit/frames.h"
#include "model/flare_model.h"
#include "predict/prediction.h"
#include "predict/scene.h"

namespace flarekit::app {
namespace {

namespace fs = std::filesystem;

// A file shipped with the project: relative to the working folder, else to the source tree.
fs::path projectFile(const fs::path& relative) {
  if (auto found = findShippedFile(relative)) return *found;
  throw InputError(relative.string() + ": not found (run from the FlareKit folder)");
}

}  // namespace

void registerDemoCommand(CLI::App& app) {
  struct Options {
    std::string out = "flarekit-demo";
    std::string rig = "sim-heliar";
    std::string scene = "predict/examples/stage_100mm.json";
    int threads = 0;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "demo", "Simulated capture on the default rig, fit of every ghost, and a light-planning "
              "report for the example scene; prints where the report is");
  cmd->add_option("--out", o->out, "Output folder (default flarekit-demo)");
  cmd->add_option("--rig", o->rig, "Simulated rig (default sim-heliar)");
  cmd->add_option("--scene", o->scene, "Scene for the report (default the bundled example)");
  cmd->add_option("--threads", o->threads, "Threads (0 = all cores)");
  cmd->callback([o] {
    const fs::path out = o->out;
    const fs::path capture_dir = out / "capture", model_file = out / "model.json",
                   report_dir = out / "report";
    createFolder(out);
    std::optional<tbb::global_control> threads;
    if (o->threads > 0)
      threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(o->threads));

    // 1. Capture (Walch 2018 §3.1) on the simulated rig; resumes a stopped one.
    const acquisition::Rig rig = acquisition::loadRig(acquisition::findRig(o->rig));
    if (!rig.simulated())
      throw InputError(rig.file.string() + ": the demo runs on a simulated rig only");
    acquisition::RigDevices devices = acquisition::openRig(rig);
    acquisition::CaptureOptions capture_options;
    capture_options.resume = fs::exists(capture_dir / "manifest.json");
    logInfo("1/3 capture: " + rig.name + " -> " + capture_dir.string());
    const acquisition::CaptureSummary captured = acquisition::runCapture(
        rig, devices, acquisition::CapturePlan::FromRig(rig), capture_dir, capture_options);
    logInfo(captured.BriefReport());

    // 2. Fit every ghost and its polynomials (§3.3).
    logInfo("2/3 fit: " + capture_dir.string() + " -> " + model_file.string());
    const fit::FrameStack stack = fit::loadCapture(capture_dir);
    const fit::FitResult fitted = fit::fitFlare(stack, fit::FlareFitterOptions{});
    fitted.model.save(model_file);
    logInfo(fitted.summary.BriefReport());

    // 3. Predict the example scene (§3.4–3.5).
    logInfo("3/3 predict: " + o->scene + " -> " + report_dir.string());
    const predict::Scene scene = predict::loadScene(projectFile(o->scene));
    const predict::PredictionSummary predicted =
        predict::predict(fitted.model, scene, predict::PredictOptions{}, report_dir, model_file);
    logInfo(predicted.BriefReport());
    std::cout << "Report: " << (report_dir / "report.html").string() << "\n";
  });
}

}  // namespace flarekit::app
