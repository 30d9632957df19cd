// Fuzz target: a capture folder's manifest.json as `flarekit fit` reads it (fit/frames.h
// loadCapture). At start-up the target makes a small simulated capture in its scratch folder
// (fuzz/capture_support.h: frames, truth and darks); each input replaces its manifest.json, so a
// manifest that names the real files goes on to load them. Seeds: fuzz/corpus/capture_manifest.
#include <cstddef>
#include <cstdint>

#include "fit/frames.h"
#include "fuzz/capture_support.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  (void)fuzz::scratchCapture();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::writeScratchFile("capture/manifest.json", data, size);
  fuzz::expectFlareKitErrors([&] { (void)fit::loadCapture(fuzz::scratchCapture()); });
  return 0;
}
