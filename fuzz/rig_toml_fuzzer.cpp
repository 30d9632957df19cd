// Fuzz target: rig files (acquisition/rig.h loadRig, TOML; rigs/*.toml). The file is written to
// the scratch folder, so a rig's `lens = "..."` resolves there (and usually does not exist).
// Seeds: fuzz/corpus/rig_toml.
#include <cstddef>
#include <cstdint>

#include "acquisition/capture.h"
#include "acquisition/rig.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  fuzz::quietLogs();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const auto path = fuzz::writeScratchFile("rig.toml", data, size);
  fuzz::expectFlareKitErrors([&] {
    const acquisition::Rig rig = acquisition::loadRig(path);
    (void)acquisition::CapturePlan::FromRig(rig);
    if (rig.simulated()) (void)acquisition::resolveLensPath(rig);
  });
  return 0;
}
