// Tests that need the real devices of a rig (CTest label "hardware"). On a machine without them
// every test is skipped with GTEST_SKIP, never faked into passing. Set FLAREKIT_HARDWARE_RIG to a
// rig file to choose the devices (default rigs/pi-stepper-eos.toml and rigs/tic-eos.toml).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "acquisition/gphoto2_camera.h"
#include "acquisition/gpio_stepper_head.h"
#include "acquisition/rig.h"
#include "acquisition/tic_head.h"

namespace flarekit::acquisition {
namespace {

Rig hardwareRig(const char* fallback) {
  const char* env = std::getenv("FLAREKIT_HARDWARE_RIG");
  return loadRig(env ? std::filesystem::path(env)
                     : std::filesystem::path(FLAREKIT_SOURCE_DIR) / "rigs" / fallback);
}

TEST(Hardware, Gphoto2CameraTakesALinearRawFrame) {
  Rig rig = hardwareRig("pi-stepper-eos.toml");
  std::vector<std::string> lines;
  if (!probeGphoto2(rig.gphoto2, &lines)) GTEST_SKIP() << "no camera: " << lines.back();
  Gphoto2Camera camera(rig.gphoto2);
  camera.setIso(100);
  camera.setExposure(1.0 / 60);
  RawFrame f = camera.capture();
  EXPECT_EQ(f.data.type(), CV_16UC1);
  EXPECT_GT(f.white_level, f.black_level);
  EXPECT_NEAR(f.exposure_s, 1.0 / 60, 0.3 / 60);  // the camera's nearest speed, from EXIF
}

TEST(Hardware, TicControllerReportsItsPosition) {
  Rig rig = hardwareRig("tic-eos.toml");
  std::vector<std::string> lines;
  if (!probeTic(rig.tic, &lines)) GTEST_SKIP() << "no Tic: " << lines.back();
  TicHead head(rig.tic, rig.file.string());
  EXPECT_NO_THROW(head.readPosition());
}

TEST(Hardware, GpioLinesOfTheRigAreFree) {
  Rig rig = hardwareRig("pi-stepper-eos.toml");
  std::vector<std::string> lines;
  const bool ok = probeGpio(rig.gpio, &lines);
  if (lines.empty() || lines[0].rfind("MISSING", 0) == 0) GTEST_SKIP() << "no GPIO chip";
  EXPECT_TRUE(ok) << lines.back();
}

}  // namespace
}  // namespace flarekit::acquisition
