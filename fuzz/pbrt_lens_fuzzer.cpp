// Fuzz target: pbrt realistic-camera lens tables (render/lens.h parsePbrtLens, `.dat` files) and,
// for a lens that loads, describeLens (`flarekit lens-info`). Seeds: fuzz/corpus/pbrt_lens.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_support.h"
#include "render/lens.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::expectFlareKitErrors([&] {
    const render::Lens lens = render::parsePbrtLens(fuzz::asText(data, size), "fuzz.dat");
    (void)render::describeLens(lens);
  });
  return 0;
}
