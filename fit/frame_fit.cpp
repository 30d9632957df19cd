#include "fit/frame_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/image.h"
#include "common/progress.h"
#include "fit/shade.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

bool FrameFitOptions::IsValid(std::string* error) const {
  if (!cost.IsValid(error) || !solver.IsValid(error) || !shade.IsValid(error)) return false;
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (sweeps < 1) return fail("frame fit: sweeps must be ≥ 1");
  if (!(seen_border_sigma_px > 0) || !(unseen_sigma_fraction > 0))
    return fail("frame fit: seen_border_sigma_px and unseen_sigma_fraction must be > 0");
  return true;
}

model::GhostParameters canonicalShade(const model::GhostParameters& g) {
  model::GhostParameters c = g;
  const double deepest = std::min(g.height, 0.5 * (g.left + g.right));
  if (!(g.inside_falloff > deepest) || !(deepest > 0)) return c;
  const double reached = std::pow(deepest / g.inside_falloff, g.inside_exponent);
  for (int ch = 0; ch < g.channels; ++ch)
    c.inside[ch] = g.border[ch] + (g.inside[ch] - g.border[ch]) * reached;
  c.inside_falloff = std::max(deepest, model::parameterBounds(model::ParameterLayout{g.channels}.fi(), g.channels).lower);
  return c;
}

std::vector<GhostCandidate> seedsFromModel(const std::vector<GhostCandidate>& candidates,
                                           const model::FlareModel& model, const FrameStack& stack) {
  std::vector<GhostCandidate> out = candidates;
  for (auto& c : out) {
    const auto track = std::find_if(model.ghosts.begin(), model.ghosts.end(),
                                    [&](const model::GhostTrack& g) { return g.id == c.id; });
    if (track == model.ghosts.end()) continue;
    for (int row = c.first_row; row <= c.last_row; ++row) {
      const double angle = model.capture.fieldAngle(stack.frames[row].angle_deg);
      if (!track->covers(angle)) continue;
      const model::GhostParameters m = track->at(angle, stack.channels);
      model::GhostParameters& seed = c.seeds[row - c.first_row];
      const double xl = c.leftSeen(row) ? seed.center_x - seed.left : m.center_x - m.left;
      const double xr = c.rightSeen(row) ? seed.center_x + seed.right : m.center_x + m.right;
      if (!(xr - xl > 1)) continue;
      model::GhostParameters s = m;
      const double middle = c.leftSeen(row) && c.rightSeen(row) ? seed.center_x : m.center_x;
      s.center_x = std::clamp(middle, xl + 0.5, xr - 0.5);
      s.center_y = seed.center_y;
      s.left = s.center_x - xl;
      s.right = xr - s.center_x;
      seed = model::clampToBounds(s);
    }
  }
  return out;
}

namespace {


FrameFit fitOneFrame(const FrameStack& stack, int index, const LightImage& light, const LightPattern& pattern,
                     const std::vector<GhostCandidate>& candidates, const FrameFitOptions& o,
                     const EdgeFilter& edge) {
  Frame frame = stack.frames[index];
  frame.image = frame.image.clone();
  frame.valid = frame.valid.clone();
  pattern.takeOut(light, frame.image, frame.valid);
  FrameFit fit;
  fit.frame = index;
  fit.angle_deg = frame.angle_deg;
  fit.noise_sigma = estimatePixelNoiseSigma(frame.image, frame.valid);
  std::vector<std::array<bool, 2>> traced;  // whether the sweep traced its left, right border here
  for (const auto& c : candidates)
    if (c.present(index)) {
      fit.ghost_ids.push_back(c.id);
      fit.ghosts.push_back(c.seed(index));
      traced.push_back({c.leftSeen(index), c.rightSeen(index)});
    }
  const std::vector<model::GhostParameters> seeds = fit.ghosts;
  // Largest first: the small ones then fit on what the large ones leave.
  std::vector<size_t> order(fit.ghosts.size());
  std::iota(order.begin(), order.end(), 0);
  auto area = [&](size_t i) {
    const auto& g = fit.ghosts[i];
    return (g.left + g.right) * g.height;
  };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return area(a) > area(b); });
  // The shades of all ghosts and the pedestal together, then each ghost's outline in turn with
  // the others and the pedestal held, then the shades together again.
  model::Pedestal* pedestal = o.pedestal ? &fit.pedestal : nullptr;
  fitShades(frame.image, frame.valid, fit.noise_sigma, fit.ghosts, pedestal, o.shade);
  // Outlines are fitted to the luminance (one shape per ghost, whatever the channels): the
  // shades per channel then come from the linear solve.
  auto grey = [](const model::GhostParameters& g) {
    model::GhostParameters one = g;
    one.channels = 1;
    one.border = {luminance(g.border.data(), g.channels), 0, 0};
    one.inside = {luminance(g.inside.data(), g.channels), 0, 0};
    return one;
  };
  for (int sweep = 0; sweep < o.sweeps; ++sweep) {
    const cv::Mat target = luminance(frame.image - fit.pedestal.image(stack.size));
    FramePyramid pyramid(target, frame.valid, edge, fit.noise_sigma);
    fit.cost = 0;
    std::vector<model::GhostParameters> shapes;
    for (const auto& g : fit.ghosts) shapes.push_back(grey(g));
    for (size_t i : order) {
      std::vector<model::GhostParameters> others;
      for (size_t j = 0; j < shapes.size(); ++j)
        if (j != i) others.push_back(shapes[j]);
      // The borders the sweep saw in the frame are known to a pixel or two; the rest of the
      // outline (beyond the frame, in the light) only roughly.
      const model::GhostParameters& seed = seeds[i];
      const double size = std::max({seed.left, seed.right, seed.height});
      auto border = [&](bool seen) { return seen ? o.seen_border_sigma_px : o.unseen_sigma_fraction * size; };
      const std::array<double, 6> sigmas = {border(traced[i][0]), border(traced[i][1]), 1.0,
                                            o.unseen_sigma_fraction * seed.height, 0.3, 0.3};
      GroupCost cost(pyramid, edge, others, std::span(&shapes[i], 1), o.cost, std::span(&sigmas, 1));
      const GroupFitResult r = solveGroup(cost, std::span(&shapes[i], 1), o.solver);
      shapes[i] = r.ghosts[0];
      // The fitted outline and fall-offs; the shades stay the frame's until solved again.
      model::GhostParameters& g = fit.ghosts[i];
      const auto border_colour = g.border, inside_colour = g.inside;
      const int channels = g.channels;
      g = shapes[i];
      g.channels = channels;
      g.border = border_colour;
      g.inside = inside_colour;
      fit.cost += r.final_cost;
      fit.evaluations += r.evaluations;
      fit.iterations += r.iterations;
    }
    fitShades(frame.image, frame.valid, fit.noise_sigma, fit.ghosts, pedestal, o.shade);
  }
  for (auto& g : fit.ghosts) g = canonicalShade(g);
  return fit;
}

}  // namespace

std::vector<FrameFit> fitFrames(const FrameStack& stack, const std::vector<int>& frames,
                                const Horizon& horizon, const LightPattern& pattern,
                                const std::vector<GhostCandidate>& candidates,
                                const FrameFitOptions& options, FrameFitSummary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const auto t0 = std::chrono::steady_clock::now();
  FrameFitOptions o = options;
  o.solver.held_parameters.push_back(model::param::kMy);
  const EdgeFilter edge(o.cost);
  std::vector<FrameFit> fits(frames.size());
  Progress progress("Fitting frames", static_cast<long long>(frames.size()));
  tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
    fits[i] = fitOneFrame(stack, frames[i], horizon.lights[frames[i]], pattern, candidates, o, edge);
    progress.advance();
  });
  progress.finish();
  if (summary) {
    *summary = {};
    summary->frames = static_cast<int>(fits.size());
    for (const auto& f : fits) {
      summary->ghost_fits += static_cast<int>(f.ghosts.size());
      summary->evaluations += f.evaluations;
      summary->iterations += f.iterations;
    }
    summary->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return fits;
}

}  // namespace flarekit::fit
