#include "common/atomic_file.h"
#include "common/input_file.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <random>
#include <thread>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"

namespace flarekit {
namespace {

using testing::TempDir;
namespace fs = std::filesystem;

std::string slurp(const fs::path& p) { return readInputFile(p); }

int countEntries(const fs::path& dir) {
  int n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

TEST(AtomicFile, WritesAndReplaces) {
  TempDir dir;
  writeTextFileAtomically(dir / "a.txt", "one");
  EXPECT_EQ(slurp(dir / "a.txt"), "one");
  writeTextFileAtomically(dir / "a.txt", "two");
  EXPECT_EQ(slurp(dir / "a.txt"), "two");
  EXPECT_EQ(countEntries(dir.path()), 1);  // no temporary left behind
}

// What a killed writer leaves, in the folder and below, goes; whole files stay, hidden or not.
TEST(AtomicFile, RemovesStrayTemporariesAndNothingElse) {
  TempDir dir;
  fs::create_directories(dir / "frames");
  std::ofstream(dir / ".manifest.tmp-ab12cd.json") << "{";
  std::ofstream(dir / "frames" / ".frame_0000.tmp-ef34gh.exr") << "half";
  writeTextFileAtomically(dir / "manifest.json", "{}");
  writeTextFileAtomically(dir / "frames" / "frame_0000.exr", "whole");
  writeTextFileAtomically(dir / ".hidden", "kept");
  writeTextFileAtomically(dir / "notes.tmp-1.txt", "kept");
  removeStrayTemporaries(dir.path());
  EXPECT_FALSE(fs::exists(dir / ".manifest.tmp-ab12cd.json"));
  EXPECT_FALSE(fs::exists(dir / "frames" / ".frame_0000.tmp-ef34gh.exr"));
  EXPECT_EQ(slurp(dir / "manifest.json"), "{}");
  EXPECT_EQ(slurp(dir / "frames" / "frame_0000.exr"), "whole");
  EXPECT_EQ(slurp(dir / ".hidden"), "kept");
  EXPECT_EQ(slurp(dir / "notes.tmp-1.txt"), "kept");
  EXPECT_EQ(countEntries(dir.path()), 4);
  EXPECT_EQ(countEntries(dir / "frames"), 1);
}

TEST(AtomicFile, FailedWriterLeavesOldFileAndNoTemporary) {
  TempDir dir;
  writeTextFileAtomically(dir / "a.txt", "old");
  EXPECT_THROW(writeFileAtomically(dir / "a.txt",
                                   [](const fs::path& t) {
                                     std::ofstream(t) << "half of the new cont";
                                     throw RuntimeError("disk on fire");
                                   }),
               RuntimeError);
  EXPECT_EQ(slurp(dir / "a.txt"), "old");
  EXPECT_EQ(countEntries(dir.path()), 1);
}

TEST(AtomicFile, MissingFolderIsAClearRuntimeError) {
  TempDir dir;
  try {
    writeTextFileAtomically(dir / "no" / "such" / "a.txt", "x");
    FAIL();
  } catch (const RuntimeError& e) {
    EXPECT_NE(std::string(e.what()).find("does not exist"), std::string::npos) << e.what();
  }
}

TEST(AtomicFile, TemporaryKeepsTheExtension) {
  TempDir dir;
  fs::path seen;
  writeFileAtomically(dir / "frame.exr", [&](const fs::path& t) {
    seen = t;
    std::ofstream(t) << "x";
  });
  EXPECT_EQ(seen.extension(), ".exr");
  EXPECT_EQ(seen.parent_path(), dir.path());
}

// A writer killed after writing but before the rename leaves the old file.
TEST(AtomicFile, KilledBetweenWritingAndRenamingLeavesOldFile) {
  TempDir dir;
  writeTextFileAtomically(dir / "a.txt", "old content");
  pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    writeFileAtomically(dir / "a.txt", [](const fs::path& t) {
      std::ofstream(t) << "new content, complete";
      ::kill(::getpid(), SIGKILL);  // dies here: written, not yet renamed
    });
    _exit(0);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(slurp(dir / "a.txt"), "old content");
}

// Killed at random moments while rewriting, the file always holds one complete version.
TEST(AtomicFile, KilledAtRandomMomentsNeverLeavesAPartialFile) {
  TempDir dir;
  const size_t kSize = 1 << 20;
  writeTextFileAtomically(dir / "big.txt", std::string(kSize, 'a'));
  std::mt19937 rng(42);
  for (int trial = 0; trial < 12; ++trial) {
    pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      for (char c = 'b';; c = c == 'z' ? 'b' : char(c + 1))
        writeTextFileAtomically(dir / "big.txt", std::string(kSize, c));
    }
    std::this_thread::sleep_for(std::chrono::microseconds(2000 + rng() % 30000));
    ::kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    std::string content = slurp(dir / "big.txt");
    ASSERT_EQ(content.size(), kSize) << "trial " << trial;
    EXPECT_EQ(content.find_first_not_of(content[0]), std::string::npos) << "trial " << trial;
  }
}

TEST(AtomicFile, DeferredWritesAreWholeOrNothingToo) {
  TempDir dir;
  auto write = [&](const std::string& text) {
    writeFileAtomically(
        dir / "a.txt", [&](const fs::path& t) { std::ofstream(t) << text; }, Durability::kDeferred);
  };
  write("one");
  write("two");
  EXPECT_EQ(slurp(dir / "a.txt"), "two");
  EXPECT_THROW(writeFileAtomically(
                   dir / "a.txt",
                   [](const fs::path& t) {
                     std::ofstream(t) << "half";
                     throw RuntimeError("writer failed");
                   },
                   Durability::kDeferred),
               RuntimeError);
  EXPECT_EQ(slurp(dir / "a.txt"), "two");
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path()), fs::directory_iterator()), 1);
  EXPECT_NO_THROW(syncFileSystem(dir.path()));
  EXPECT_THROW(syncFileSystem(dir / "missing"), RuntimeError);
}

TEST(AtomicFile, KilledExrWriterLeavesReadableOldFile) {
  TempDir dir;
  cv::Mat old(64, 64, CV_32F, cv::Scalar(1.0f));
  writeExr(dir / "f.exr", old);
  pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    cv::Mat big(1500, 1500, CV_32FC3, cv::Scalar::all(2.0f));
    for (;;) writeExr(dir / "f.exr", big);
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(150));
  ::kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
  ExrImage back = readExr(dir / "f.exr");
  EXPECT_TRUE(back.main().cols == 64 || back.main().cols == 1500);
}

}  // namespace
}  // namespace flarekit
