#pragma once
// Files FlareKit ships beside its code (rigs/, lenses/, predict/examples/): found where the user
// points first, then relative to the working folder, then in the source tree the binary was built
// from, so `build/bin/flarekit demo` and `--rig sim-heliar` work from any working folder.

#include <filesystem>
#include <optional>
#include <vector>

namespace flarekit {

// The first existing path among `preferred` (tried in order), `relative` itself, and `relative`
// inside the source tree; nullopt when none exists. An absolute `relative` is only checked as is.
std::optional<std::filesystem::path> findShippedFile(const std::filesystem::path& relative,
                                                     const std::vector<std::filesystem::path>& preferred = {});

}  // namespace flarekit
