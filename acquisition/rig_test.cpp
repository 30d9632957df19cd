// Rig files: the shipped ones load; bad ones give one line naming the file, the key and the
// problem.
#include "acquisition/rig.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/testing.h"

namespace flarekit::acquisition {
namespace {

const std::filesystem::path kRigs = std::filesystem::path(FLAREKIT_SOURCE_DIR) / "rigs";

TEST(Rig, ShippedRigsLoad) {
  for (const char* name : {"sim-heliar", "sim-nikon", "pi-stepper-eos", "tic-eos"}) {
    SCOPED_TRACE(name);
    Rig rig = loadRig(kRigs / (std::string(name) + ".toml"));
    EXPECT_EQ(rig.name, name);
  }
  Rig pi = loadRig(kRigs / "pi-stepper-eos.toml");
  EXPECT_EQ(pi.head_driver, HeadDriver::kGpioStepper);
  EXPECT_EQ(pi.camera_driver, CameraDriver::kGphoto2);
  EXPECT_EQ(pi.gpio.step_line, 17);
  EXPECT_EQ(pi.gpio.geometry.microsteps, 16);
  EXPECT_DOUBLE_EQ(pi.gpio.geometry.gear_ratio, 3.0);
  EXPECT_DOUBLE_EQ(pi.lens.focal_length_mm, 50.0);
  Rig tic = loadRig(kRigs / "tic-eos.toml");
  EXPECT_EQ(tic.head_driver, HeadDriver::kTic);
  Rig sim = loadRig(kRigs / "sim-heliar.toml");
  EXPECT_TRUE(sim.simulated());
  EXPECT_EQ(sim.simulation.width_px, 320);
  EXPECT_EQ(sim.capture.exposures_s, (std::vector<double>{0.25, 1, 4}));
  EXPECT_GT(sim.light_illuminance_lux, 0);  // the demo's predictions are calibrated by it
}

TEST(Rig, FindRigByName) {
  EXPECT_TRUE(std::filesystem::exists(findRig("sim-heliar")));
  EXPECT_THROW(findRig("no-such-rig"), InputError);
}

// Loads `text` as a rig file and returns the error message ("" when it loads).
std::string errorOf(const std::string& text) {
  testing::TempDir dir;
  std::ofstream(dir / "bad.toml") << text;
  try {
    loadRig(dir / "bad.toml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

const std::string kGpioRig = R"(
name = "t"
[head]
driver = "gpio_stepper"
chip = "gpiochip0"
step_line = 1
dir_line = 2
[camera]
driver = "gphoto2"
)";

TEST(Rig, ErrorsNameFileKeyAndProblem) {
  std::string e = errorOf(kGpioRig + "");
  EXPECT_EQ(e, "");
  e = errorOf(std::string(kGpioRig).replace(kGpioRig.find("dir_line = 2"), 12, "dir_line = 1"));
  EXPECT_NE(e.find("bad.toml"), std::string::npos) << e;
  EXPECT_NE(e.find("head.dir_line"), std::string::npos) << e;
  e = errorOf(kGpioRig + "[sensor]\nbit_depth = 20\n");
  EXPECT_NE(e.find("sensor.bit_depth"), std::string::npos) << e;
  e = errorOf(std::string(kGpioRig).insert(kGpioRig.find("[camera]"), "microsteps = 3\n"));
  EXPECT_NE(e.find("head.microsteps"), std::string::npos) << e;
  EXPECT_NE(e.find("power of two"), std::string::npos) << e;
  e = errorOf(std::string(kGpioRig).insert(kGpioRig.find("[camera]"), "stepline = 3\n"));
  EXPECT_NE(e.find("stepline"), std::string::npos) << e;
  e = errorOf("name = \"x\"\n[head]\ndriver = \"warp\"\n[camera]\ndriver = \"simulated\"\n");
  EXPECT_NE(e.find("head.driver"), std::string::npos) << e;
  e = errorOf("name = \"x\"\n[head]\ndriver = \"simulated\"\n[camera]\ndriver = \"simulated\"\n");
  EXPECT_NE(e.find("simulation"), std::string::npos) << e;
  e = errorOf("name = \"x\"\n[head\n");
  EXPECT_NE(e.find("bad.toml"), std::string::npos) << e;
  e = errorOf(kGpioRig + "[faults]\ncamera_transient_probability = 0.1\n");
  EXPECT_NE(e.find("faults"), std::string::npos) << e;
  e = errorOf("light_illuminance_lux = -5\n" + kGpioRig);
  EXPECT_NE(e.find("light_illuminance_lux"), std::string::npos) << e;
  e = errorOf(kGpioRig + "[lens]\nfocal_length_mm = -50\n");
  EXPECT_NE(e.find("lens.focal_length_mm"), std::string::npos) << e;
  e = errorOf("name = \"x\"\n[head]\ndriver = \"simulated\"\n[camera]\ndriver = \"simulated\"\n"
              "[simulation]\nlens = \"l.json\"\n[lens]\nfocal_length_mm = 50\n");
  EXPECT_NE(e.find("[simulation] lens"), std::string::npos) << e;
  // Every message is one line.
  EXPECT_EQ(e.find('\n'), std::string::npos);
}

}  // namespace
}  // namespace flarekit::acquisition
