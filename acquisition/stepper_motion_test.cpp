#include "acquisition/stepper_motion.h"

#include <gtest/gtest.h>

#include <cmath>

namespace flarekit::acquisition {
namespace {

StepperGeometry geometry() {
  StepperGeometry g;
  g.full_steps_per_rev = 200;
  g.microsteps = 16;
  g.gear_ratio = 3;  // 26.67 microsteps per degree
  return g;
}

TEST(StepperMotion, WholeMicrostepsOnly) {
  const StepperGeometry g = geometry();
  EXPECT_EQ(microstepsForAngle(g, 0.3, "rig"), 8);
  EXPECT_EQ(microstepsForAngle(g, 30, "rig"), 800);
  try {
    microstepsForAngle(g, 0.2, "rig.toml");
    FAIL() << "0.2° is 5.33 microsteps";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("rig.toml"), std::string::npos) << m;
    EXPECT_NE(m.find("not a whole number of microsteps"), std::string::npos) << m;
    EXPECT_NE(m.find("0.1875"), std::string::npos) << m;  // nearest: 5 microsteps
  }
  EXPECT_NEAR(angleForMicrosteps(g, 8), 0.3, 1e-12);
}

TEST(StepperMotion, SoftLimits) {
  StepperGeometry g = geometry();
  g.min_deg = -5;
  g.max_deg = 10;
  EXPECT_NO_THROW(checkSoftLimits(g, 10, "rig"));
  EXPECT_THROW(checkSoftLimits(g, 10.5, "rig"), InputError);
}

TEST(StepperMotion, BacklashApproachFromOneSide) {
  EXPECT_EQ(approachWaypoints(0, 100, +1, 10), (std::vector<long long>{100}));
  EXPECT_EQ(approachWaypoints(100, 50, +1, 10), (std::vector<long long>{40, 50}));
  EXPECT_EQ(approachWaypoints(100, 50, -1, 10), (std::vector<long long>{50}));
  EXPECT_TRUE(approachWaypoints(7, 7, +1, 10).empty());
}

TEST(StepperMotion, TrapezoidTiming) {
  // 1000 steps, cruise 500 steps/s, 1000 steps/s²: 125 steps to reach cruise.
  auto t = stepTimes(1000, 500, 1000);
  ASSERT_EQ(t.size(), 1000u);
  EXPECT_NEAR(t[0], std::sqrt(2.0 / 1000), 1e-12);
  for (size_t i = 1; i < t.size(); ++i) ASSERT_GT(t[i], t[i - 1]);
  // Total time: 2 × 0.5 s ramps + 750 steps at 500/s = 2.5 s.
  EXPECT_NEAR(t.back(), 2.5, 1e-9);
  // Cruise intervals are 1/500 s; symmetric ramps.
  EXPECT_NEAR(t[500] - t[499], 1.0 / 500, 1e-9);
  EXPECT_NEAR(t[0] - 0.0, t[999] - t[998], 1e-9);  // starts and stops at rest
  // Short move: a triangle (never reaches cruise speed).
  auto s = stepTimes(10, 500, 1000);
  EXPECT_NEAR(s.back(), 2 * std::sqrt(5.0 / 1000 * 2), 1e-9);
}

}  // namespace
}  // namespace flarekit::acquisition
