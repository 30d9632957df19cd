// The sweep image, its border traces and the ghosts paired from them, on a pan capture of known
// ghosts.
#include "fit/sweep.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "fit/ghost_candidates.h"
#include "fit/testing.h"

namespace flarekit::fit {
namespace {

using testing::anglesFrom;
using testing::PanScene;

TEST(SweepOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(SweepOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(CandidateOptions{}.IsValid(&error)) << error;
}

TEST(Sweep, EveryBorderIsATraceAtItsPlace) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  ASSERT_EQ(sweep.rows(), static_cast<int>(stack.frames.size()));
  const std::vector<BorderTrace> traces = findTraces(sweep);
  // Each ghost border inside the frame (away from the light's core) has a trace point within
  // a pixel, on the right side, in nine frames of ten.
  for (size_t g = 0; g < scene.ghosts.size(); ++g)
    for (BorderSide side : {BorderSide::kLeft, BorderSide::kRight}) {
      int inside = 0, found = 0;
      for (int row = 0; row < sweep.rows(); ++row) {
        const auto p = scene.ghostAt(g, sweep.angles_deg[row]);
        const double x = side == BorderSide::kLeft ? p.center_x - p.left : p.center_x + p.right;
        if (x < 8 || x > stack.size.width - 8 || std::abs(x - scene.lightX(sweep.angles_deg[row])) < 10) continue;
        ++inside;
        for (const auto& t : traces)
          if (const BorderPoint* q = t.side == side ? t.at(row) : nullptr; q && std::abs(q->x_px - x) < 1) {
            ++found;
            break;
          }
      }
      EXPECT_GE(found, 0.9 * inside) << "ghost " << g << (side == BorderSide::kLeft ? " left" : " right");
    }
}

// The light's profile is measured over the frames that show it; with the light in fewer frames
// than that needs, it masks its core alone, and the ghosts about it stay in view.
TEST(Sweep, ALightInTooFewFramesToMeasureMasksItsCoreAlone) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 0.6, 0.2));  // four frames
  SweepOptions options;
  ASSERT_LT(static_cast<int>(stack.frames.size()), options.light_min_frames);
  const SweepImage sweep = buildSweep(stack, measureHorizon(stack), options);
  EXPECT_LT(sweep.light_zone_left_px, 2 * scene.light_radius_px);
  EXPECT_LT(sweep.light_zone_right_px, 2 * scene.light_radius_px);
  // Every ghost border (away from the light's core) lies where the sweep can trace it.
  for (int row = 0; row < sweep.rows(); ++row)
    for (size_t g = 0; g < scene.ghosts.size(); ++g) {
      const auto p = scene.ghostAt(g, sweep.angles_deg[row]);
      for (double x : {p.center_x - p.left, p.center_x + p.right}) {
        if (std::abs(x - scene.lightX(sweep.angles_deg[row])) > 2 * scene.light_radius_px) {
          EXPECT_TRUE(sweep.valid.at<uchar>(row, static_cast<int>(x))) << "row " << row << ", x " << x;
        }
      }
    }
}

// A merged HDR frame may hold the light without clipping it: its core is still the light's zone,
// where it draws no border of its own (its fall-off would otherwise pass for a ghost's edge).
TEST(Sweep, AnUnclippedLightsCoreIsItsZoneAndDrawsNoBorder) {
  PanScene scene;
  scene.light_clipped = false;
  scene.light_radius_px = 4;  // σ of the light's Gaussian; its core (above half its peak) 4.7 px
  scene.light_peak = 20;
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const double core = scene.light_radius_px * std::sqrt(2 * std::log(2.0));
  EXPECT_GE(sweep.light_zone_left_px, core - 1);
  EXPECT_GE(sweep.light_zone_right_px, core - 1);
  int in_core = 0;
  for (const auto& t : findTraces(sweep))
    for (const auto& p : t.points)
      if (std::abs(p.x_px - scene.lightX(sweep.angles_deg[p.row])) < core) ++in_core;
  EXPECT_EQ(in_core, 0);
}

TEST(GhostCandidates, PairTheBordersOfEachGhostAndSeedIt) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const std::vector<BorderTrace> traces = findTraces(sweep);
  CandidateSummary summary;
  const std::vector<GhostCandidate> candidates = findGhostCandidates(stack, sweep, traces, {}, &summary);
  // Each true ghost is one candidate, seeded at its borders and height in every frame it is in.
  for (size_t g = 0; g < scene.ghosts.size(); ++g) {
    int matched_frames = 0, frames = 0;
    for (int row = 0; row < sweep.rows(); ++row) {
      const auto p = scene.ghostAt(g, sweep.angles_deg[row]);
      if (p.center_x - p.left < 0 || p.center_x + p.right > stack.size.width) continue;
      ++frames;
      for (const auto& c : candidates) {
        if (!c.present(row)) continue;
        const auto& s = c.seed(row);
        if (std::abs(s.center_x - s.left - (p.center_x - p.left)) < 1.5 &&
            std::abs(s.center_x + s.right - (p.center_x + p.right)) < 1.5 &&
            std::abs(s.height - p.height) < 0.15 * p.height) {
          ++matched_frames;
          break;
        }
      }
    }
    EXPECT_GE(matched_frames, 0.9 * frames) << "ghost " << g << " of " << frames << " frames";
  }
  EXPECT_GE(summary.pairs, 2);
}

// A wide flat ghost whose left border never enters the frame: its right border's trace and the
// optical zero (from the other ghosts' pairs) give its middle and half-width, so its hidden border
// is seeded where it is, not from the curvature of the seen one (which is no circle's).
TEST(GhostCandidates, AGhostWithOneBorderInTheFrameGetsTheOtherFromItsBorderModel) {
  PanScene scene;
  scene.ghosts = {{-0.8, 45, 0.01, 0.015}, {0.3, 150, 0.004, 0.004, 0.5}};
  const FrameStack stack = scene.stack(anglesFrom(3, 8, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const std::vector<GhostCandidate> candidates = findGhostCandidates(stack, sweep, findTraces(sweep));
  int matched_frames = 0;
  for (int row = 0; row < sweep.rows(); ++row) {
    const auto p = scene.ghostAt(1, sweep.angles_deg[row]);
    ASSERT_LT(p.center_x - p.left, 0);
    for (const auto& c : candidates) {
      if (!c.present(row) || c.leftSeen(row) || !c.rightSeen(row)) continue;
      const auto& s = c.seed(row);
      if (std::abs(s.center_x + s.right - (p.center_x + p.right)) < 1.5 &&
          std::abs(s.center_x - s.left - (p.center_x - p.left)) < 0.05 * p.left) {
        ++matched_frames;
        break;
      }
    }
  }
  EXPECT_GE(matched_frames, 0.9 * sweep.rows());
}

// A ghost that stays beside the light, one border hidden in the light's core: the light's own
// profile, measured over the frames, holds the ghost's inside too. Its seen border is still one
// candidate's, seeded there.
TEST(GhostCandidates, AGhostBesideTheLightWithOneBorderInItsCoreIsFound) {
  PanScene scene;
  scene.light_radius_px = 12;
  scene.ghosts = {{1.4, 30, 0.01, 0.01}};
  const FrameStack stack = scene.stack(anglesFrom(3, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const std::vector<GhostCandidate> candidates = findGhostCandidates(stack, sweep, findTraces(sweep));
  int frames = 0, seeded = 0;
  for (int row = 0; row < sweep.rows(); ++row) {
    const auto p = scene.ghostAt(0, sweep.angles_deg[row]);
    ASSERT_LT(std::abs(p.center_x + p.right - scene.lightX(sweep.angles_deg[row])), scene.light_radius_px);
    if (p.center_x - p.left < 8) continue;
    ++frames;
    for (const auto& c : candidates)
      if (c.present(row) && c.leftSeen(row) &&
          std::abs(c.seed(row).center_x - c.seed(row).left - (p.center_x - p.left)) < 1.5) {
        ++seeded;
        break;
      }
  }
  EXPECT_GE(seeded, 0.9 * frames) << "of " << frames << " frames";
}

// A ghost wider than the frame, whose one border enters it partway through the sweep: before, it
// was in the frame all along, its border beyond the frame's edge or in the margin where S has no
// edge response. The candidate of its border's trace is present in those frames too.
TEST(GhostCandidates, AGhostWhoseBorderIsNotYetInTheFrameIsPresentAlready) {
  PanScene scene;
  scene.ghosts = {{1.6, 30, 0.02, 0.01}, {-0.8, 40, 0.01, 0.015}, {0.6, 190, 0.004, 0.004, 0.6}};
  const FrameStack stack = scene.stack(anglesFrom(2, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const std::vector<GhostCandidate> candidates = findGhostCandidates(stack, sweep, findTraces(sweep));
  const auto last = scene.ghostAt(2, sweep.angles_deg.back());
  int frames = 0, present = 0;
  for (int row = 0; row < sweep.rows(); ++row) {
    const auto p = scene.ghostAt(2, sweep.angles_deg[row]);
    ASSERT_LT(p.center_x - p.left, 0);
    ++frames;
    // The candidate of the trace of its right border, present in the frame.
    for (const auto& c : candidates)
      if (c.present(row) && c.right_trace >= 0 && c.right_seen.back() &&
          std::abs(c.seed(c.last_row).center_x + c.seed(c.last_row).right - (last.center_x + last.right)) < 1.5) {
        ++present;
        break;
      }
  }
  EXPECT_GE(present, 0.9 * frames) << "of " << frames << " frames";
}

// A ghost goes on while its borders are hidden, but not once it has left the frame whole: no
// candidate is present where its seed lies wholly beyond the frame.
TEST(GhostCandidates, AGhostThatHasLeftTheFrameIsNoLongerPresent) {
  PanScene scene;
  const FrameStack stack = scene.stack(anglesFrom(0, 9, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  const std::vector<GhostCandidate> candidates =
      findGhostCandidates(stack, sweep, findTraces(sweep));
  ASSERT_LT(scene.ghostAt(0, 9).center_x + scene.ghostAt(0, 9).right, 0);  // the first has left
  for (const auto& c : candidates)
    for (int row = c.first_row; row <= c.last_row; ++row) {
      const auto& p = c.seed(row);
      const std::string where = "candidate " + std::to_string(c.id) + " at " +
                                std::to_string(sweep.angles_deg[row]) + "°";
      EXPECT_GE(p.center_x + p.right, 0) << where;
      EXPECT_LE(p.center_x - p.left, stack.size.width) << where;
    }
}

// A ghost found at its peak goes on while its peak is hidden beyond the frame, and ends, as every
// ghost, where it has wholly left the frame.
TEST(GhostCandidates, AGhostFoundAtItsPeakThatHasLeftTheFrameIsNoLongerPresent) {
  PanScene scene;
  scene.ghosts = {{-1.2, 40, 1e-4, 0.03, 1, 1}};
  const FrameStack stack = scene.stack(anglesFrom(0, 12, 0.2));
  const SweepImage sweep = buildSweep(stack, measureHorizon(stack));
  CandidateSummary summary;
  const std::vector<GhostCandidate> candidates =
      findGhostCandidates(stack, sweep, findTraces(sweep), {}, &summary);
  ASSERT_EQ(summary.peaks, 1);
  ASSERT_GT(scene.ghostAt(0, 12).center_x - scene.ghostAt(0, 12).right, stack.size.width);
  for (const auto& c : candidates)
    for (int row = c.first_row; row <= c.last_row; ++row) {
      const auto& p = c.seed(row);
      EXPECT_LE(p.center_x - p.left, stack.size.width)
          << "candidate " << c.id << " at " << sweep.angles_deg[row] << "°";
    }
}

// A ghost whose light gathers to a point, its outline at the noise (a near-focused ghost's
// glow): no border to pair, but one candidate centred on its peak, in the frames that show it.
TEST(GhostCandidates, AGhostWhoseLightGathersToAPointIsFoundAtItsPeak) {
  PanScene scene;
  scene.ghosts = {{1.6, 30, 0.02, 0.01}, {-0.8, 40, 1e-4, 0.03, 1, 1}};
  const FrameStack stack = scene.stack(anglesFrom(0, 6, 0.2));
  const Horizon h = measureHorizon(stack);
  const SweepImage sweep = buildSweep(stack, h);
  CandidateSummary summary;
  const std::vector<GhostCandidate> candidates = findGhostCandidates(stack, sweep, findTraces(sweep), {}, &summary);
  EXPECT_EQ(summary.peaks, 1);
  int frames = 0, centred = 0;
  for (int row = 0; row < sweep.rows(); ++row) {
    const auto p = scene.ghostAt(1, sweep.angles_deg[row]);
    if (p.center_x < 8 || p.center_x > stack.size.width - 8 ||
        std::abs(p.center_x - scene.lightX(sweep.angles_deg[row])) < 10)
      continue;
    ++frames;
    for (const auto& c : candidates)
      if (c.peak_trace >= 0 && c.present(row) && std::abs(c.seed(row).center_x - p.center_x) < 1) {
        ++centred;
        break;
      }
  }
  EXPECT_GE(centred, 0.9 * frames) << "of " << frames << " frames";
}

}  // namespace
}  // namespace flarekit::fit
