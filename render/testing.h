#pragma once
// Helpers for the render layer's tests (header-only; not part of any library).

#include <filesystem>
#include <string>

#include "render/lens.h"

namespace flarekit::testing {

// A lens shipped in the project's lenses/ folder, by file name.
inline render::Lens lensNamed(const std::string& name) {
  return render::loadLens(std::filesystem::path(FLAREKIT_SOURCE_DIR) / "lenses" / name);
}

}  // namespace flarekit::testing
