// Rig files: the shipped ones load; bad ones give one line naming the file, the key and the
// problem.
#include "acquisition/rig.h"
#include "acquisition/capture.h"

#include <gtest/gtest.h>

#include <fstream>

#include "common/exr.h"
#include "common/image.h"
#include "common/testing.h"
#ifdef FLAREKIT_ACQUISITION_WITH_RENDER
#include "acquisition/render_scene.h"
#endif

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

// A camera on the network is named by its PTP/IP address, which libgphoto2 takes numeric.
TEST(Rig, PtpIpCameraPortsAreChecked) {
  auto withPort = [](const std::string& port) {
    return kGpioRig + "port = \"" + port + "\"\ncapture_timeout_s = 10\n";
  };
  EXPECT_EQ(errorOf(withPort("ptpip:192.168.1.20")), "");
  EXPECT_EQ(errorOf(withPort("ptpip:127.0.0.1:15740")), "");
  EXPECT_EQ(errorOf(withPort("usb:001,004")), "");
  for (const std::string bad : {"ptpip:camera.local", "ptpip:10.0.0.1:0", "ptpip:10.0.0.1:x"}) {
    const std::string e = errorOf(withPort(bad));
    EXPECT_NE(e.find("bad.toml: camera.port: must be \"ptpip:IPV4\" or \"ptpip:IPV4:PORT\""),
              std::string::npos) << e;
  }
  EXPECT_NE(errorOf(kGpioRig + "capture_timeout_s = 0\n").find("camera.capture_timeout_s"),
            std::string::npos);
}

// A simulated rig, small and quick: 160×107 pixels, the Heliar's three brightest ghosts.
std::string simulatedRig(const std::string& simulation_keys) {
  const std::string lens =
      (std::filesystem::path(FLAREKIT_SOURCE_DIR) / "lenses/heliar_tronnier.json").string();
  const std::string head = R"(
name = "t"
[head]
driver = "simulated"
[camera]
driver = "simulated"
[simulation]
width_px = 160
height_px = 107
grid_size = 24
max_ghosts = 3
)";
  return head + "lens = \"" + lens + "\"\n" + simulation_keys;
}

Rig loadRigText(const testing::TempDir& dir, const std::string& name, const std::string& text) {
  std::ofstream(dir / name) << text;
  return loadRig(dir / name);
}

TEST(Rig, SimulatedImperfectionsDefaultToAnIdealRig) {
  testing::TempDir dir;
  const Rig ideal = loadRigText(dir, "ideal.toml", simulatedRig(""));
  EXPECT_EQ(ideal.simulation.optical_axis_offset_px, cv::Point2d(0, 0));
  EXPECT_EQ(ideal.simulation.angle_zero_offset_deg, 0.0);
  const Rig shipped = loadRig(kRigs / "sim-heliar.toml");
  EXPECT_EQ(shipped.simulation.optical_axis_offset_px, cv::Point2d(0, 0));
  EXPECT_EQ(shipped.simulation.angle_zero_offset_deg, 0.0);
  const Rig off = loadRigText(
      dir, "off.toml",
      simulatedRig("optical_axis_offset_px = [7.25, -3.5]\nangle_zero_offset_deg = -1.5\n"));
  EXPECT_EQ(off.simulation.optical_axis_offset_px, cv::Point2d(7.25, -3.5));
  EXPECT_EQ(off.simulation.angle_zero_offset_deg, -1.5);
  // At the limits: a quarter of the image, 5°.
  const Rig limits = loadRigText(
      dir, "limits.toml",
      simulatedRig("optical_axis_offset_px = [-40, 26.75]\nangle_zero_offset_deg = 5\n"));
  EXPECT_EQ(limits.simulation.optical_axis_offset_px, cv::Point2d(-40, 26.75));
}

TEST(Rig, BadSimulatedImperfectionsNameTheKey) {
  const struct {
    const char* keys;
    const char* key;  // the key path the message names
  } cases[] = {
      {"optical_axis_offset_px = [nan, 0]\n", "simulation.optical_axis_offset_px[0]"},
      {"optical_axis_offset_px = [0, inf]\n", "simulation.optical_axis_offset_px[1]"},
      {"optical_axis_offset_px = [40.5, 0]\n", "simulation.optical_axis_offset_px"},  // > 160/4
      {"optical_axis_offset_px = [0, -27]\n", "simulation.optical_axis_offset_px"},   // > 107/4
      {"optical_axis_offset_px = [1, 2, 3]\n", "simulation.optical_axis_offset_px"},
      {"optical_axis_offset_px = 3\n", "simulation.optical_axis_offset_px"},
      {"angle_zero_offset_deg = 5.5\n", "simulation.angle_zero_offset_deg"},
      {"angle_zero_offset_deg = -inf\n", "simulation.angle_zero_offset_deg"},
      {"angle_zero_offset_deg = nan\n", "simulation.angle_zero_offset_deg"},
      {"angle_zero_offset_deg = \"1\"\n", "simulation.angle_zero_offset_deg"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.keys);
    const std::string e = errorOf(simulatedRig(c.keys));
    EXPECT_NE(e.find("bad.toml"), std::string::npos) << e;
    EXPECT_NE(e.find(std::string(c.key) + ":"), std::string::npos) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

// The capture-trust keys: a settle pause on every head, light exposures (one time or a list), a
// declared ND filter, and a simulated light that drifts.
TEST(Rig, SettleLightExposuresAndDrift) {
  testing::TempDir dir;
  const Rig plain = loadRigText(dir, "plain.toml", simulatedRig(""));
  EXPECT_EQ(plain.settle.settle_s, 0.0);
  EXPECT_TRUE(plain.capture.light_exposures_s.empty());
  EXPECT_EQ(plain.capture.light_nd_factor, 1.0);
  EXPECT_EQ(plain.simulation.light_drift_pct, 0.0);
  std::string text = simulatedRig("light_drift_pct = 2\n");
  text.replace(text.find("[head]\n"), 7, "[head]\nsettle_s = 0.25\n");
  text += "[capture]\nlight_exposure_s = [3e-6, 1e-4]\nlight_nd_factor = 100\n";
  const Rig rig = loadRigText(dir, "rig.toml", text);
  EXPECT_EQ(rig.settle.settle_s, 0.25);
  EXPECT_EQ(rig.capture.light_exposures_s, (std::vector<double>{3e-6, 1e-4}));
  EXPECT_EQ(rig.capture.light_nd_factor, 100.0);
  EXPECT_EQ(rig.simulation.light_drift_pct, 2.0);
  const CapturePlan plan = CapturePlan::FromRig(rig);
  EXPECT_EQ(plan.settle_s, 0.25);
  EXPECT_EQ(plan.light_exposures_s, rig.capture.light_exposures_s);
  EXPECT_EQ(plan.light_nd_factor, 100.0);
  const Rig one = loadRigText(dir, "one.toml", simulatedRig("") + "[capture]\nlight_exposure_s = 5e-6\n");
  EXPECT_EQ(one.capture.light_exposures_s, (std::vector<double>{5e-6}));
  const Rig none = loadRigText(dir, "none.toml", simulatedRig("") + "[capture]\nlight_exposure_s = 0\n");
  EXPECT_TRUE(none.capture.light_exposures_s.empty());
  // Real heads take settle_s too (the shipped ones pause).
  EXPECT_GT(loadRig(kRigs / "pi-stepper-eos.toml").settle.settle_s, 0.0);
  EXPECT_GT(loadRig(kRigs / "tic-eos.toml").settle.settle_s, 0.0);
  EXPECT_EQ(errorOf(std::string(kGpioRig).insert(kGpioRig.find("[camera]"), "settle_s = 0.5\n")), "");
}

TEST(Rig, BadTrustKeysNameTheKey) {
  const struct {
    std::string text;
    const char* key;
  } cases[] = {
      {std::string(kGpioRig).insert(kGpioRig.find("[camera]"), "settle_s = -1\n"), "head.settle_s"},
      {std::string(kGpioRig).insert(kGpioRig.find("[camera]"), "settle_s = 61\n"), "head.settle_s"},
      {kGpioRig + "[capture]\nlight_exposure_s = -1\n", "capture.light_exposure_s"},
      {kGpioRig + "[capture]\nlight_exposure_s = [1e-4, 1e-4]\n", "capture.light_exposure_s"},
      {kGpioRig + "[capture]\nlight_exposure_s = [0, 1e-4]\n", "capture.light_exposure_s"},
      {kGpioRig + "[capture]\nlight_nd_factor = 100\n", "capture.light_nd_factor"},
      {kGpioRig + "[capture]\nlight_exposure_s = 1e-4\nlight_nd_factor = 0.5\n", "capture.light_nd_factor"},
      {simulatedRig("light_drift_pct = 60\n"), "simulation.light_drift_pct"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.text);
    const std::string e = errorOf(c.text);
    EXPECT_NE(e.find("bad.toml"), std::string::npos) << e;
    EXPECT_NE(e.find(std::string(c.key) + ":"), std::string::npos) << e;
    EXPECT_EQ(e.find('\n'), std::string::npos) << e;
  }
}

#ifdef FLAREKIT_ACQUISITION_WITH_RENDER
cv::Point2d lightImagePx(const ExrImage& truth) {
  const cv::Vec2d p = std::get<cv::Vec2d>(truth.attributes.at("flarekit.light_image_px"));
  return {p[0], p[1]};
}

// The head reports θ; the light stands at θ − angle_zero_offset_deg from the optical axis, so at
// θ = offset it is on the axis. Frames and truth keep the head's θ.
TEST(Rig, AngleZeroOffsetRendersTheLightAtTheTrueAngle) {
  testing::TempDir dir;
  const auto ideal = makeRenderScene(loadRigText(dir, "ideal.toml", simulatedRig("")));
  const auto offset = makeRenderScene(
      loadRigText(dir, "offset.toml", simulatedRig("angle_zero_offset_deg = 1.5\n")));
  const double f_number = 4;
  EXPECT_EQ(cv::norm(offset->radiance(5.0, f_number), ideal->radiance(3.5, f_number), cv::NORM_INF),
            0.0);
  const ExrImage truth = offset->truth(5.0, f_number);
  EXPECT_EQ(numericAttribute(truth.attributes, "flarekit.angle_deg"), 5.0);
  EXPECT_EQ(numericAttribute(truth.attributes, "flarekit.true_angle_deg"), 3.5);
  EXPECT_EQ(lightImagePx(truth), lightImagePx(ideal->truth(3.5, f_number)));
  EXPECT_EQ(cv::norm(truth.main(), ideal->truth(3.5, f_number).main(), cv::NORM_INF), 0.0);
  EXPECT_EQ(ideal->truth(3.5, f_number).attributes.count("flarekit.true_angle_deg"), 0u);
  const cv::Point2d on_axis = lightImagePx(offset->truth(1.5, f_number));
  EXPECT_NEAR(on_axis.x, 80, 0.05);
  EXPECT_NEAR(on_axis.y, 53.5, 0.05);
}

// The rig's optical axis offset reaches the renderer: the light's image and the truth's ghosts
// move by (dx, dy).
TEST(Rig, OpticalAxisOffsetMovesTheSimulatedFlare) {
  testing::TempDir dir;
  const auto ideal = makeRenderScene(loadRigText(dir, "ideal.toml", simulatedRig("")));
  const auto offset = makeRenderScene(
      loadRigText(dir, "offset.toml", simulatedRig("optical_axis_offset_px = [7.25, -3.5]\n")));
  const ExrImage a = ideal->truth(3.0, 4), b = offset->truth(3.0, 4);
  EXPECT_NEAR(lightImagePx(b).x - lightImagePx(a).x, 7.25, 1e-9);
  EXPECT_NEAR(lightImagePx(b).y - lightImagePx(a).y, -3.5, 1e-9);
  EXPECT_EQ(std::get<cv::Vec2d>(b.attributes.at("flarekit.optical_axis_offset_px")),
            cv::Vec2d(7.25, -3.5));
  EXPECT_EQ(a.attributes.count("flarekit.optical_axis_offset_px"), 0u);
  // Truth and frames come from one render.
  cv::Mat radiance = offset->radiance(3.0, 4);
  EXPECT_EQ(cv::norm(luminance(radiance), b.main(), cv::NORM_INF), 0.0);
}
#endif

}  // namespace
}  // namespace flarekit::acquisition
