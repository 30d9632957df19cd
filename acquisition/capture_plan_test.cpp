// A capture's plan: its checks and its angles.
#include "acquisition/capture_plan.h"

#include <gtest/gtest.h>

namespace flarekit::acquisition {
namespace {

TEST(CapturePlan, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(CapturePlan{}.IsValid(&error)) << error;
  EXPECT_EQ(CapturePlan{}.anglesDeg().size(), 41u);  // 0..20° in 0.5° steps
  CapturePlan p;
  p.step_deg = 0.3;
  EXPECT_FALSE(p.IsValid(&error));
  EXPECT_NE(error.find("whole number"), std::string::npos);
  p = CapturePlan{};
  p.exposures_s = {1, 1};
  EXPECT_FALSE(p.IsValid(&error));
  CapturePlan down;
  down.from_deg = 2;
  down.to_deg = 0;
  EXPECT_EQ(down.anglesDeg(), (std::vector<double>{2, 1.5, 1, 0.5, 0}));
}

TEST(CapturePlan, LightExposuresAndSettleAreChecked) {
  std::string error;
  CapturePlan p;
  p.light_exposures_s = {1e-4, 1e-4};
  EXPECT_FALSE(p.IsValid(&error));
  p.light_exposures_s = {};
  p.light_nd_factor = 10;
  EXPECT_FALSE(p.IsValid(&error));
  EXPECT_NE(error.find("ND"), std::string::npos);
  p.light_nd_factor = 1;
  p.settle_s = -1;
  EXPECT_FALSE(p.IsValid(&error));
  p.settle_s = 0.5;
  p.light_exposures_s = {3e-6, 1e-4};
  EXPECT_TRUE(p.IsValid(&error)) << error;
}

}  // namespace
}  // namespace flarekit::acquisition
