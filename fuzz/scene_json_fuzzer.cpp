// Fuzz target: scene files of `flarekit predict` (predict/scene.h parseSceneJson, format
// "flarekit.scene"; predict/examples/*.json). Relative paths (a background image) resolve against
// the scratch folder, where the target writes small stand-ins for the examples' backgrounds.
// Seeds: fuzz/corpus/scene_json.
#include <cstddef>
#include <cstdint>

#include <opencv2/core.hpp>

#include "common/exr.h"
#include "fuzz/fuzz_support.h"
#include "predict/scene.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  const cv::Mat background(12, 16, CV_32FC3, cv::Scalar(0.1, 0.2, 0.3));
  writeExr(fuzz::scratchDir() / "stage_background.exr", background);
  writeExr(fuzz::scratchDir() / "stage_100mm_background.exr", background);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fuzz::expectFlareKitErrors([&] {
    (void)predict::parseSceneJson(fuzz::asText(data, size), fuzz::scratchDir() / "scene.json");
  });
  return 0;
}
