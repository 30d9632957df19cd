#pragma once
// Helpers shared by the fuzz targets (fuzz/README.md).
//
// Every target follows one rule: FlareKit's own errors (InputError, RuntimeError and what derives
// from them) are the expected answer to bad input and are caught by expectFlareKitErrors; any
// other exception escapes to libFuzzer, which reports it as a crash. Such an exception reaches
// `flarekit`'s main as "unexpected failure" (app/main.cpp), which is a bug. Catching
// std::runtime_error instead would hide std::filesystem::filesystem_error and friends.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "common/error.h"

namespace flarekit::fuzz {

// This process's scratch folder, /dev/shm/flarekit-fuzz-<pid> (created on first use, removed at
// exit; those of processes that died without exiting are removed when the next one starts).
// Falls back to the system temporary folder when /dev/shm is absent.
const std::filesystem::path& scratchDir();

// Writes the bytes to scratchDir()/name (replacing it) and returns the path.
std::filesystem::path writeScratchFile(const std::string& name, const uint8_t* data, size_t size);
std::filesystem::path writeScratchFile(const std::string& name, std::string_view text);

// The input as text (any bytes, NUL included).
inline std::string asText(const uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

// Quiets FlareKit's log (warnings about bad frames and the like) for fast, readable runs; call
// from LLVMFuzzerInitialize. FLAREKIT_FUZZ_VERBOSE=1 keeps it.
void quietLogs();

// Runs `f`, swallowing InputError and RuntimeError; anything else propagates.
template <class F>
void expectFlareKitErrors(F&& f) {
  try {
    f();
  } catch (const InputError&) {
  } catch (const RuntimeError&) {
  }
}

}  // namespace flarekit::fuzz
