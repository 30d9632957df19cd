// Fuzz target: glTF 2.0 scenes of `flarekit predict` (predict/scene.h loadGltfScene, tinygltf):
// written as .glb when the input starts with the binary magic "glTF", else as .gltf.
// Seeds: fuzz/corpus/gltf (predict/examples/stage.gltf, a .glb made from it, edge cases).
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "fuzz/fuzz_support.h"
#include "predict/scene.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool binary = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  const auto path = fuzz::writeScratchFile(binary ? "scene.glb" : "scene.gltf", data, size);
  fuzz::expectFlareKitErrors([&] { (void)predict::loadGltfScene(path); });
  return 0;
}
