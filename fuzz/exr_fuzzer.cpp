// Fuzz target: one EXR file as `flarekit exr-info`, the fitter and the predictor read it
// (common/exr.h): readExr (every layer), readExrAttributes, listExrLayers, describeExr with its
// text and JSON forms (exr-info / exr-info --json). Seeds: fuzz/corpus/exr (fuzz/make_seeds).
#include <cstddef>
#include <cstdint>

#include <nlohmann/json.hpp>

#include "common/config.h"
#include "common/exr.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fuzz::writeScratchFile("input.exr", data, size);
  fuzz::expectFlareKitErrors([&] { readExr(path); });
  fuzz::expectFlareKitErrors([&] {
    ExrReadOptions strict;
    strict.allow_nonfinite = false;
    readExr(path, strict);
  });
  fuzz::expectFlareKitErrors([&] { readExrAttributes(path); });
  fuzz::expectFlareKitErrors([&] { listExrLayers(path); });
  fuzz::expectFlareKitErrors([&] {
    const ExrFileInfo info = describeExr(path);
    (void)toText(info);
    (void)jsonText(toJson(info));  // what exr-info --json prints
  });
  return 0;
}
