#include "common/folder_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

#include "common/error.h"

namespace flarekit {

FolderLock::FolderLock(const std::filesystem::path& folder) {
  const std::filesystem::path file = folder / kFileName;
  fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0)
    throw RuntimeError("cannot create " + file.string() + ": " + std::strerror(errno) +
                       " (is the folder writable?)");
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int error = errno;
    char holder[32] = "";
    const ssize_t n = ::pread(fd_, holder, sizeof holder - 1, 0);
    ::close(fd_);
    fd_ = -1;
    if (error != EWOULDBLOCK) throw RuntimeError("cannot lock " + file.string() + ": " + std::strerror(error));
    const std::string pid = n > 0 ? std::string(holder, static_cast<size_t>(n)) : std::string("unknown");
    throw RuntimeError(folder.string() + ": in use by process " + oneLine(pid) +
                       "; wait for it to finish or stop it");
  }
  // Who holds it, for the message a second process gives (without it, that one says "unknown").
  const std::string pid = std::to_string(::getpid());
  if (::ftruncate(fd_, 0) == 0) (void)!::pwrite(fd_, pid.data(), pid.size(), 0);
}

FolderLock::~FolderLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

}  // namespace flarekit
