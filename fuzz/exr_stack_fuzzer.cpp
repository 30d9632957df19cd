// Fuzz target: one EXR file as a frame of an EXR stack handed to `flarekit fit` (fit/frames.h
// loadExrStack, the frame and its "saturated" mask, the angle from flarekit.angle_deg), and the
// same file as a simulated capture's per-ghost truth (readGhostTruth, `fit-eval`).
// Seeds: fuzz/corpus/exr_stack (fuzz/make_seeds).
#include <cstddef>
#include <cstdint>

#include "fit/frames.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fuzz::writeScratchFile("frame_0001.exr", data, size);
  fuzz::expectFlareKitErrors([&] { fit::loadExrStack({path}); });
  fuzz::expectFlareKitErrors([&] {
    fit::FrameLoadOptions by_name;
    by_name.angle_pattern = "frame_([0-9]+)";
    fit::loadExrStack({path}, by_name);
  });
  fuzz::expectFlareKitErrors([&] { fit::readGhostTruth(path); });
  return 0;
}
