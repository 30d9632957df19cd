#include "common/shipped_file.h"

namespace flarekit {

std::optional<std::filesystem::path> findShippedFile(const std::filesystem::path& relative,
                                                     const std::vector<std::filesystem::path>& preferred) {
  namespace fs = std::filesystem;
  std::vector<fs::path> candidates = preferred;
  candidates.push_back(relative);
  if (relative.is_relative()) candidates.push_back(fs::path(FLAREKIT_SOURCE_DIR) / relative);
  std::error_code ec;
  for (const auto& c : candidates)
    if (fs::exists(fs::symlink_status(c, ec))) return c;  // a broken link is named when read
  return std::nullopt;
}

}  // namespace flarekit
