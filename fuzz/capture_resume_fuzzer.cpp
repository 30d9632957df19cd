// Fuzz target: a capture folder's manifest.json as `flarekit capture --resume` reads it
// (acquisition/capture.cpp runCapture with CaptureOptions::resume), on the simulated devices of
// fuzz/capture_support.h. At start-up the target makes the small capture in its scratch folder;
// each input replaces manifest.json and the session resumes with a stop already requested, so no
// frame is captured: the manifest is read, checked against the plan, merged with the darks and
// frames on disk and written again. Seeds: fuzz/corpus/capture_resume.
#include <atomic>
#include <cstddef>
#include <cstdint>

#include "fuzz/capture_support.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  (void)fuzz::scratchCapture();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const acquisition::Rig rig = fuzz::captureRig();
  static acquisition::RigDevices devices = fuzz::captureDevices(rig);
  static const acquisition::CapturePlan plan = fuzz::capturePlan();
  fuzz::writeScratchFile("capture/manifest.json", data, size);
  std::atomic<bool> stop{true};
  acquisition::CaptureOptions options;
  options.resume = true;
  options.progress = false;
  options.stop_requested = &stop;
  fuzz::expectFlareKitErrors(
      [&] { (void)acquisition::runCapture(rig, devices, plan, fuzz::scratchCapture(), options); });
  return 0;
}
