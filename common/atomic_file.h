#pragma once
// Every file FlareKit writes appears whole or not at all (docs/design.md, Conventions): the
// content goes to a temporary name in the same folder, is flushed and fsynced, and is renamed over
// the target; the folder is fsynced so the rename survives a crash. A writer killed at any moment
// leaves the old file (or none) and at worst a stray ".<name>.tmp-XXXXXX" beside it.

#include <filesystem>
#include <functional>
#include <string_view>

namespace flarekit {

// Throws RuntimeError (the same lines writeFileAtomically gives) when `path` could not be written:
// its folder is missing or not writable, or `path` is a folder. Long commands call it before their
// work, so a mistyped --out fails at once and not after minutes of fitting.
void checkWritable(const std::filesystem::path& path);

// Creates an output folder and its parents, or checks that an existing one is writable. Throws
// RuntimeError "cannot create folder <folder>: <reason>" (a read-only disk, a file in the way).
void createFolder(const std::filesystem::path& folder);

// Writes `path` atomically. `write` receives the temporary path (same folder, same extension, so
// writers that choose the format from the extension, such as cv::imwrite, work) and must create
// the file there. If `write` throws, the temporary file is removed, `path` is untouched and the
// exception propagates. Throws RuntimeError when the folder is missing or not writable.
// Thread-safe for different paths.
void writeFileAtomically(const std::filesystem::path& path,
                         const std::function<void(const std::filesystem::path& temporary)>& write);

// Writes `content` to `path` atomically.
void writeTextFileAtomically(const std::filesystem::path& path, std::string_view content);

// Removes, under `folder` and its subfolders, the stray temporaries ".<name>.tmp-XXXXXX<ext>" that
// writers killed mid-write left (they belong to no file), so that a folder resumed or written
// again holds only whole files. Errors are ignored: a stray that cannot be removed is harmless.
void removeStrayTemporaries(const std::filesystem::path& folder);

}  // namespace flarekit
