#include "common/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <random>
#include <vector>

#include "common/error.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;

std::string errnoText() { return std::strerror(errno); }

// fsyncs an existing file or folder; throws RuntimeError naming `what`.
void syncPath(const fs::path& p, bool directory) {
  int fd = ::open(p.c_str(), directory ? (O_RDONLY | O_DIRECTORY) : O_RDONLY);
  if (fd < 0) throw RuntimeError("cannot open " + p.string() + " to flush it: " + errnoText());
  int rc = ::fsync(fd);
  int saved = errno;
  ::close(fd);
  // Some file systems do not support fsync on folders (EINVAL); the rename is still atomic.
  if (rc != 0 && !(directory && saved == EINVAL))
    throw RuntimeError("cannot flush " + p.string() + " to disk: " + std::strerror(saved));
}

fs::path temporaryNameFor(const fs::path& path) {
  static thread_local std::mt19937_64 rng{std::random_device{}() ^
                                          static_cast<unsigned long>(::getpid())};
  static constexpr char kAlphabet[] = "abcdefghijklmnopqrstuvwxyz0123456789";
  std::string tag;
  for (int i = 0; i < 6; ++i) tag += kAlphabet[rng() % (sizeof(kAlphabet) - 1)];
  // ".<stem>.tmp-XXXXXX<ext>": hidden, and keeps the extension for format-by-extension writers.
  std::string name = ".";
  name.append(path.stem().string()).append(".tmp-").append(tag).append(path.extension().string());
  return path.parent_path() / name;
}

}  // namespace

void removeStrayTemporaries(const fs::path& folder) {
  std::error_code ec;
  std::vector<fs::path> stray;
  for (auto it = fs::recursive_directory_iterator(folder, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    const std::string n = it->path().filename().string();
    // The names temporaryNameFor makes.
    if (it->is_regular_file() && n.size() > 1 && n[0] == '.' && n.find(".tmp-") != std::string::npos)
      stray.push_back(it->path());
  }
  for (const auto& p : stray) fs::remove(p, ec);
}

void checkWritable(const fs::path& path) {
  fs::path folder = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw RuntimeError("cannot write " + path.string() + ": folder " + folder.string() +
                       " does not exist; create it first");
  if (::access(folder.c_str(), W_OK) != 0)
    throw RuntimeError("cannot write " + path.string() + ": folder " + folder.string() +
                       " is not writable (" + errnoText() + ")");
  if (fs::is_directory(path, ec))
    throw RuntimeError("cannot write " + path.string() + ": it is a folder");
}

void createFolder(const fs::path& folder) {
  std::error_code ec;
  if (fs::is_directory(folder, ec)) {
    if (::access(folder.c_str(), W_OK) != 0)
      throw RuntimeError("cannot write in folder " + folder.string() + ": " + errnoText());
    return;
  }
  fs::create_directories(folder, ec);
  if (ec) throw RuntimeError("cannot create folder " + folder.string() + ": " + ec.message());
}

void writeFileAtomically(const fs::path& path,
                         const std::function<void(const fs::path& temporary)>& write,
                         Durability durability) {
  const bool flush = durability == Durability::kFlushed;
  checkWritable(path);
  const fs::path folder = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  fs::path temporary = temporaryNameFor(path.parent_path().empty() ? fs::path(".") / path : path);
  try {
    write(temporary);
    if (std::error_code ec; !fs::exists(temporary, ec))
      throw RuntimeError("writing " + path.string() + " produced no file");
    if (flush) syncPath(temporary, false);
    if (::rename(temporary.c_str(), path.c_str()) != 0)
      throw RuntimeError("cannot rename " + temporary.string() + " to " + path.string() + ": " +
                         errnoText());
  } catch (...) {
    std::error_code ec;
    fs::remove(temporary, ec);
    throw;
  }
  if (flush) syncPath(folder, true);
}

void syncFileSystem(const fs::path& folder) {
  const int fd = ::open(folder.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) throw RuntimeError("cannot open " + folder.string() + " to flush it: " + errnoText());
  const int rc = ::syncfs(fd);
  const int saved = errno;
  ::close(fd);
  if (rc != 0)
    throw RuntimeError("cannot flush the files in " + folder.string() + " to disk: " + std::strerror(saved));
}

void writeTextFileAtomically(const fs::path& path, std::string_view content) {
  writeFileAtomically(path, [&](const fs::path& temporary) {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    if (!out) throw RuntimeError("cannot create " + temporary.string() + ": " + errnoText());
    out.write(content.data(), static_cast<std::streamsize>(content.size()));
    out.flush();
    if (!out) throw RuntimeError("cannot write " + path.string() + ": " + errnoText() +
                                 " (is the disk full?)");
  });
}

}  // namespace flarekit
