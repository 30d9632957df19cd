#include "fuzz/fuzz_support.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <cstdlib>
#include <fstream>
#include <system_error>

#include "common/log.h"

namespace flarekit::fuzz {

namespace fs = std::filesystem;

namespace {

// Scratch folders of processes that are gone (a crash or a killed fork-mode job skips atexit).
void removeStaleScratchDirs(const fs::path& base) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(base, ec)) {
    const std::string name = e.path().filename().string();
    const std::string prefix = "flarekit-fuzz-";
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    const long pid = std::stol(digits);
    if (::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH) fs::remove_all(e.path(), ec);
  }
}

fs::path makeScratchDir() {
  std::error_code ec;
  fs::path base = "/dev/shm";
  if (!fs::is_directory(base, ec)) base = fs::temp_directory_path();
  removeStaleScratchDirs(base);
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
