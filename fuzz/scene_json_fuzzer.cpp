// Fuzz target: scene files of `flarekit predict` (predict/scene.h parseSceneJson, format
// "flarekit.scene"; predict/examples/*.json). Relative paths (a background image) resolve against
// the scratch folder. Seeds: fuzz/corpus/scene_json.
#include <cstddef>
#include <cstdint>

#include "fuzz/fuzz_support.h"
#include "predict/scene.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::expectFlareKitErrors([&] {
    (void)predict::parseSceneJson(fuzz::asText(data, size), fuzz::scratchDir() / "scene.json");
  });
  return 0;
}
