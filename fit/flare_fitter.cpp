#include "fit/flare_fitter.h"

#include <chrono>
#include <iomanip>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/log.h"

namespace flarekit::fit {

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

bool FlareFitterOptions::IsValid(std::string* error) const {
  if (!horizon.IsValid(error) || !light_pattern.IsValid(error) || !sweep.IsValid(error) || !candidates.IsValid(error) ||
      !optical_zero.IsValid(error) || !frame_fit.IsValid(error) || !model_fit.IsValid(error))
    return false;
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(frame_step_deg > 0)) return fail("fit: frame_step_deg must be > 0");
  if (threads < 1) return fail("fit: threads must be ≥ 1");
  return true;
}

std::string FitSummary::BriefReport() const {
  std::ostringstream s;
  s << std::fixed << std::setprecision(2);
  s << "Fit of " << frames_used << " of " << frames_total << " frames: horizon at y = " << horizon_y_px
    << " px, the light in " << light_frames << " frames";
  if (optical_zero.measured)
    s << ", optical zero at θ = " << std::setprecision(3) << optical_zero.angle_zero_deg << "°, x = "
      << std::setprecision(2) << optical_zero.axis_x_px << " px (" << optical_zero.ghosts_used << " ghosts)";
  s << ". " << traces << " traces: " << candidates.pairs << " ghosts from two borders, "
    << candidates.single << " from one, " << candidates.peaks << " from a peak, " << candidates.traces_unused
    << " traces inside ghosts. "
    << frame_fit.ghost_fits << " ghost fits in " << frame_fit.frames << " frames";
  if (model_fit.refine_frames > 0)
    s << "; the model refined on " << model_fit.refine_frames << " frames in " << model_fit.refine_iterations
      << " iterations (cost " << std::setprecision(4) << model_fit.refine_initial_cost << " → "
      << model_fit.refine_final_cost << ", " << model_fit.refine_termination << ")";
  s << std::setprecision(1) << ". " << ghosts << " ghosts in the model; " << seconds_total << " s (horizon "
    << seconds_horizon << ", sweep " << seconds_sweep << ", candidates " << seconds_candidates
    << ", frame fits " << seconds_frame_fit << ", model " << seconds_model_fit << ").";
  for (const auto& w : warnings) s << " " << w;
  return s.str();
}

nlohmann::json FitSummary::toJson() const {
  nlohmann::json j;
  j["frames_total"] = frames_total;
  j["frames_used"] = frames_used;
  j["horizon_y_px"] = horizon_y_px;
  j["light_frames"] = light_frames;
  j["optical_zero"] = {{"measured", optical_zero.measured},
                       {"angle_zero_deg", optical_zero.angle_zero_deg},
                       {"axis_x_px", optical_zero.axis_x_px},
                       {"light_rms_px", optical_zero.light_rms_px},
                       {"centre_rms_px", optical_zero.centre_rms_px},
                       {"ghosts_used", optical_zero.ghosts_used}};
  j["traces"] = traces;
  j["candidates"] = {{"pairs", candidates.pairs},
                     {"single", candidates.single},
                     {"peaks", candidates.peaks},
                     {"traces_unused", candidates.traces_unused}};
  j["frame_fit"] = {{"frames", frame_fit.frames},
                    {"ghost_fits", frame_fit.ghost_fits},
                    {"evaluations", frame_fit.evaluations},
                    {"iterations", frame_fit.iterations}};
  j["model_fit"] = {{"ghosts_unseen", model_fit.ghosts_unseen},
                    {"refine_frames", model_fit.refine_frames},
                    {"refine_iterations", model_fit.refine_iterations},
                    {"refine_initial_cost", model_fit.refine_initial_cost},
                    {"refine_final_cost", model_fit.refine_final_cost},
                    {"refine_termination", model_fit.refine_termination}};
  j["ghosts"] = ghosts;
  j["warnings"] = warnings;
  j["seconds_horizon"] = seconds_horizon;
  j["seconds_sweep"] = seconds_sweep;
  j["seconds_candidates"] = seconds_candidates;
  j["seconds_frame_fit"] = seconds_frame_fit;
  j["seconds_model_fit"] = seconds_model_fit;
  j["seconds_total"] = seconds_total;
  return j;
}

FitResult measureCaptureGeometry(const FrameStack& stack, const FlareFitterOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  FitResult result;
  FitSummary& sum = result.summary;
  sum.frames_total = sum.frames_used = static_cast<int>(stack.frames.size());
  for (size_t i = 0; i < stack.frames.size(); ++i) result.frames_used.push_back(static_cast<int>(i));
  auto t = Clock::now();
  result.horizon = measureHorizon(stack, options.horizon);
  result.light = measureLightPattern(stack, result.horizon, options.light_pattern);
  sum.horizon_y_px = result.horizon.y_px;
  sum.light_frames = result.horizon.lights_found;
  sum.seconds_horizon = since(t);

  t = Clock::now();
  result.sweep = buildSweep(stack, result.horizon, options.sweep);
  result.traces = findTraces(result.sweep, options.sweep);
  sum.traces = static_cast<int>(result.traces.size());
  sum.seconds_sweep = since(t);

  t = Clock::now();
  result.candidates = findGhostCandidates(stack, result.sweep, result.traces, options.candidates, &sum.candidates);
  sum.optical_zero = measureOpticalZero(stack, result.horizon,
                                        centreSamples(result.candidates, result.traces, result.sweep),
                                        options.optical_zero);
  // Where the light's core is cut by the frame's edge, or lies just beyond it, its halo and
  // starburst are still in the frame: the light's curve says where it is.
  if (!sum.optical_zero.light_coefficients.empty())
    for (size_t i = 0; i < stack.frames.size(); ++i) {
      LightImage& light = result.horizon.lights[i];
      const double x = sum.optical_zero.lightX(stack.frames[i].angle_deg);
      const bool cut = !light.found || light.cutByEdge(stack.size.width);
      if (cut && x > -result.light.radius_px && x < stack.size.width + result.light.radius_px)
        light = {true, {x, result.horizon.y_px}, light.core_radius_px};
    }
  sum.seconds_candidates = since(t);
  if (result.candidates.empty())
    sum.warnings.push_back("No ghost was found in the capture: the model is empty.");

  return result;
}

FitResult fitFlare(const FrameStack& full, const FlareFitterOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const auto t0 = Clock::now();
  FitResult result;
  FitSummary& sum = result.summary;
  sum.frames_total = static_cast<int>(full.frames.size());
  // Held out: the fit sees the even frames only.
  FrameStack held;
  const FrameStack* used = &full;
  if (options.holdout_odd) {
    held = full;
    held.frames.clear();
    for (size_t i = 0; i < full.frames.size(); i += 2) held.frames.push_back(full.frames[i]);
    used = &held;
  }
  const FrameStack& stack = *used;
  for (size_t i = 0; i < full.frames.size(); i += options.holdout_odd ? 2 : 1)
    result.frames_used.push_back(static_cast<int>(i));
  sum.frames_used = static_cast<int>(stack.frames.size());

  FitResult geometry = measureCaptureGeometry(stack, options);
  result.horizon = std::move(geometry.horizon);
  result.light = std::move(geometry.light);
  result.sweep = std::move(geometry.sweep);
  result.traces = std::move(geometry.traces);
  result.candidates = std::move(geometry.candidates);
  for (const auto& w : geometry.summary.warnings) sum.warnings.push_back(w);
  sum.horizon_y_px = geometry.summary.horizon_y_px;
  sum.light_frames = geometry.summary.light_frames;
  sum.optical_zero = geometry.summary.optical_zero;
  sum.traces = geometry.summary.traces;
  sum.candidates = geometry.summary.candidates;
  sum.seconds_horizon = geometry.summary.seconds_horizon;
  sum.seconds_sweep = geometry.summary.seconds_sweep;
  sum.seconds_candidates = geometry.summary.seconds_candidates;

  auto t = Clock::now();
  std::vector<int> frames;
  const size_t stride = std::max(1L, std::lround(options.frame_step_deg / stack.medianStepDeg()));
  for (size_t i = 0; i < stack.frames.size(); i += stride) frames.push_back(static_cast<int>(i));
  if (options.skip_frame_fit) {
    for (int i : frames) {
      FrameFit f;
      f.frame = i;
      f.angle_deg = stack.frames[i].angle_deg;
      for (const auto& c : result.candidates)
        if (c.present(i)) {
          f.ghost_ids.push_back(c.id);
          f.ghosts.push_back(c.seed(i));
        }
      result.frame_fits.push_back(std::move(f));
    }
  } else if (options.reseed_from_model) {
    std::vector<int> first;
    for (size_t i = 0; i < frames.size(); i += 2) first.push_back(frames[i]);
    const std::vector<FrameFit> first_fits =
        fitFrames(stack, first, result.horizon, result.light, result.candidates, options.frame_fit);
    sum.seconds_frame_fit = since(t);
    t = Clock::now();
    ModelFitOptions first_options = options.model_fit;
    first_options.pedestal = false;  // only its ghosts seed the second pass
    const model::FlareModel first_model = fitModel(stack, result.horizon, result.light, result.candidates,
                                                   first_fits, sum.optical_zero, first_options);
    sum.seconds_model_fit = since(t);
    t = Clock::now();
    result.frame_fits = fitFrames(stack, frames, result.horizon, result.light,
                                  seedsFromModel(result.candidates, first_model, stack), options.frame_fit,
                                  &sum.frame_fit);
  } else {
    result.frame_fits = fitFrames(stack, frames, result.horizon, result.light, result.candidates,
                                  options.frame_fit, &sum.frame_fit);
  }
  sum.seconds_frame_fit += since(t);

  t = Clock::now();
  result.model = fitModel(stack, result.horizon, result.light, result.candidates, result.frame_fits,
                          sum.optical_zero, options.model_fit, &sum.model_fit);
  sum.ghosts = static_cast<int>(result.model.ghosts.size());
  sum.seconds_model_fit += since(t);
  // Frame indices of the stack the caller gave.
  for (auto& f : result.frame_fits) f.frame = result.frames_used[f.frame];
  sum.seconds_total = since(t0);
  for (const auto& w : sum.warnings) logWarning(w);
  return result;
}

}  // namespace flarekit::fit
