#pragma once
// What fit/evaluation.cpp and fit/ceiling.cpp both measure a frame's ground truth with: a
// luminance blob's centroid, peak and radius, PSNR over a mask, a frame's truth layers, and
// measuring every frame of a stack in parallel. Not part of the library's interface.

#include <cmath>
#include <exception>
#include <optional>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "common/progress.h"
#include "fit/evaluation.h"
#include "fit/frames.h"

namespace flarekit::fit::detail {

struct Blob {
  int id = 0;
  cv::Point2d centroid;
  double peak = 0;
  double radius = 0;
  double sigma_x = 0, sigma_y = 0;  // intensity-weighted standard deviations, pixels
  bool present = false;
};

// Intensity-weighted centroid, peak and radius of a luminance image placed at `offset` in the
// frame (fit/evaluation.cpp says why the radius is the moments' and not an area's).
Blob describe(const cv::Mat& lum, cv::Point offset);

// The normal σ of `values` about their median, from their MAD (NaN when empty); reorders them.
double robustSigma(std::vector<float>& values);

// PSNR of `a` against `reference` over `mask`, the peak being the reference's maximum there.
double psnr(const cv::Mat& a, const cv::Mat& reference, const cv::Mat& mask);

// A frame's ground truth as the measures read it.
struct FrameTruth {
  double noise_sigma = 0;          // noiseFloor of frame − noise-free luminance
  double pixel_noise_sigma = 0;    // the same per pixel (block 1)
  std::vector<GhostTruth> ghosts;  // each ghost's own layer
  cv::Mat flare;                   // the noise-free flare: the sum of the ghosts' luminance
  cv::Mat light;                   // the light's own image: noise-free luminance − flare
};

FrameTruth readFrameTruth(const Frame& f, const cv::Mat& frame_lum, int noise_block_px);

// A figure for JSON: null where it is not a finite number.
inline nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

// `measure(i)` of every frame i of the stack (nullopt: the frame is left out), in frame order.
// Frames are independent, and each decodes its truth layers (tens of MB a frame): measured in
// parallel, each into its own slot. A frame that fails keeps its exception; the first in frame
// order is rethrown, as a serial loop would have.
template <class Result, class Measure>
std::vector<std::optional<Result>> measureFrames(const FrameStack& stack, const char* what, const Measure& measure) {
  const size_t n = stack.frames.size();
  std::vector<std::optional<Result>> results(n);
  std::vector<std::exception_ptr> failed(n);
  Progress progress(what, static_cast<long long>(n));
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    // Isolated: a thread waiting inside this frame's renders must not start another frame
    // (each holds its truth layers).
    tbb::this_task_arena::isolate([&] {
      try {
        results[i] = measure(i);
      } catch (...) {
        failed[i] = std::current_exception();
      }
    });
    progress.advance();
  });
  progress.finish();
  for (const auto& e : failed)
    if (e) std::rethrow_exception(e);
  return results;
}


}  // namespace flarekit::fit::detail
