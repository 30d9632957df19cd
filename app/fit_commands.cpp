// flarekit fit, flarekit fit-eval, flarekit bench fit: parse options, call fit/.
#include <iostream>
#include <memory>
#include <optional>

#include <nlohmann/json.hpp>
#include <tbb/global_control.h>

#include "app/commands.h"
#include "common/atomic_file.h"
#include "common/config.h"
#include "common/error.h"
#include "common/image.h"
#include "common/log.h"
#include "fit/evaluation.h"
#include "fit/flare_fitter.h"
#include "fit/frames.h"
#include "fit/optimizer_bench.h"
#include "fit/report.h"

namespace flarekit::app {
namespace {

namespace fs = std::filesystem;

struct StackArgs {
  std::vector<std::string> inputs;
  std::string angles_csv, angle_pattern, layer;
  std::string camera, lens, light;
  double f_number = 0, iso = 0, exposure_s = 0, pixel_pitch_um = 0, focal_length_mm = 0;
};

void addStackOptions(CLI::App* cmd, StackArgs& a) {
  cmd->add_option("--angles-csv", a.angles_csv, "EXR stacks: CSV \"file,angle_deg\" with each frame's angle");
  cmd->add_option("--angle-pattern", a.angle_pattern,
                  "EXR stacks: regular expression whose first group in the file name is the angle, e.g. 'theta_([-0-9.]+)'");
  cmd->add_option("--layer", a.layer, "Layer holding the image (default: the main layer Y or R,G,B)");
  cmd->add_option("--camera", a.camera, "EXR stacks: camera model for the model file");
  cmd->add_option("--lens", a.lens, "EXR stacks: lens name for the model file");
  cmd->add_option("--light", a.light, "EXR stacks: light source for the model file");
  cmd->add_option("--f-number", a.f_number, "EXR stacks: f-number (else from attributes, else 1)");
  cmd->add_option("--iso", a.iso, "EXR stacks: ISO (else from attributes, else 100)");
  cmd->add_option("--exposure-s", a.exposure_s, "EXR stacks: exposure time in s (else from attributes, else 1)");
  cmd->add_option("--pixel-pitch-um", a.pixel_pitch_um, "EXR stacks: pixel pitch in µm (else from attributes, else 1)");
  cmd->add_option("--focal-length-mm", a.focal_length_mm,
                  "EXR stacks: the lens's focal length in mm (else from attributes, else unknown)");
}

fit::FrameStack loadStack(const StackArgs& a) {
  fit::FrameLoadOptions o;
  o.angles_csv = a.angles_csv;
  o.angle_pattern = a.angle_pattern;
  o.layer = a.layer;
  o.info.camera = a.camera;
  o.info.lens = a.lens;
  o.info.light = a.light;
  o.info.f_number = a.f_number;
  o.info.iso = a.iso;
  o.info.exposure_s = a.exposure_s;
  o.info.pixel_pitch_um = a.pixel_pitch_um;
  o.info.focal_length_mm = a.focal_length_mm;
  std::string error;
  if (!o.IsValid(&error)) throw InputError(error);
  std::vector<fs::path> inputs(a.inputs.begin(), a.inputs.end());
  return fit::loadFrames(inputs, o);
}

void registerFit(CLI::App& app) {
  struct Options {
    StackArgs stack;
    std::string out, optimizer = "ceres", holdout, report;
    int threads = 2;
    double edge_weight = -1, frame_step_deg = fit::FlareFitterOptions{}.frame_step_deg;
    bool refine = false, pedestal = true;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "fit", "Fit a model of every ghost to a capture: ghosts found once in the sweep image, fitted in "
             "every frame, made polynomials in the light angle (docs/fitting.md); writes model.json");
  cmd->add_option("CAPTURE", o->stack.inputs, "Capture folder (manifest.json), or EXR files / folders")
      ->required();
  cmd->add_option("--out", o->out, "Model file to write (model.json)")->required();
  cmd->add_option("--optimizer", o->optimizer,
                  "Frame fits: ceres (Levenberg–Marquardt, default) or walch-gd (the paper's gradient descent)");
  cmd->add_option("--holdout", o->holdout, "odd: fit on every other frame only (evaluate the others with fit-eval --frames odd)");
  cmd->add_option("--report", o->report,
                  "Folder for the summary, the sweep picture, each ghost's frame fits and contact sheets");
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  cmd->add_option("--edge-weight", o->edge_weight, "λ, the edge term's weight (default 1)");
  cmd->add_option("--frame-step", o->frame_step_deg,
                  "Fit frames one by one this many degrees apart (every frame of a coarser capture)")
      ->capture_default_str();
  cmd->add_flag("--refine,!--no-refine", o->refine,
                "Also refine the polynomials against the frames themselves in one Ceres problem (off by default: see docs/fitting.md)");
  cmd->add_flag("--pedestal,!--no-pedestal", o->pedestal,
                "Fit the pedestal, the smooth glow of veils wider than the frame (default)");
  addStackOptions(cmd, o->stack);
  cmd->callback([o] {
    fit::FlareFitterOptions options;
    options.frame_fit.solver.optimizer = fit::parseOptimizer(o->optimizer);
    if (!o->holdout.empty() && o->holdout != "odd") throw InputError("--holdout: only \"odd\" is supported");
    options.holdout_odd = o->holdout == "odd";
    options.threads = o->threads;
    options.frame_step_deg = o->frame_step_deg;
    if (o->edge_weight >= 0) {
      options.frame_fit.cost.edge_weight = o->edge_weight;
      options.model_fit.cost.edge_weight = o->edge_weight;
    }
    options.model_fit.refine = o->refine;
    options.frame_fit.pedestal = o->pedestal;
    options.model_fit.pedestal = o->pedestal;
    std::string error;
    if (!options.IsValid(&error)) throw InputError(error);
    checkWritable(o->out);  // before minutes of fitting, not after
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, options.threads);
    fit::FrameStack stack = loadStack(o->stack);
    fit::FitResult result = fit::fitFlare(stack, options);
    result.model.save(o->out);
    if (!o->report.empty()) fit::writeFitReport(o->report, result, stack);
    logInfo(result.summary.BriefReport());
    logInfo("Model written to " + o->out);
  });
}

void registerSweep(CLI::App& app) {
  struct Options {
    StackArgs stack;
    std::string out;
    int threads = 2;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "sweep", "Draw a capture's sweep image: the horizon rows of all frames over the angle, with the "
               "ghosts' border traces and ids the fit finds in it");
  cmd->add_option("CAPTURE", o->stack.inputs, "Capture folder (manifest.json), or EXR files / folders")
      ->required();
  cmd->add_option("--out", o->out, "PNG to write")->required();
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  addStackOptions(cmd, o->stack);
  cmd->callback([o] {
    if (fs::path(o->out).extension() != ".png") throw InputError(o->out, "--out writes a PNG: name it *.png");
    checkWritable(o->out);
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::max(1, o->threads));
    const fit::FrameStack stack = loadStack(o->stack);
    const fit::FlareFitterOptions options;
    const fit::Horizon horizon = fit::measureHorizon(stack, options.horizon);
    const fit::SweepImage sweep = fit::buildSweep(stack, horizon, options.sweep);
    const std::vector<fit::BorderTrace> traces = fit::findTraces(sweep, options.sweep);
    fit::CandidateSummary found;
    const auto candidates = fit::findGhostCandidates(stack, sweep, traces, options.candidates, &found);
    writeImage8(o->out, fit::sweepPicture(sweep, traces, candidates));
    logInfo(std::to_string(traces.size()) + " traces, " + std::to_string(candidates.size()) + " ghosts (" +
            std::to_string(found.pairs) + " from two borders, " + std::to_string(found.single) + " from one, " +
            std::to_string(found.peaks) + " from a peak); written to " + o->out);
  });
}

void registerFitEval(CLI::App& app) {
  struct Options {
    std::string model;
    StackArgs stack;
    std::string frames = "all";
    bool json = false;
    int threads = 2;
    std::string plot, ceiling;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "fit-eval", "Compare a fitted model with a capture and, where truth/ exists, with the ground "
                  "truth: PSNR (of the frame and over each ghost's support), centroid errors (px and "
                  "% of the ghost's radius), flux errors, detection recall and precision, track "
                  "continuity, model ghosts on the light");
  cmd->add_option("MODEL", o->model,
                  "Model file (model.json), or the per-frame fits of a fit's report (REPORT/frame_fits.json)")
      ->required();
  cmd->add_option("CAPTURE", o->stack.inputs, "Capture folder, or EXR files / folders")->required();
  cmd->add_option("--frames", o->frames, "all (default) or odd (the frames --holdout odd left out)");
  cmd->add_option("--ceiling", o->ceiling,
                  "The capture's model ceiling (flarekit fit-ceiling --json output; with --fit-above, "
                  "the ceiling of the ghosts above that level): each frame's PSNR set against it");
  cmd->add_option("--plot", o->plot,
                  "PNG of PSNR and ghosts found over the angles (with the ceiling, when given)");
  cmd->add_flag("--json", o->json, "Print one JSON object");
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  addStackOptions(cmd, o->stack);
  cmd->callback([o] {
    if (o->frames != "all" && o->frames != "odd")
      throw InputError("--frames: expected all or odd, got \"" + o->frames + "\"");
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::max(1, o->threads));
    // A flare model, or the per-frame fits a fit's report holds (fit/frame_fits.h).
    const ConfigNode root = loadJsonFile(o->model);
    const bool frame_fits = root.has("format") && root["format"].json() == fit::kFrameFitsFormat;
    std::optional<model::FlareModel> m;
    std::optional<fit::FrameFits> fits;
    if (frame_fits)
      fits = fit::FrameFits::fromJson(root);
    else
      m = model::FlareModel::fromJson(root);
    const cv::Size size = m ? m->capture.image_size : fits->image_size;
    const int channels = m ? m->channels : fits->channels;
    fit::FrameStack stack = loadStack(o->stack);
    if (size != stack.size)
      throw InputError(o->model, "fitted to " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                                     " frames, the capture's are " + std::to_string(stack.size.width) + "x" +
                                     std::to_string(stack.size.height));
    if (channels != stack.channels)
      throw InputError(o->model, "has " + std::to_string(channels) + " channel(s), the capture " +
                                     std::to_string(stack.channels));
    if (!o->plot.empty()) {
      if (fs::path(o->plot).extension() != ".png")
        throw InputError(o->plot, "--plot writes a PNG: name it *.png");
      checkWritable(o->plot);  // before the evaluation, not after
    }
    fit::CeilingCurve ceiling;
    if (!o->ceiling.empty()) {
      if (!stack.has_truth)
        throw InputError(o->ceiling,
                         "is a ceiling against ground truth, and the capture has none (truth/)");
      ceiling = fit::parseCeiling(loadJsonFile(o->ceiling).json(), stack.size, o->ceiling);
    }
    fit::EvaluationOptions options;
    options.odd_frames_only = o->frames == "odd";
    fit::Evaluation ev =
        m ? fit::evaluateModel(*m, stack, options) : fit::evaluateFrameFits(*fits, stack, options);
    if (ev.frames.empty())
      throw InputError(o->model, "none of the capture's frames" + std::string(options.odd_frames_only ? " (odd)" : "") +
                                     " was fitted: nothing to evaluate");
    if (!o->ceiling.empty()) {
      ev.setCeiling(ceiling);
      if (ev.ceiling_frames == 0)
        throw InputError(o->ceiling,
                         "has no frame at the angles evaluated (was it measured on this capture?)");
    }
    if (!o->plot.empty()) writeImage8(o->plot, fit::evaluationPlot(ev));
    if (o->json)
      std::cout << jsonText(ev.toJson()) << "\n";
    else
      std::cout << ev.BriefReport() << "\n";
  });
}

void registerFitCeiling(CLI::App& app) {
  struct Options {
    StackArgs stack;
    int every = 10, threads = 2;
    double edge_weight = -1, fit_above = 0;
    bool json = false, quadratic_pedestal = false;
    std::string sheets;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "fit-ceiling", "What the ghost model can describe of a simulated capture at best: every true ghost fitted "
                     "alone to its noise-free truth layer, measured as fit-eval measures a model");
  cmd->add_option("CAPTURE", o->stack.inputs, "Capture folder with ground truth (truth/)")->required();
  cmd->add_option("--every", o->every, "Measure every Nth frame (default 10)");
  cmd->add_option("--edge-weight", o->edge_weight, "λ of the first stage of each fit (default 1, as fit)");
  cmd->add_option("--fit-above", o->fit_above,
                  "Fit only the true ghosts whose peak exceeds this many noise σ, the rest drawn as one flat "
                  "pedestal: what a fitter that finds every ghost above that level could reach (default 0: "
                  "every ghost)");
  cmd->add_flag("--quadratic-pedestal", o->quadratic_pedestal,
                "With --fit-above: the pedestal a quadratic in x and y over the frame instead of flat");
  cmd->add_option("--sheets", o->sheets,
                  "Folder for one picture per measured frame: noise-free flare | ceiling | |flare − ceiling|");
  cmd->add_flag("--json", o->json, "Print one JSON object");
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  addStackOptions(cmd, o->stack);
  cmd->callback([o] {
    fit::CeilingOptions options;
    if (o->every < 1) throw InputError("--every: expected a number ≥ 1, got " + std::to_string(o->every));
    options.frame_step = o->every;
    if (o->edge_weight >= 0) options.cost.edge_weight = o->edge_weight;
    if (!(o->fit_above >= 0)) throw InputError("--fit-above: expected a number of noise σ ≥ 0");
    options.fit_factor = o->fit_above;
    if (o->quadratic_pedestal && !(o->fit_above > 0))
      throw InputError("--quadratic-pedestal: needs --fit-above above 0 (below it no ghost is drawn as a pedestal)");
    options.quadratic_pedestal = o->quadratic_pedestal;
    std::string error;
    if (!options.IsValid(&error)) throw InputError(error);
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::max(1, o->threads));
    const fit::FrameStack stack = loadStack(o->stack);
    const fit::ModelCeiling ceiling = fit::measureModelCeiling(stack, options);
    if (!o->sheets.empty()) fit::writeCeilingSheets(o->sheets, ceiling);
    if (o->json)
      std::cout << jsonText(ceiling.toJson()) << "\n";
    else
      std::cout << ceiling.BriefReport() << "\n";
  });
}

void registerBenchFit(CLI::App& app) {
  struct Options {
    StackArgs stack;
    bool json = false;
    int frames = 3, seeds = 1, gd_iterations = 200, threads = 2;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = benchCommand(app).add_subcommand(
      "fit", "Ceres (Levenberg–Marquardt) against the paper's gradient descent on the same frames "
             "from the same starts: time and cost evaluations to reach the GD's final cost");
  cmd->add_option("CAPTURE", o->stack.inputs, "Capture folder, or EXR files / folders")->required();
  cmd->add_flag("--json", o->json, "Print one JSON object (always JSON; accepted for symmetry)");
  cmd->add_option("--frames", o->frames, "Frames sampled evenly (default 3)");
  cmd->add_option("--seeds", o->seeds, "Starts per frame: the brightest ghost candidates present (default 1)");
  cmd->add_option("--gd-iterations", o->gd_iterations, "Gradient-descent iterations per start (default 200)");
  cmd->add_option("--threads", o->threads, "Threads (default 2)");
  addStackOptions(cmd, o->stack);
  cmd->callback([o] {
    fit::OptimizerBenchOptions options;
    options.frames = o->frames;
    options.seeds_per_frame = o->seeds;
    options.gd_iterations = o->gd_iterations;
    options.fit.threads = o->threads;
    std::string error;
    if (!options.IsValid(&error)) throw InputError(error);
    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, o->threads);
    fit::FrameStack stack = loadStack(o->stack);
    std::cout << jsonText(fit::benchOptimizers(stack, options)) << "\n";
  });
}

}  // namespace

void registerFitCommands(CLI::App& app) {
  registerBenchFit(app);
  registerFit(app);
  registerSweep(app);
  registerFitEval(app);
  registerFitCeiling(app);
}

}  // namespace flarekit::app
