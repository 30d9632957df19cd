// The gphoto2 backend on its real path, without hardware: libgphoto2's ptp2 driver through its
// PTP/IP port talks to a PTP/IP camera served by the test (acquisition/testing/ptpip_camera.h),
// whose frames come from the simulated camera; downloads are decoded by LibRaw. Captures through
// it are compared with the same captures made with the simulated camera directly.
#include <gtest/gtest.h>

#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>

#include "acquisition/capture.h"
#include "acquisition/gphoto2_camera.h"
#include "acquisition/render_scene.h"
#include "acquisition/testing.h"
#include "acquisition/testing/ptpip_camera.h"
#include "common/config.h"
#include "common/exr.h"
#include "common/testing.h"

// libgphoto2 2.5.30 leaks what a failed camera_init allocated (the ptp2 driver's private data
// and its iconv descriptors; the driver is unloaded by then, so only its callers have names) and
// the device list of its USB port driver. Not this program's leaks: suppressed for LeakSanitizer
// builds, with full unwinding so that the callers are seen.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:gp_camera_init\nleak:libusb_get_device_list\n";
}
extern "C" const char* __asan_default_options() { return "fast_unwind_on_malloc=0"; }

namespace flarekit::acquisition {
namespace {

namespace fs = std::filesystem;
using testing::PtpIpCamera;
using testing::PtpIpFaults;

// A simulated camera (scene + sensor on a stage shared with a simulated head) served over PTP/IP.
struct ServedCamera {
  std::shared_ptr<SimulatedStage> stage = std::make_shared<SimulatedStage>();
  std::unique_ptr<SimulatedCamera> sensor;
  std::unique_ptr<PtpIpCamera> camera;

  ServedCamera(std::shared_ptr<SceneProvider> scene, RawExposer exposer, Cfa cfa, double black,
               std::function<double(double)> white, double focal_length_mm = 0) {
    sensor = std::make_unique<SimulatedCamera>(stage, std::move(scene), std::move(exposer), cfa,
                                               black, std::move(white), 1, FaultConfig{});
    testing::PtpIpCameraOptions options;
    options.focal_length_mm = focal_length_mm;
    camera = std::make_unique<PtpIpCamera>(
        [this](const testing::ExposureSettings& s) {
          sensor->setExposure(s.exposure_s);
          sensor->setIso(s.iso);
          sensor->setAperture(s.f_number);
          return sensor->capture();
        },
        options);
  }

  ServedCamera(const ServedCamera&) = delete;  // the frame source holds `this`
  ServedCamera& operator=(const ServedCamera&) = delete;

  // The rig's devices: a simulated head on the camera's stage and the gphoto2 backend.
  RigDevices devices(const Rig& rig) const {
    RigDevices d;
    d.head = std::make_unique<SimulatedHead>(stage, SimulatedHeadConfig{}, FaultConfig{});
    d.camera = std::make_unique<Gphoto2Camera>(rig.gphoto2);
    return d;
  }
};

// The spot scene of acquisition/testing.h on an RGGB sensor (12 bit, black 100).
std::unique_ptr<ServedCamera> spotCamera(std::function<void(double)> on_render = {}) {
  return std::make_unique<ServedCamera>(std::make_shared<testing::SpotScene>(std::move(on_render)),
                                        testing::exposeSpot, Cfa::kRGGB, 100.0,
                                        [](double) { return 4095.0; }, 50.0);
}

Rig spotRig(const ServedCamera& served) {
  Rig rig = testing::spotRig("ptpip-spot");
  rig.sensor.cfa = Cfa::kRGGB;
  rig.camera_driver = CameraDriver::kGphoto2;
  rig.gphoto2.port = served.camera->gphoto2Port();
  rig.gphoto2.capture_timeout_s = 0.5;
  return rig;
}

// Three angles, two short exposures the camera offers (1/100 s and 1/25 s): the watchdog's wait
// for a capture that never completes is the exposure plus capture_timeout_s.
CapturePlan spotPlan() {
  CapturePlan p;
  p.from_deg = 0;
  p.to_deg = 2;
  p.step_deg = 1;
  p.exposures_s = {0.01, 0.04};
  p.retry_delay_s = 0;
  return p;
}

nlohmann::json manifest(const fs::path& dir) { return loadJsonFile(dir / "manifest.json").json(); }

// Every frame of a finished capture in `dir` equals the same frame of `reference` (same units).
void expectSameFrames(const fs::path& dir, const fs::path& reference, double scale = 1.0) {
  const auto m = manifest(dir), r = manifest(reference);
  ASSERT_EQ(m["status"], "complete");
  ASSERT_EQ(m["frames"].size(), r["frames"].size());
  const auto differences = testing::frameDifferences(dir, reference, scale);
  for (size_t i = 0; i < differences.size(); ++i) EXPECT_LE(differences[i].largest, 1e-5) << "frame " << i;
}

// No temporaries of interrupted writes, and every frame file is listed in the manifest.
void expectNothingHalfWritten(const fs::path& dir) {
  const auto m = manifest(dir);
  size_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    if (e.path().parent_path().filename() == "frames") ++files;
  }
  EXPECT_EQ(files, m["frames"].size());
}

TEST(Gphoto2PtpIp, RigCheckFindsTheCameraAtItsPort) {
  auto served = spotCamera();
  const Rig rig = spotRig(*served);
  std::vector<std::string> lines;
  EXPECT_TRUE(probeGphoto2(rig.gphoto2, &lines));
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "found camera PTP/IP Camera on " + served->camera->gphoto2Port() +
                          " (FlareKit PTP/IP test camera) (used)");
  const RigCheckReport report = checkRig(rig);
  EXPECT_TRUE(report.ok);
}

// The settings reach the camera's device properties, and a frame comes back whole with its EXIF.
TEST(Gphoto2PtpIp, SetsExposureIsoApertureAndDownloadsTheFrame) {
  auto served = spotCamera();
  const Rig rig = spotRig(*served);
  Gphoto2Camera camera(rig.gphoto2);
  EXPECT_EQ(camera.describe(), "FlareKit PTP/IP test camera (gphoto2, " + rig.gphoto2.port + ")");
  camera.setIso(200);
  camera.setAperture(5.6);
  camera.setExposure(0.25);
  auto s = served->camera->settings();
  EXPECT_EQ(s.iso, 200);
  EXPECT_DOUBLE_EQ(s.f_number, 5.6);
  EXPECT_DOUBLE_EQ(s.exposure_s, 0.25);
  camera.setExposure(0.58);  // not offered: the nearest in log scale, 0.6 s
  EXPECT_DOUBLE_EQ(served->camera->settings().exposure_s, 0.6);
  camera.setExposure(1.0);
  const int64_t before = static_cast<int64_t>(std::time(nullptr));
  const RawFrame frame = camera.capture();
  served->stage->angle_deg = 0;
  served->sensor->setExposure(1.0);
  served->sensor->setIso(200);
  const RawFrame direct = served->sensor->capture();
  ASSERT_EQ(frame.data.size(), direct.data.size());
  EXPECT_EQ(cv::norm(frame.data, direct.data, cv::NORM_INF), 0.0);
  EXPECT_EQ(frame.cfa, Cfa::kRGGB);
  EXPECT_EQ(frame.black_level, 100);
  EXPECT_EQ(frame.white_level, 4095);
  EXPECT_NEAR(frame.exposure_s, 1.0, 1e-6);
  EXPECT_NEAR(frame.iso, 200, 1e-6);
  EXPECT_NEAR(frame.f_number, 5.6, 1e-3);
  EXPECT_NEAR(frame.focal_length_mm, 50, 1e-6);
  EXPECT_GE(frame.capture_time, before);
  EXPECT_NE(frame.camera.find("FlareKit PTP/IP test camera"), std::string::npos) << frame.camera;
  const auto counters = served->camera->counters();
  EXPECT_EQ(counters.captures, 1);
  EXPECT_EQ(counters.downloads, 1);
  EXPECT_EQ(counters.objects_on_card, 0);  // downloaded, then deleted from the camera
}

// Target of issue 61: a 0–5° capture of a simulated lens through libgphoto2 + LibRaw matches the
// same capture made with the simulated camera directly.
TEST(Gphoto2PtpIp, CaptureOfASimulatedLensMatchesTheDirectCapture) {
  testing::TempDir dir;
  Rig direct_rig = loadRig(findRig("sim-nikon"));
  direct_rig.simulation.width_px = 96;
  direct_rig.simulation.height_px = 64;
  direct_rig.simulation.grid_size = 24;
  CapturePlan plan = CapturePlan::FromRig(direct_rig);
  plan.from_deg = 0;
  plan.to_deg = 5;
  plan.step_deg = 2.5;
  plan.retry_delay_s = 0;
  {
    RigDevices devices = openRig(direct_rig);
    CaptureOptions options;
    options.write_truth = false;
    runCapture(direct_rig, devices, plan, dir.path() / "direct", options);
  }
  auto scene = makeRenderScene(direct_rig);
  ServedCamera served(scene, makeSensorExposer(direct_rig), direct_rig.sensor.cfa,
                      direct_rig.sensor.black_level_dn,
                      [direct_rig](double iso) { return simulatedWhiteLevel(direct_rig, iso); },
                      scene->focalLengthMm());
  Rig rig = direct_rig;
  rig.camera_driver = CameraDriver::kGphoto2;
  rig.gphoto2.port = served.camera->gphoto2Port();
  RigDevices devices = served.devices(rig);
  const CaptureSummary s = runCapture(rig, devices, plan, dir.path() / "ptpip");
  EXPECT_EQ(s.termination, "complete");
  EXPECT_EQ(s.camera_retries, 0);
  // Frames of a real camera are in electrons/s, the simulated camera's in render units.
  const auto m = manifest(dir.path() / "ptpip"), d = manifest(dir.path() / "direct");
  EXPECT_EQ(m["image"]["units"], "electrons/s");
  ASSERT_EQ(m["frames"].size(), 3u);
  const auto differences = testing::frameDifferences(dir.path() / "ptpip", dir.path() / "direct",
                                                     direct_rig.sensor.electrons_per_unit_s);
  ASSERT_EQ(differences.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const auto& f = differences[i];
    std::printf("frame %zu (%.1f deg): median relative difference %.3g, largest %.3g\n", i,
                f.angle_deg, f.median, f.largest);
    EXPECT_LE(f.median, 0.01) << "frame " << i;  // the target
    EXPECT_LE(f.largest, 1e-5) << "frame " << i;  // the same photosites: float rounding only
    EXPECT_EQ(m["frames"][i]["exposures_s"], d["frames"][i]["exposures_s"]);
  }
  EXPECT_EQ(served.camera->counters().objects_on_card, 0);
}

// ── faults ────────────────────────────────────────────────────────────────────────────────
// Each fault is armed when the head reaches 1° (frame 0 is taken cleanly). `count` faults in a
// row are retried (max_retries 3) and the capture completes; a fault for ever stops it with the
// session saved, and a resume once the camera behaves gives the frames of a clean capture.

struct FaultCase {
  const char* name;
  int PtpIpFaults::*fault;
  int session_retries;  // of the capture session, for two faults in a row
};

void PrintTo(const FaultCase& c, std::ostream* os) { *os << c.name; }

class Gphoto2PtpIpFault : public ::testing::TestWithParam<FaultCase> {
 protected:
  // A clean capture, for comparison.
  static void SetUpTestSuite() {
    reference_ = new testing::TempDir;
    auto served = spotCamera();
    const Rig rig = spotRig(*served);
    RigDevices d = served->devices(rig);
    runCapture(rig, d, spotPlan(), reference_->path() / "clean");
  }
  static void TearDownTestSuite() {
    delete reference_;
    reference_ = nullptr;
  }
  static fs::path clean() { return reference_->path() / "clean"; }

  // A camera that starts the fault `count` times (-1 = for ever) once the head is at 1°.
  std::unique_ptr<ServedCamera> faultyCamera(int count) {
    PtpIpCamera** camera = &armed_;
    int PtpIpFaults::*fault = GetParam().fault;
    auto served = spotCamera([camera, count, fault](double angle) {
      if (angle == 1 && *camera) {
        PtpIpFaults f;
        f.*fault = count;
        (*camera)->setFaults(f);
        *camera = nullptr;  // once
      }
    });
    armed_ = served->camera.get();
    return served;
  }

  PtpIpCamera* armed_ = nullptr;
  static testing::TempDir* reference_;
};
testing::TempDir* Gphoto2PtpIpFault::reference_ = nullptr;

TEST_P(Gphoto2PtpIpFault, TransientFaultsAreRetriedAndTheCaptureCompletes) {
  testing::TempDir dir;
  auto served = faultyCamera(2);
  const Rig rig = spotRig(*served);
  RigDevices d = served->devices(rig);
  const CaptureSummary s = runCapture(rig, d, spotPlan(), dir.path() / "cap");
  EXPECT_EQ(s.termination, "complete");
  EXPECT_EQ(s.camera_retries, GetParam().session_retries);
  EXPECT_EQ(served->camera->faults().*(GetParam().fault), 0);  // both happened
  expectSameFrames(dir.path() / "cap", clean());
  expectNothingHalfWritten(dir.path() / "cap");
}

TEST_P(Gphoto2PtpIpFault, PersistentFaultStopsTheSessionAndResumeFinishesIt) {
  testing::TempDir dir;
  auto served = faultyCamera(-1);
  const Rig rig = spotRig(*served);
  {
    RigDevices d = served->devices(rig);
    try {
      runCapture(rig, d, spotPlan(), dir.path() / "cap");
      ADD_FAILURE() << "completed despite the fault";
    } catch (const RuntimeError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find("camera PTP/IP Camera on " + rig.gphoto2.port), std::string::npos) << m;
      EXPECT_NE(m.find("at frame 1 (1°)"), std::string::npos) << m;
      EXPECT_NE(m.find("--resume"), std::string::npos) << m;
    }
  }
  const auto m = manifest(dir.path() / "cap");
  EXPECT_EQ(m["status"], "failed");
  EXPECT_EQ(m["frames"].size(), 1u);
  expectNothingHalfWritten(dir.path() / "cap");
  served->camera->setFaults({});
  RigDevices d = served->devices(rig);
  CaptureOptions resume;
  resume.resume = true;
  const CaptureSummary s = runCapture(rig, d, spotPlan(), dir.path() / "cap", resume);
  EXPECT_EQ(s.frames_already_done, 1);
  EXPECT_EQ(s.frames_captured, 2);
  expectSameFrames(dir.path() / "cap", clean());
  expectNothingHalfWritten(dir.path() / "cap");
}

INSTANTIATE_TEST_SUITE_P(
    Faults, Gphoto2PtpIpFault,
    // A busy camera is asked again by the backend itself; the other faults are retried by the
    // session, which reconnects.
    ::testing::Values(FaultCase{"CaptureNeverCompletes", &PtpIpFaults::captures_never_completing, 2},
                      FaultCase{"ConnectionDroppedMidDownload", &PtpIpFaults::downloads_dropped, 2},
                      FaultCase{"DeviceBusy", &PtpIpFaults::busy_captures, 0},
                      FaultCase{"PropertySetRefused", &PtpIpFaults::property_sets_refused, 2},
                      FaultCase{"TruncatedObject", &PtpIpFaults::objects_truncated, 2}),
    [](const ::testing::TestParamInfo<FaultCase>& info) { return std::string(info.param.name); });

// ── bad input ─────────────────────────────────────────────────────────────────────────────

// A port on this machine where nothing listens.
int closedPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t n = sizeof a;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

TEST(Gphoto2PtpIp, AnUnreachablePortIsOneLineNamingTheCamera) {
  Gphoto2Config config;
  config.port = "ptpip:127.0.0.1:" + std::to_string(closedPort());
  try {
    Gphoto2Camera camera(config);
    FAIL() << "connected to nothing";
  } catch (const DeviceError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("camera PTP/IP Camera on " + config.port + ": connecting failed", 0), 0u) << m;
    EXPECT_NE(m.find("nothing answers there as a PTP/IP camera"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  std::vector<std::string> lines;
  EXPECT_FALSE(probeGphoto2(config, &lines));
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].rfind("MISSING: camera PTP/IP Camera on " + config.port, 0), 0u) << lines[0];
}

// A model libgphoto2 does not know is the rig file's error (exit 2), found before connecting.
TEST(Gphoto2PtpIp, AnUnknownModelIsTheRigFilesError) {
  Rig rig = testing::spotRig("ptpip-unknown");
  rig.camera_driver = CameraDriver::kGphoto2;
  rig.gphoto2.model = "Flarekit Imaginary Mark II";
  rig.gphoto2.port = "ptpip:127.0.0.1:" + std::to_string(closedPort());
  const std::string expected = "ptpip-unknown.toml: camera.model: libgphoto2 has no camera named "
                               "\"Flarekit Imaginary Mark II\"";
  try {
    openRig(rig);
    FAIL() << "opened an unknown model";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(expected, 0), 0u) << e.what();
  }
  try {
    checkRig(rig);
    FAIL() << "checked an unknown model";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(expected, 0), 0u) << e.what();
  }
}

TEST(Gphoto2PtpIp, ACameraAnsweringGarbageIsOneLineNamingTheCamera) {
  auto served = spotCamera();
  PtpIpFaults f;
  f.garbage_handshake = true;
  served->camera->setFaults(f);
  Gphoto2Config config;
  config.port = served->camera->gphoto2Port();
  try {
    Gphoto2Camera camera(config);
    FAIL() << "accepted an HTTP answer as a camera";
  } catch (const DeviceError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("camera PTP/IP Camera on " + config.port + ": connecting failed", 0), 0u) << m;
    EXPECT_NE(m.find("what answers there is not a PTP/IP camera"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
}

TEST(Gphoto2PtpIp, AFileThatIsNotRawStopsTheSessionNamingTheCamera) {
  testing::TempDir dir;
  auto served = spotCamera();
  PtpIpFaults f;
  f.jpeg_objects = true;
  served->camera->setFaults(f);
  const Rig rig = spotRig(*served);
  RigDevices d = served->devices(rig);
  try {
    runCapture(rig, d, spotPlan(), dir.path() / "cap");
    FAIL() << "merged JPEG files";
  } catch (const RuntimeError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("camera PTP/IP Camera on " + rig.gphoto2.port + ": FK_0001.JPG is not a RAW file"),
              std::string::npos) << m;
    EXPECT_NE(m.find("set the camera to save RAW only"), std::string::npos) << m;
  }
  EXPECT_EQ(manifest(dir.path() / "cap")["status"], "failed");
  EXPECT_EQ(served->camera->counters().captures, 1);  // persistent: not retried
}

}  // namespace
}  // namespace flarekit::acquisition
