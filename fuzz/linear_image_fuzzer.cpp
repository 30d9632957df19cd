// Fuzz target: linear 16-bit TIFF/PNG frames given to `flarekit merge`
// (acquisition/raw_decode.h loadLinearImage; OpenCV's decoders). Written as .png when the input
// starts with the PNG signature, else as .tif. Seeds: fuzz/corpus/linear_image (fuzz/make_seeds).
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "acquisition/raw_decode.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool png = size >= 8 && std::memcmp(data, "\x89PNG\r\n\x1a\n", 8) == 0;
  const auto path = fuzz::writeScratchFile(png ? "input.png" : "input.tif", data, size);
  fuzz::expectFlareKitErrors([&] {
    (void)acquisition::loadLinearImage(path, 0.25, 64, 4095, acquisition::Cfa::kRGGB);
  });
  return 0;
}
