// The pure parts of the gphoto2 backend (the rest needs a camera: hardware_test.cpp).
#include "acquisition/gphoto2_camera.h"

#include <gtest/gtest.h>

namespace flarekit::acquisition {
namespace {

TEST(Gphoto2, ParsesShutterSpeeds) {
  EXPECT_DOUBLE_EQ(parseShutterSpeed("1/250"), 1.0 / 250);
  EXPECT_DOUBLE_EQ(parseShutterSpeed("4"), 4);
  EXPECT_DOUBLE_EQ(parseShutterSpeed("0.3"), 0.3);
  EXPECT_DOUBLE_EQ(parseShutterSpeed("30\""), 30);
  EXPECT_DOUBLE_EQ(parseShutterSpeed("bulb"), 0);
}

TEST(Gphoto2, PicksTheNearestShutterSpeed) {
  const std::vector<std::string> choices = {"bulb", "30", "4", "1", "1/4", "1/5", "1/250"};
  EXPECT_EQ(nearestShutterSpeed(choices, 0.25), "1/4");
  EXPECT_EQ(nearestShutterSpeed(choices, 1.1), "1");
  EXPECT_EQ(nearestShutterSpeed(choices, 3.0), "4");
  EXPECT_EQ(nearestShutterSpeed({}, 1.0), "");
}

}  // namespace
}  // namespace flarekit::acquisition
