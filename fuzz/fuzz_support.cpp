#include "fuzz/fuzz_support.h"

#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <system_error>

#include "common/log.h"

namespace flarekit::fuzz {

namespace fs = std::filesystem;

namespace {

fs::path makeScratchDir() {
  std::error_code ec;
  fs::path base = "/dev/shm";
  if (!fs::is_directory(base, ec)) base = fs::temp_directory_path();
  fs::path dir = base / ("flarekit-fuzz-" + std::to_string(::getpid()));
  fs::remove_all(dir, ec);
  fs::create_directories(dir);
  return dir;
}

void removeScratchDir() {
  std::error_code ec;
  fs::remove_all(scratchDir(), ec);
}

}  // namespace

const fs::path& scratchDir() {
  static const fs::path dir = [] {
    fs::path d = makeScratchDir();
    std::atexit(removeScratchDir);
    return d;
  }();
  return dir;
}

fs::path writeScratchFile(const std::string& name, const uint8_t* data, size_t size) {
  const fs::path path = scratchDir() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  if (!out) {
    // The harness cannot work (e.g. /dev/shm full): stop loudly rather than fuzz nothing.
    std::abort();
  }
  return path;
}

fs::path writeScratchFile(const std::string& name, std::string_view text) {
  return writeScratchFile(name, reinterpret_cast<const uint8_t*>(text.data()), text.size());
}

void quietLogs() {
  const char* verbose = std::getenv("FLAREKIT_FUZZ_VERBOSE");
  if (verbose && std::string(verbose) == "1") return;
  setLogLevel(LogLevel::kError);
}

}  // namespace flarekit::fuzz
