#include "fuzz/capture_support.h"

#include <atomic>
#include <memory>

#include "acquisition/testing.h"
#include "fuzz/fuzz_support.h"

namespace flarekit::fuzz {

using namespace acquisition;

using testing::SpotScene;
using testing::spotDevices;

Rig captureRig() { return testing::spotRig("fuzz"); }

RigDevices captureDevices(const Rig& rig) { return spotDevices(rig); }

CapturePlan capturePlan() {
  CapturePlan p;
  p.from_deg = 0;
  p.to_deg = 2;
  p.step_deg = 1;
  p.exposures_s = {0.25, 1};
  p.dark_frames = 1;
  p.retry_delay_s = 0;
  return p;
}

void makeSmallCapture(const std::filesystem::path& dir, int stop_after_frames) {
  const Rig rig = captureRig();
  std::atomic<bool> stop{false};
  // The plan's angles are 0, 1, 2°: rendering frame k (at k°) requests the stop when k + 1 frames
  // are enough; the session notices after that frame.
  RigDevices d = spotDevices(rig, std::make_shared<SpotScene>([&](double angle_deg) {
    if (stop_after_frames > 0 && angle_deg + 1 >= stop_after_frames) stop = true;
  }));
  CaptureOptions options;
  options.progress = false;
  options.stop_requested = &stop;
  if (stop_after_frames == 0) stop = true;
  runCapture(rig, d, capturePlan(), dir, options);
}

const std::filesystem::path& scratchCapture() {
  static const std::filesystem::path dir = [] {
    const auto d = scratchDir() / "capture";
    makeSmallCapture(d);
    return d;
  }();
  return dir;
}

}  // namespace flarekit::fuzz
