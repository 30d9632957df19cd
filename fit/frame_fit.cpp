#include "fit/frame_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/progress.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

bool FrameFitOptions::IsValid(std::string* error) const {
  if (!cost.IsValid(error) || !solver.IsValid(error) || !pedestal_fit.IsValid(error)) return false;
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (sweeps < 1) return fail("frame fit: sweeps must be ≥ 1");
  if (pedestal_level < 1) return fail("frame fit: pedestal_level must be ≥ 1");
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

namespace {

// The ghosts' image over the whole frame at level k (capture pixels → k×k blocks).
cv::Mat renderAtLevel(const std::vector<model::GhostParameters>& ghosts, cv::Size capture, int k,
                      int channels) {
  model::ViewTransform view;
  view.scale = 1.0 / k;
  return model::renderGhosts(ghosts, cv::Size(capture.width / k, capture.height / k), channels, {}, view);
}

// Averages of k×k blocks (sizes round down), and the blocks all of whose pixels are valid.
void downsample(const cv::Mat& image, const cv::Mat& valid, int k, cv::Mat* out, cv::Mat* out_valid) {
  const cv::Size size(image.cols / k, image.rows / k);
  const cv::Rect whole(0, 0, size.width * k, size.height * k);
  cv::resize(image(whole), *out, size, 0, 0, cv::INTER_AREA);
  cv::Mat v;
  cv::resize(valid(whole), v, size, 0, 0, cv::INTER_AREA);
  *out_valid = v >= 255;
}

FrameFit fitOneFrame(const FrameStack& stack, int index, const std::vector<GhostCandidate>& candidates,
                     const FrameFitOptions& o, const EdgeFilter& edge) {
  const Frame& frame = stack.frames[index];
  FrameFit fit;
  fit.frame = index;
  fit.angle_deg = frame.angle_deg;
  fit.noise_sigma = estimatePixelNoiseSigma(frame.image, frame.valid);
  for (const auto& c : candidates)
    if (c.present(index)) {
      fit.ghost_ids.push_back(c.id);
      fit.ghosts.push_back(c.seed(index));
    }
  // Largest first: the small ones then fit on what the large ones leave.
  std::vector<size_t> order(fit.ghosts.size());
  std::iota(order.begin(), order.end(), 0);
  auto area = [&](size_t i) {
    const auto& g = fit.ghosts[i];
    return (g.left + g.right) * g.height;
  };
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return area(a) > area(b); });
  cv::Mat target = frame.image;
  for (int sweep = 0; sweep < o.sweeps; ++sweep) {
    FramePyramid pyramid(target, frame.valid, edge, fit.noise_sigma);
    fit.cost = 0;
    for (size_t i : order) {
      std::vector<model::GhostParameters> others;
      for (size_t j = 0; j < fit.ghosts.size(); ++j)
        if (j != i) others.push_back(fit.ghosts[j]);
      GroupCost cost(pyramid, edge, others, std::span(&fit.ghosts[i], 1), o.cost);
      const GroupFitResult r = solveGroup(cost, std::span(&fit.ghosts[i], 1), o.solver);
      fit.ghosts[i] = r.ghosts[0];
      fit.cost += r.final_cost;
      fit.evaluations += r.evaluations;
      fit.iterations += r.iterations;
    }
    if (!o.pedestal) continue;
    // The glow the ghosts leave, fitted on block averages (it is smooth), taken out of the frame
    // for the next pass.
    const int k = o.pedestal_level;
    cv::Mat level, level_valid;
    downsample(frame.image, frame.valid, k, &level, &level_valid);
    const cv::Mat rest = level - renderAtLevel(fit.ghosts, stack.size, k, stack.channels);
    fit.pedestal = fitPedestal(rest, level_valid, stack.size, k, fit.noise_sigma / k, o.pedestal_fit);
    cv::Mat glow = cv::Mat::zeros(frame.image.size(), frame.image.type());
    fit.pedestal.addTo(glow, stack.size);
    // addTo clamps the sum at 0; the pedestal may be negative where it corrects the ghosts.
    cv::Mat signed_glow = cv::Mat::zeros(frame.image.size(), frame.image.type());
    for (int y = 0; y < glow.rows; ++y)
      for (int x = 0; x < glow.cols; ++x)
        for (int c = 0; c < stack.channels; ++c)
          signed_glow.ptr<float>(y)[x * stack.channels + c] = static_cast<float>(
              fit.pedestal.at({x + 0.5, y + 0.5}, stack.size, c));
    target = frame.image - signed_glow;
  }
  for (auto& g : fit.ghosts) g = canonicalShade(g);
  return fit;
}

}  // namespace

std::vector<FrameFit> fitFrames(const FrameStack& stack, const std::vector<int>& frames,
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
    fits[i] = fitOneFrame(stack, frames[i], candidates, o, edge);
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
