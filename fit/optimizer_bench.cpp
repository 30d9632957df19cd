#include "fit/optimizer_bench.h"

#include <cmath>

#include "common/error.h"
#include "common/image.h"
#include "common/progress.h"
#include "fit/evaluation.h"
#include "fit/ghost_candidates.h"
#include "fit/horizon.h"
#include "fit/sweep.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

bool OptimizerBenchOptions::IsValid(std::string* error) const {
  if (frames < 1 || seeds_per_frame < 1 || gd_iterations < 1) {
    if (error) *error = "frames, seeds_per_frame and gd_iterations must be ≥ 1";
    return false;
  }
  return fit.IsValid(error);
}

CeresEnd describeCeresEnd(GroupCost& cost, const model::GhostParameters& ceres_end,
                          const model::GhostParameters& gd_end) {
  CeresEnd end;
  const std::vector<double> a = model::toParameterVector(ceres_end), b = model::toParameterVector(gd_end);
  constexpr int kSteps = 10;
  for (int i = 0; i <= kSteps; ++i) {
    const double t = static_cast<double>(i) / kSteps;
    std::vector<double> p(a.size());
    for (size_t k = 0; k < a.size(); ++k) p[k] = a[k] + t * (b[k] - a[k]);
    const std::vector<model::GhostParameters> one = {model::fromParameterVector(p, ceres_end.channels)};
    end.path_costs.push_back(cost.evaluate(one, false));
  }
  end.stalled = end.path_costs[1] < end.path_costs[0];
  const auto names = model::parameterNames(ceres_end.channels);
  const auto bounds = fitBounds(cost);
  for (size_t k = 0; k < a.size(); ++k)
    if (a[k] <= bounds[k].lower || a[k] >= bounds[k].upper) end.on_bounds.push_back(names[k]);
  return end;
}

nlohmann::json benchOptimizers(const FrameStack& stack, const OptimizerBenchOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError("bench fit: " + error);
  const CostOptions& cost = options.fit.frame_fit.cost;
  EdgeFilter edge(cost);
  // The seeds the fitter starts from: the ghost candidates of stages 2–4 at each frame.
  const Horizon horizon = measureHorizon(stack, options.fit.horizon);
  const SweepImage sweep = buildSweep(stack, horizon, options.fit.sweep);
  const std::vector<BorderTrace> traces = findTraces(sweep, options.fit.sweep);
  const std::vector<GhostCandidate> candidates =
      findGhostCandidates(stack, sweep, traces, options.fit.candidates);
  nlohmann::json cases = nlohmann::json::array();
  std::vector<double> speedup_time, speedup_evals;
  const int n = static_cast<int>(stack.frames.size());
  Progress progress("bench fit", options.frames);
  int reached = 0, total = 0, stalled = 0;
  for (int k = 0; k < options.frames; ++k) {
    progress.advance();
    // Sample inside the range (the ends are where ghosts are hardest to see).
    const int index = std::min(n - 1, static_cast<int>((k + 0.5) * n / options.frames));
    const Frame& frame = stack.frames[index];
    FramePyramid pyramid(frame.image, frame.valid, edge, estimatePixelNoiseSigma(frame.image, frame.valid));
    // The brightest ghosts present first, of those with a pixel in the frame: a candidate's range
    // ends where it has left the frame, but within it a seed may still lie wholly beyond the edge.
    const cv::Rect image(0, 0, stack.size.width, stack.size.height);
    std::vector<model::GhostParameters> seeds;
    for (const auto& c : candidates)
      if (c.present(index) && !(model::ghostPixelBounds(c.seed(index)) & image).empty())
        seeds.push_back(c.seed(index));
    auto peak = [](const model::GhostParameters& g) { return std::max(g.border[0], g.inside[0]); };
    std::stable_sort(seeds.begin(), seeds.end(), [&](const auto& a, const auto& b) { return peak(a) > peak(b); });
    if (static_cast<int>(seeds.size()) > options.seeds_per_frame) seeds.resize(options.seeds_per_frame);
    for (const auto& seed : seeds) {
      std::vector<model::GhostParameters> one = {seed};
      SolverOptions gd = options.fit.frame_fit.solver;
      gd.optimizer = Optimizer::kWalchGd;
      gd.gd_max_iterations = options.gd_iterations;
      gd.gd_patience = options.gd_iterations;
      gd.record_trace = true;
      GroupCost gd_cost(pyramid, edge, {}, one, cost);
      const GroupFitResult g = solveGroup(gd_cost, one, gd);
      SolverOptions lm = options.fit.frame_fit.solver;
      lm.optimizer = Optimizer::kCeres;
      lm.record_trace = true;
      lm.max_iterations = 100;
      lm.function_tolerance = 1e-10;
      lm.parameter_tolerance = 1e-10;
      GroupCost lm_cost(pyramid, edge, {}, one, cost);
      const GroupFitResult c = solveGroup(lm_cost, one, lm);
      // GD's time and evaluations to its own final cost.
      TracePoint gd_reach = g.trace.back();
      for (const auto& t : g.trace)
        if (t.cost <= g.final_cost) {
          gd_reach = t;
          break;
        }
      nlohmann::json entry = {{"angle_deg", frame.angle_deg},
                              {"seed", model::toParameterVector(seed)},
                              {"initial_cost", g.initial_cost},
                              {"gd_final_cost", g.final_cost},
                              {"gd_seconds", gd_reach.seconds},
                              {"gd_evaluations", gd_reach.evaluations},
                              {"gd_iterations", g.iterations},
                              {"ceres_final_cost", c.final_cost},
                              {"ceres_seconds_total", c.seconds},
                              {"ceres_evaluations_total", c.evaluations},
                              {"ceres_iterations", c.iterations},
                              {"ceres_termination", c.termination},
                              {"gd_final_parameters", model::toParameterVector(g.ghosts[0])},
                              {"ceres_final_parameters", model::toParameterVector(c.ghosts[0])}};
      ++total;
      bool ok = false;
      for (const auto& t : c.trace)
        if (t.cost <= g.final_cost) {
          entry["ceres_seconds_to_gd_cost"] = t.seconds;
          entry["ceres_evaluations_to_gd_cost"] = t.evaluations;
          const double st = gd_reach.seconds / std::max(t.seconds, 1e-9);
          const double se = double(gd_reach.evaluations) / std::max<long long>(t.evaluations, 1);
          entry["speedup_time"] = st;
          entry["speedup_evaluations"] = se;
          speedup_time.push_back(st);
          speedup_evals.push_back(se);
          ok = true;
          ++reached;
          break;
        }
      entry["ceres_reached_gd_cost"] = ok;
      const CeresEnd end = describeCeresEnd(lm_cost, c.ghosts[0], g.ghosts[0]);
      entry["ceres_parameters_on_bounds"] = end.on_bounds;
      entry["path_costs_ceres_to_gd"] = end.path_costs;
      if (!ok) {
        entry["ceres_stalled"] = end.stalled;
        if (end.stalled) ++stalled;
      }
      cases.push_back(entry);
    }
  }
  progress.finish();
  nlohmann::json out;
  out["benchmark"] = "fit";
  out["capture"] = stack.source.string();
  out["gd_iterations"] = options.gd_iterations;
  out["cases"] = cases;
  out["cases_total"] = total;
  out["cases_ceres_reached_gd_cost"] = reached;
  // Of the cases Ceres did not win, those where it stopped on a slope towards the GD's end.
  out["cases_ceres_stalled"] = stalled;
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  out["median_speedup_time"] = num(medianOf(speedup_time));
  out["median_speedup_evaluations"] = num(medianOf(speedup_evals));
  out["threads"] = options.fit.threads;
  return out;
}

}  // namespace flarekit::fit
