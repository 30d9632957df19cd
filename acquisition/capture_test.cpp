// Capture sessions with a small synthetic scene (fast): plan, manifest after every frame, stop and
// resume, retries of transient faults, a persistent fault that leaves a resumable session.
#include "acquisition/capture.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <functional>
#include <fstream>

#include "acquisition/simulated_camera.h"
#include "acquisition/testing.h"
#include "common/config.h"
#include "common/exr.h"
#include "common/folder_lock.h"
#include "common/testing.h"

namespace flarekit::acquisition {
namespace {

namespace fs = std::filesystem;

using testing::SpotScene;

Rig testRig(FaultConfig faults = {}) { return testing::spotRig("unit-test", faults); }

RigDevices devices(const Rig& rig, std::shared_ptr<SpotScene> scene = std::make_shared<SpotScene>()) {
  return testing::spotDevices(rig, std::move(scene));
}

CapturePlan smallPlan(double to = 4, double step = 1) {
  CapturePlan p;
  p.from_deg = 0;
  p.to_deg = to;
  p.step_deg = step;
  p.exposures_s = {0.25, 1};
  p.retry_delay_s = 0;
  return p;
}

nlohmann::json manifest(const fs::path& dir) { return loadJsonFile(dir / "manifest.json").json(); }

void expectEveryAngleOnce(const fs::path& dir, const CapturePlan& plan) {
  const auto m = manifest(dir);
  const auto angles = plan.anglesDeg();
  ASSERT_EQ(m["frames"].size(), angles.size());
  for (size_t i = 0; i < angles.size(); ++i) {
    EXPECT_EQ(m["frames"][i]["index"], static_cast<int>(i));
    EXPECT_DOUBLE_EQ(m["frames"][i]["angle_deg"].get<double>(), angles[i]);
    const fs::path file = dir / m["frames"][i]["file"].get<std::string>();
    ExrImage exr = readExr(file);
    EXPECT_EQ(numericAttribute(exr.attributes, "flarekit.angle_deg"), angles[i]);
    EXPECT_NE(exr.find("saturated"), nullptr);
  }
  EXPECT_EQ(m["status"], "complete");
  EXPECT_EQ(m["frames_done"], static_cast<int>(angles.size()));
}

TEST(Capture, WritesFramesTruthAndManifest) {
  testing::TempDir dir;
  Rig rig = testRig();
  RigDevices d = devices(rig);
  CapturePlan plan = smallPlan();
  plan.dark_frames = 2;
  plan.keep_raw = true;
  CaptureSummary s = runCapture(rig, d, plan, dir.path() / "cap");
  EXPECT_EQ(s.termination, "complete");
  EXPECT_EQ(s.frames_captured, 5);
  expectEveryAngleOnce(dir.path() / "cap", plan);
  const auto m = manifest(dir.path() / "cap");
  EXPECT_EQ(m["format"], "flarekit.capture");
  EXPECT_EQ(m["version"], 1);
  EXPECT_EQ(m["truth"], true);
  EXPECT_EQ(m["image"]["width"], 32);
  EXPECT_EQ(m["image"]["height"], 24);
  EXPECT_EQ(m["darks"].size(), 2u);
  EXPECT_EQ(m["lens"]["focal_length_mm"], 50);  // the scene's: where its lights image
  EXPECT_TRUE(fs::exists(dir.path() / "cap" / m["frames"][2]["truth_file"].get<std::string>()));
  EXPECT_EQ(m["frames"][2]["raw_files"].size(), 2u);
  // The merged frame agrees with the scene (0.05 background, 3.0 spot) in scene units.
  cv::Mat y = readExrLayer(dir.path() / "cap" / "frames/frame_0000.exr", "");
  EXPECT_NEAR(y.at<float>(2, 2), 0.05, 0.02);
  EXPECT_NEAR(y.at<float>(12, 16), 3.0, 0.2);
  EXPECT_NE(s.BriefReport().find("complete"), std::string::npos);
  // A second capture into the same folder is refused; resuming a complete one does nothing.
  EXPECT_THROW(runCapture(rig, d, plan, dir.path() / "cap"), InputError);
  CaptureOptions resume;
  resume.resume = true;
  CaptureSummary again = runCapture(rig, d, plan, dir.path() / "cap", resume);
  EXPECT_EQ(again.frames_captured, 0);
  EXPECT_EQ(again.frames_already_done, 5);
}

// Light exposures: merged apart into light/, measured in the manifest; after the last frame the
// first whole light is measured again, and a drifting simulated light is reported as such.
TEST(Capture, LightExposuresMeasureTheLightAndItsDrift) {
  testing::TempDir dir;
  Rig rig = testRig();
  rig.simulation.light_drift_pct = 2;
  RigDevices d = devices(rig);
  CapturePlan plan = smallPlan(4, 0.5);
  plan.light_exposures_s = {3.0};
  plan.light_check_repeats = 4;
  plan.settle_s = 0.01;
  const CaptureSummary s = runCapture(rig, d, plan, dir.path() / "cap");
  expectEveryAngleOnce(dir.path() / "cap", plan);
  EXPECT_EQ(s.exposures_taken, 9 * 3 + 2 * 4);  // the bracket and the light exposure; the light check
  const auto m = manifest(dir.path() / "cap");
  EXPECT_EQ(m["plan"]["light_exposures_s"], nlohmann::json({3.0}));
  EXPECT_EQ(m["plan"]["light_nd_factor"], 1.0);
  EXPECT_EQ(m["plan"]["settle_s"], 0.01);
  EXPECT_EQ(m["rig"]["simulation"]["light_drift_pct"], 2.0);
  for (const auto& f : m["frames"]) {
    const auto& l = f["light"];
    EXPECT_TRUE(l["found"].get<bool>());
    EXPECT_FALSE(l["cut"].get<bool>());
    EXPECT_EQ(l["saturated_photosites"], 0);
    EXPECT_TRUE(fs::exists(dir.path() / "cap" / l["file"].get<std::string>()));
    // The spot (3.0 on a disc of radius 4) about its centre, unclipped, in scene units.
    EXPECT_NEAR(l["center_px"][0].get<double>(), 16.5 - std::floor(f["angle_deg"].get<double>()), 0.6);
    EXPECT_NEAR(l["peak"].get<double>(), 3.0 * (1 + 0.02 * f["index"].get<int>() / 8.0), 0.25);
  }
  ASSERT_TRUE(m.contains("light_check"));
  EXPECT_EQ(m["light_check"]["frame_index"], 0);
  EXPECT_EQ(m["light_check"]["repeats"], 4);
  EXPECT_EQ(m["light_check"]["start"]["fluxes"].size(), 4u);
  EXPECT_EQ(m["light_check"]["end"]["fluxes"].size(), 4u);
  const auto& st = m["light_stability"];
  EXPECT_EQ(st["frames"], 9);
  EXPECT_EQ(st["reference_frame_index"], 0);
  EXPECT_NEAR(st["drift_pct"].get<double>(), 2.0, 0.5);
  EXPECT_TRUE(st["scatter_pct"].is_number());
  EXPECT_NE(st["warning"].get<std::string>().find("drifted"), std::string::npos);
  // The truth is what the frames saw: the drift included.
  const ExrImage last = readExr(dir.path() / "cap" / m["frames"][8]["truth_file"].get<std::string>());
  EXPECT_EQ(numericAttribute(last.attributes, "flarekit.light_scale"), 1.02);
}

// A declared ND filter: the simulated camera sees the light through it, the light exposure's
// values are multiplied back; a steady light stays within 1 %, without a warning.
TEST(Capture, NdFilteredLightExposureAndASteadyLight) {
  testing::TempDir dir;
  Rig rig = testRig();
  RigDevices d = devices(rig);
  CapturePlan plan = smallPlan(4, 0.5);
  plan.light_exposures_s = {30.0};
  plan.light_nd_factor = 10;
  runCapture(rig, d, plan, dir.path() / "cap");
  const auto m = manifest(dir.path() / "cap");
  EXPECT_EQ(m["plan"]["light_nd_factor"], 10.0);
  const cv::Mat light = readExrLayer(dir.path() / "cap" / "light/frame_0000.exr", "");
  EXPECT_NEAR(light.at<float>(12, 16), 3.0, 0.2);  // 30 s through ×10 = 3 s of the light
  const auto& st = m["light_stability"];
  EXPECT_LT(std::abs(st["drift_pct"].get<double>()), 1.0);
  EXPECT_FALSE(st.contains("warning"));
  // Without light exposures or settle, the manifest has none of their keys (older captures stay
  // alike).
  runCapture(rig, d, smallPlan(2), dir.path() / "plain");
  const auto p = manifest(dir.path() / "plain");
  EXPECT_FALSE(p["plan"].contains("light_exposures_s"));
  EXPECT_FALSE(p["plan"].contains("settle_s"));
  EXPECT_FALSE(p.contains("light_stability"));
  EXPECT_FALSE(p["frames"][0].contains("light"));
  EXPECT_FALSE(fs::exists(dir.path() / "plain" / "light"));
}

// A simulated rig's imperfections are recorded under rig.simulation (an ideal rig has none), the
// frames keep the head's angles, and a resume with other imperfections is refused.
TEST(Capture, ManifestRecordsTheSimulatedRigsImperfections) {
  testing::TempDir dir;
  Rig ideal = testRig();
  RigDevices d = devices(ideal);
  const CapturePlan plan = smallPlan(2);
  runCapture(ideal, d, plan, dir.path() / "ideal");
  EXPECT_FALSE(manifest(dir.path() / "ideal")["rig"].contains("simulation"));

  Rig rig = testRig();
  rig.simulation.optical_axis_offset_px = {7.25, -3.5};
  rig.simulation.angle_zero_offset_deg = 1.5;
  RigDevices e = devices(rig);
  runCapture(rig, e, plan, dir.path() / "off");
  expectEveryAngleOnce(dir.path() / "off", plan);  // the head's angles, in manifest and frames
  const auto m = manifest(dir.path() / "off");
  ASSERT_TRUE(m["rig"].contains("simulation"));
  EXPECT_EQ(m["rig"]["simulation"]["optical_axis_offset_px"], nlohmann::json({7.25, -3.5}));
  EXPECT_EQ(m["rig"]["simulation"]["angle_zero_offset_deg"], 1.5);
  Rig other = rig;
  other.simulation.angle_zero_offset_deg = 1.0;
  CaptureOptions resume;
  resume.resume = true;
  try {
    runCapture(other, e, plan, dir.path() / "off", resume);
    ADD_FAILURE() << "resumed with another angle zero";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("angle zero"), std::string::npos) << error.what();
  }
  EXPECT_EQ(runCapture(rig, e, plan, dir.path() / "off", resume).frames_already_done, 3);
}

// A capture killed during its first manifest write leaves a stray temporary and no manifest; it is
// started again without --resume, and the new capture clears the stray.
TEST(Capture, AFreshCaptureRemovesTheStrayTemporariesOfAKilledOne) {
  testing::TempDir dir;
  Rig rig = testRig();
  RigDevices d = devices(rig);
  const fs::path out = dir.path() / "cap";
  fs::create_directories(out / "frames");
  std::ofstream(out / ".manifest.tmp-ab12cd.json") << "{\"format\": \"flarekit.cap";
  std::ofstream(out / "frames" / ".frame_0000.tmp-ef34gh.exr") << "half";
  CaptureSummary s = runCapture(rig, d, smallPlan(), out);
  EXPECT_EQ(s.termination, "complete");
  for (const auto& e : fs::recursive_directory_iterator(out))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
}

TEST(Capture, StopsAfterTheCurrentFrameAndResumesExactly) {
  testing::TempDir dir;
  Rig rig = testRig();
  std::atomic<bool> stop{false};
  auto scene = std::make_shared<SpotScene>([&](double angle) {
    if (angle == 2) stop = true;  // "Ctrl-C" while frame 2 is being taken
  });
  RigDevices d = devices(rig, scene);
  CapturePlan plan = smallPlan();
  CaptureOptions options;
  options.stop_requested = &stop;
  CaptureSummary s = runCapture(rig, d, plan, dir.path() / "cap", options);
  EXPECT_EQ(s.termination, "interrupted");
  EXPECT_EQ(s.frames_captured, 3);  // frame 2 was finished
  EXPECT_EQ(manifest(dir.path() / "cap")["status"], "interrupted");
  EXPECT_EQ(manifest(dir.path() / "cap")["frames"].size(), 3u);
  RigDevices fresh = devices(rig);
  CaptureOptions resume;
  resume.resume = true;
  CaptureSummary r = runCapture(rig, fresh, plan, dir.path() / "cap", resume);
  EXPECT_EQ(r.frames_already_done, 3);
  EXPECT_EQ(r.frames_captured, 2);
  expectEveryAngleOnce(dir.path() / "cap", plan);
  // Resuming with another plan is refused with a clear message.
  CapturePlan other = smallPlan(6);
  try {
    runCapture(rig, fresh, other, dir.path() / "cap", resume);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("angle plan"), std::string::npos) << e.what();
  }
}

// A damaged manifest is named with the field's path, never half used.
TEST(Capture, ResumeNamesAManifestFieldOfTheWrongType) {
  testing::TempDir dir;
  Rig rig = testRig();
  const CapturePlan plan = smallPlan(2);
  RigDevices d = devices(rig);
  runCapture(rig, d, plan, dir.path() / "cap", {});
  const nlohmann::json good = manifest(dir.path() / "cap");
  CaptureOptions resume;
  resume.resume = true;
  const std::vector<std::pair<std::function<void(nlohmann::json&)>, std::string>> damages = {
      {[](nlohmann::json& m) { m["rig"] = 3; }, "manifest.json: rig: must be a table, got an integer"},
      {[](nlohmann::json& m) { m["frames"][1] = 2; }, "manifest.json: frames[1]: must be a table, got an integer"},
      {[](nlohmann::json& m) { m["frames"][0]["index"] = "0"; }, "manifest.json: frames[0].index: must be an integer, got a string"},
      {[](nlohmann::json& m) { m["plan"] = "x"; }, "manifest.json: plan: must be a table, got a string"},
      {[](nlohmann::json& m) { m["darks"] = {1}; }, "manifest.json: darks[0]: must be a table, got an integer"}};
  for (const auto& [damage, message] : damages) {
    nlohmann::json m = good;
    damage(m);
    writeJsonFile(dir.path() / "cap" / "manifest.json", m);
    RigDevices fresh = devices(rig);
    try {
      runCapture(rig, fresh, plan, dir.path() / "cap", resume);
      ADD_FAILURE() << "accepted: " << message;
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), (dir.path() / "cap" / message).string());
    }
  }
}

// One process per capture folder: a second session is refused while the first holds it.
TEST(Capture, ASecondSessionOnAFolderInUseIsRefused) {
  testing::TempDir dir;
  Rig rig = testRig();
  fs::create_directories(dir.path() / "cap");
  const FolderLock held(dir.path() / "cap");
  RigDevices d = devices(rig);
  try {
    runCapture(rig, d, smallPlan(2), dir.path() / "cap", {});
    FAIL();
  } catch (const RuntimeError& e) {
    EXPECT_EQ(std::string(e.what()), (dir.path() / "cap").string() + ": in use by process " +
                                         std::to_string(::getpid()) + "; wait for it to finish or stop it");
  }
  EXPECT_FALSE(fs::exists(dir.path() / "cap" / "manifest.json"));
}

TEST(Capture, TransientFaultsAreRetried) {
  testing::TempDir dir;
  FaultConfig faults;
  faults.camera_transient_probability = 0.05;
  faults.head_transient_probability = 0.02;
  faults.camera_timeout_probability = 0.01;
  faults.timeout_s = 0.001;
  Rig rig = testRig(faults);
  RigDevices d = devices(rig);
  CapturePlan plan = smallPlan(99, 1);  // 100 steps
  CaptureSummary s = runCapture(rig, d, plan, dir.path() / "cap");
  EXPECT_EQ(s.termination, "complete");
  EXPECT_GT(s.camera_retries, 0);
  EXPECT_GT(s.head_retries, 0);
  expectEveryAngleOnce(dir.path() / "cap", plan);
}

TEST(Capture, PersistentFaultLeavesAResumableSession) {
  testing::TempDir dir;
  FaultConfig faults;
  faults.camera_disconnect_after_frames = 7;  // 3 frames of 2 exposures, then a disconnect
  Rig rig = testRig(faults);
  RigDevices d = devices(rig);
  CapturePlan plan = smallPlan();
  try {
    runCapture(rig, d, plan, dir.path() / "cap");
    FAIL();
  } catch (const RuntimeError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("disconnected"), std::string::npos) << m;
    EXPECT_NE(m.find("--resume"), std::string::npos) << m;
  }
  const auto m = manifest(dir.path() / "cap");
  EXPECT_EQ(m["status"], "failed");
  EXPECT_EQ(m["frames"].size(), 3u);
  Rig healthy = testRig();
  RigDevices fresh = devices(healthy);
  CaptureOptions resume;
  resume.resume = true;
  runCapture(healthy, fresh, plan, dir.path() / "cap", resume);
  expectEveryAngleOnce(dir.path() / "cap", plan);
}

TEST(Capture, FramesDependOnlyOnAngleAndExposure) {
  // Determinism: a resumed capture reproduces an uninterrupted one bit for bit.
  testing::TempDir dir;
  Rig rig = testRig();
  RigDevices a = devices(rig), b = devices(rig);
  CapturePlan plan = smallPlan(2);
  runCapture(rig, a, plan, dir.path() / "a");
  CapturePlan tail = plan;
  tail.from_deg = 1;
  runCapture(rig, b, tail, dir.path() / "b");
  cv::Mat fa = readExrLayer(dir.path() / "a/frames/frame_0002.exr", "");
  cv::Mat fb = readExrLayer(dir.path() / "b/frames/frame_0001.exr", "");
  EXPECT_EQ(cv::norm(fa, fb, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace flarekit::acquisition
