// Fuzz target: camera RAW files given to `flarekit merge` (acquisition/raw_decode.h decodeRawFile,
// LibRaw; written as .dng). LibRaw itself is Debian's uninstrumented build: coverage guidance
// comes from FlareKit's side, ASan still checks what FlareKit does with LibRaw's output.
// Seeds: fuzz/corpus/raw_decode (small DNGs from acquisition/dng_writer, fuzz/make_seeds).
#include <cstddef>
#include <cstdint>

#include "acquisition/raw_decode.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fuzz::writeScratchFile("input.dng", data, size);
  fuzz::expectFlareKitErrors([&] { (void)acquisition::decodeRawFile(path); });
  return 0;
}
