// Fuzz target: lens JSON (render/lens.h parseLensJson, schema in lenses/README.md) and, for a lens
// that loads, what `flarekit lens-info` computes from it (describeLens: paraxial properties).
// Seeds: fuzz/corpus/lens_json (lenses/*.json plus edge cases).
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
    const render::Lens lens = render::parseLensJson(fuzz::asText(data, size), "fuzz.json");
    (void)render::describeLens(lens);
  });
  return 0;
}
