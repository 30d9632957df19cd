#pragma once
// Files a user names are opened through here: regular files only, of bounded size. A path at a
// device (/dev/zero), a FIFO or a socket fails at once with one line instead of reading without
// end or blocking, and a symlink loop or a folder is named as such.

#include <cstdint>
#include <filesystem>
#include <string>

namespace flarekit {

// Largest text input (lens, rig, model, scene, manifest, glTF) read, in bytes. The largest file
// FlareKit writes that it reads back, a fit's frame fits of a long capture, is a few MB.
inline constexpr std::uintmax_t kMaxTextFileBytes = 256u << 20;
// Largest RAW file read (a 150-megapixel back writes about 300 MB).
inline constexpr std::uintmax_t kMaxRawFileBytes = 1024u << 20;

// Throws InputError "<path>: <problem>" unless `path` names an existing regular file (symlinks
// followed): no such file, a symlink loop, permission denied, a folder, or not a regular file.
// Returns its size in bytes.
std::uintmax_t checkInputFile(const std::filesystem::path& path);

// Reads a whole regular file of at most `max_bytes`; InputError (as checkInputFile, or "is N MB;
// ... limited to M MB") otherwise. Never blocks on a FIFO: the file is opened non-blocking and checked with
// fstat before any read.
std::string readInputFile(const std::filesystem::path& path,
                         std::uintmax_t max_bytes = kMaxTextFileBytes);

}  // namespace flarekit
