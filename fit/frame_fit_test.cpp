// The second pass's seeds: the first model's curves, with the borders the sweep saw kept.
#include "fit/frame_fit.h"

#include <gtest/gtest.h>

#include "fit/testing.h"

namespace flarekit::fit {
namespace {

// A model ghost whose parameters are `g` at every angle of [0°, 1°].
model::GhostTrack constantTrack(int id, const model::GhostParameters& g) {
  model::GhostTrack t;
  t.id = id;
  t.angle_min_deg = 0;
  t.angle_max_deg = 1;
  for (double v : model::toParameterVector(g)) t.parameters.push_back({{v}});
  return t;
}

TEST(SeedsFromModel, KeepTheBordersTheSweepSawAndTakeTheRestFromTheCurves) {
  FrameStack stack;
  stack.channels = 1;
  for (double angle : {0.0, 0.5, 1.0, 1.5}) {
    Frame f;
    f.angle_deg = angle;
    stack.frames.push_back(f);
  }
  // Candidate 0 saw its left border at 62 px in every frame, never its right one; candidate 1 has
  // no model ghost.
  GhostCandidate seen_left;
  seen_left.id = 0;
  seen_left.first_row = 0;
  seen_left.last_row = 3;
  seen_left.seeds.assign(4, testing::ghost(90, 50, 28, 60, 30, 0.01, 0.02));
  seen_left.left_seen.assign(4, true);
  seen_left.right_seen.assign(4, false);
  GhostCandidate unmodelled = seen_left;
  unmodelled.id = 1;
  model::FlareModel m;
  const model::GhostParameters curves = testing::ghost(100, 50, 30, 40, 35, 0.03, 0.04);
  m.ghosts.push_back(constantTrack(0, curves));

  const std::vector<GhostCandidate> out = seedsFromModel({seen_left, unmodelled}, m, stack);
  ASSERT_EQ(out.size(), 2u);
  for (int row = 0; row < 3; ++row) {
    const model::GhostParameters& s = out[0].seed(row);
    EXPECT_NEAR(s.center_x - s.left, 62, 1e-9) << "row " << row;  // the seen border
    EXPECT_NEAR(s.center_x, 100, 1e-9);                          // the rest from the curves
    EXPECT_NEAR(s.center_x + s.right, 140, 1e-9);
    EXPECT_NEAR(s.height, 35, 1e-9);
    EXPECT_NEAR(s.inside[0], 0.04, 1e-12);
  }
  // Beyond the model ghost's range (1.5°) and without a model ghost, the seeds stay.
  EXPECT_DOUBLE_EQ(out[0].seed(3).right, 60);
  for (int row = 0; row < 4; ++row) EXPECT_DOUBLE_EQ(out[1].seed(row).center_x, 90);
}

}  // namespace
}  // namespace flarekit::fit
