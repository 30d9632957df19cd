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

// When a written file reaches the disk. Either way readers, and a writer killed midway, see the
// whole file or none: the rename is atomic.
enum class Durability {
  kFlushed,   // fsync the file before the rename and the folder after it: it survives a power cut
  // Rename only; the data reaches the disk when the kernel writes it back. For writers of many
  // files (export-flares), whose fsync per file would cost more than the work: they call
  // syncFileSystem once before writing the file that says the set is complete.
  kDeferred,
};

// Writes `path` atomically. `write` receives the temporary path (same folder, same extension, so
// writers that choose the format from the extension, such as cv::imwrite, work) and must create
// the file there. If `write` throws, the temporary file is removed, `path` is untouched and the
// exception propagates. Throws RuntimeError when the folder is missing or not writable.
// Thread-safe for different paths.
void writeFileAtomically(const std::filesystem::path& path,
                         const std::function<void(const std::filesystem::path& temporary)>& write,
                         Durability durability = Durability::kFlushed);

// Flushes every written file of the file system that holds `folder` to disk (syncfs(2)).
// Throws RuntimeError naming the folder when that fails.
void syncFileSystem(const std::filesystem::path& folder);

// Writes `content` to `path` atomically.
void writeTextFileAtomically(const std::filesystem::path& path, std::string_view content);

// Removes, under `folder` and its subfolders, the stray temporaries ".<name>.tmp-XXXXXX<ext>" that
// writers killed mid-write left (they belong to no file), so that a folder resumed or written
// again holds only whole files. Errors are ignored: a stray that cannot be removed is harmless.
void removeStrayTemporaries(const std::filesystem::path& folder);

}  // namespace flarekit
