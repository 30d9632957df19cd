#include "common/shipped_file.h"

#include <fstream>

#include <gtest/gtest.h>

#include "common/testing.h"

namespace flarekit {
namespace {

TEST(ShippedFile, PreferredThenWorkingFolderThenSourceTree) {
  testing::TempDir dir;
  const auto cwd = std::filesystem::current_path();
  std::filesystem::current_path(dir.path());
  // Only in the source tree: found there.
  auto rig = findShippedFile("rigs/sim-heliar.toml");
  ASSERT_TRUE(rig.has_value());
  EXPECT_EQ(*rig, std::filesystem::path(FLAREKIT_SOURCE_DIR) / "rigs/sim-heliar.toml");
  // A copy in the working folder wins over the source tree, a preferred path over both.
  std::filesystem::create_directories("rigs");
  std::ofstream("rigs/sim-heliar.toml") << "name = \"x\"\n";
  EXPECT_EQ(*findShippedFile("rigs/sim-heliar.toml"), std::filesystem::path("rigs/sim-heliar.toml"));
  std::ofstream("mine.toml") << "name = \"y\"\n";
  EXPECT_EQ(*findShippedFile("rigs/sim-heliar.toml", {"mine.toml", "missing.toml"}), std::filesystem::path("mine.toml"));
  EXPECT_FALSE(findShippedFile("rigs/no-such-rig.toml").has_value());
  std::filesystem::current_path(cwd);
}

}  // namespace
}  // namespace flarekit
