#include "common/input_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>

#include "common/error.h"
#include "common/testing.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;

std::string messageOf(const fs::path& path, std::uintmax_t max_bytes = kMaxTextFileBytes) {
  try {
    readInputFile(path, max_bytes);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

TEST(InputFile, ReadsARegularFileWhole) {
  testing::TempDir dir;
  std::ofstream(dir / "lens.json") << "{\"a\": 1}\n";
  EXPECT_EQ(readInputFile(dir / "lens.json"), "{\"a\": 1}\n");
  EXPECT_EQ(checkInputFile(dir / "lens.json"), 9u);
}

TEST(InputFile, NamesTheFileAndTheProblem) {
  testing::TempDir dir;
  EXPECT_EQ(messageOf(dir / "missing.json"), (dir / "missing.json").string() + ": no such file");
  EXPECT_EQ(messageOf(dir.path()), dir.path().string() + ": is a folder, not a file");
  fs::create_symlink("loop_b", dir / "loop_a");
  fs::create_symlink("loop_a", dir / "loop_b");
  EXPECT_EQ(messageOf(dir / "loop_a"), (dir / "loop_a").string() + ": cannot open: a loop of symbolic links");
  EXPECT_THROW(checkInputFile(dir / "loop_a"), InputError);
}

// A device or FIFO would read without end or block; both fail at once.
TEST(InputFile, RefusesDevicesAndFifos) {
  testing::TempDir dir;
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
  EXPECT_EQ(messageOf(dir / "fifo"), (dir / "fifo").string() + ": is not a regular file (a device, FIFO or socket)");
  EXPECT_EQ(messageOf("/dev/zero"), "/dev/zero: is not a regular file (a device, FIFO or socket)");
  EXPECT_THROW(checkInputFile(dir / "fifo"), InputError);
}

TEST(InputFile, RefusesAFileAboveTheLimit) {
  testing::TempDir dir;
  std::ofstream(dir / "big.json") << std::string(3u << 20, ' ');
  EXPECT_EQ(messageOf(dir / "big.json", 2u << 20),
            (dir / "big.json").string() + ": is 3 MB; inputs of this kind are limited to 2 MB");
  EXPECT_EQ(readInputFile(dir / "big.json", 4u << 20).size(), 3u << 20);
}

}  // namespace
}  // namespace flarekit
