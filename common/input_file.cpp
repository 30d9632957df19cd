#include "common/input_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "common/error.h"

namespace flarekit {
namespace {

[[noreturn]] void failOpen(const std::filesystem::path& path, int error) {
  switch (error) {
    case ENOENT: throw InputError(path.string(), "no such file");
    case ENOTDIR: throw InputError(path.string(), "no such file (a part of the path is not a folder)");
    case ELOOP: throw InputError(path.string(), "cannot open: a loop of symbolic links");
    case EACCES: throw InputError(path.string(), "cannot open: permission denied");
    case ENAMETOOLONG: throw InputError(path.string(), "cannot open: the name is too long");
    default: throw InputError(path.string(), std::string("cannot open: ") + std::strerror(error));
  }
}

void checkStat(const std::filesystem::path& path, const struct stat& st) {
  if (S_ISDIR(st.st_mode)) throw InputError(path.string(), "is a folder, not a file");
  if (!S_ISREG(st.st_mode))
    throw InputError(path.string(), "is not a regular file (a device, FIFO or socket)");
}

std::string megabytes(std::uintmax_t bytes) { return std::to_string(bytes >> 20) + " MB"; }

}  // namespace

std::uintmax_t checkInputFile(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) failOpen(path, errno);
  checkStat(path, st);
  return static_cast<std::uintmax_t>(st.st_size);
}

std::string readInputFile(const std::filesystem::path& path, std::uintmax_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) failOpen(path, errno);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) failOpen(path, errno);
  checkStat(path, st);
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes)
    throw InputError(path.string(), "is " + megabytes(st.st_size) + "; inputs of this kind are limited to " +
                                        megabytes(max_bytes));
  std::string text;
  text.reserve(static_cast<size_t>(st.st_size));
  char buffer[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      throw InputError(path.string(), std::string("cannot read: ") + std::strerror(errno));
    }
    text.append(buffer, static_cast<size_t>(n));
    if (text.size() > max_bytes)  // grew while being read
      throw InputError(path.string(), "grew beyond the " + megabytes(max_bytes) + " inputs of this kind are limited to");
  }
  return text;
}

}  // namespace flarekit
