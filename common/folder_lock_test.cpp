#include "common/folder_lock.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "common/error.h"
#include "common/testing.h"

namespace flarekit {
namespace {

std::string lockError(const std::filesystem::path& folder) {
  try {
    FolderLock second(folder);
  } catch (const RuntimeError& e) {
    return e.what();
  }
  return "no error";
}

TEST(FolderLock, ASecondHolderIsRefusedWithTheFirstOnesProcess) {
  testing::TempDir dir;
  {
    FolderLock first(dir.path());
    EXPECT_EQ(lockError(dir.path()), dir.path().string() + ": in use by process " +
                                         std::to_string(::getpid()) + "; wait for it to finish or stop it");
  }
  EXPECT_EQ(lockError(dir.path()), "no error");  // released with the first
}

// The kernel drops the lock of a killed holder: nothing lingers after SIGKILL.
TEST(FolderLock, DoesNotOutliveAKilledHolder) {
  testing::TempDir dir;
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    FolderLock lock(dir.path());
    (void)!::write(ready[1], "x", 1);
    for (;;) ::pause();
  }
  char c;
  ASSERT_EQ(::read(ready[0], &c, 1), 1);
  EXPECT_NE(lockError(dir.path()).find("in use by process " + std::to_string(child)), std::string::npos);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  EXPECT_EQ(lockError(dir.path()), "no error");
  ::close(ready[0]);
  ::close(ready[1]);
}

TEST(FolderLock, NamesAFolderItCannotLock) {
  testing::TempDir dir;
  EXPECT_THROW(FolderLock(dir / "missing"), RuntimeError);
}

}  // namespace
}  // namespace flarekit
