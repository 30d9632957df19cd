// Fuzz target: flare-model files (model/flare_model.h FlareModel::load, model.json written by
// `flarekit fit`), and for a model that loads what `model-info`, `render` and `predict` do with it:
// its JSON again, the ghosts and pedestal at a few angles, a small render.
// Seeds: fuzz/corpus/model_json (tests/data/*/ models plus edge cases).
#include <cstddef>
#include <cstdint>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "common/config.h"
#include "fuzz/fuzz_support.h"
#include "model/flare_model.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fuzz::writeScratchFile("model.json", data, size);
  fuzz::expectFlareKitErrors([&] {
    const model::FlareModel m = model::FlareModel::load(path);
    (void)jsonText(m.toJson());
    std::vector<double> angles{0.0};
    for (const auto& g : m.ghosts) {
      angles.push_back(g.angle_min_deg);
      angles.push_back(0.5 * (g.angle_min_deg + g.angle_max_deg));
    }
    if (angles.size() > 4) angles.resize(4);
    for (double a : angles) {
      (void)m.ghostsAt(a);
      (void)m.pedestalAt(a);
    }
    (void)m.render(angles.back(), 10.0, cv::Size(32, 24));
  });
  return 0;
}
