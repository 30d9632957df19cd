#pragma once
// An exclusive lock on a folder for as long as the object lives, so that two processes never
// work in one folder (two captures would drive the same head and camera). It is flock(2) on
// FOLDER/.flarekit.lock, which records the holder's process id; the kernel drops the lock when
// the holder exits or is killed (SIGKILL too), so a lock never lingers. The file itself stays.

#include <filesystem>

namespace flarekit {

class FolderLock {
 public:
  // Takes the lock; the folder must exist. Throws RuntimeError "<folder>: in use by process PID;
  // wait for it to finish or stop it" when another process holds it, RuntimeError when the lock
  // file cannot be made (a read-only folder).
  explicit FolderLock(const std::filesystem::path& folder);
  ~FolderLock();
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

  static constexpr char kFileName[] = ".flarekit.lock";

 private:
  int fd_ = -1;
};

}  // namespace flarekit
