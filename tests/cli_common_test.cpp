// The flarekit command as a user meets it: version, help, exr-info, exit codes, and EXR files
// exchanged with other programs (OpenEXR's own tools, OpenCV).
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/exr.h"
#include "common/testing.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

using testing::lineCount;
using testing::runFlarekit;
using testing::runProgram;
using testing::TempDir;


TEST(Cli, VersionAndHelp) {
  auto v = runFlarekit({"--version"});
  EXPECT_EQ(v.exit_code, 0);
  EXPECT_EQ(v.out.rfind("flarekit ", 0), 0u) << v.out;
  auto h = runFlarekit({"--help"});
  EXPECT_EQ(h.exit_code, 0);
  EXPECT_NE(h.out.find("exr-info"), std::string::npos);
}

TEST(Cli, BadUsageExitsTwoWithOneLine) {
  auto r = runFlarekit({"no-such-command"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  auto none = runFlarekit({});
  EXPECT_EQ(none.exit_code, 2);
  auto missing = runFlarekit({"exr-info"});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_EQ(lineCount(missing.err), 1) << missing.err;
}

TEST(Cli, ExrInfoShowsLayersAttributesAndStatistics) {
  TempDir dir;
  ExrImage image;
  image.layers = {{"", cv::Mat(4, 5, CV_32FC3, cv::Scalar(1, 2, 3))},
                  {"ghost.3", cv::Mat(4, 5, CV_32FC1, cv::Scalar(0.5))}};
  image.attributes["flarekit.angle_deg"] = 7.5;
  writeExr(dir / "a.exr", image);
  auto r = runFlarekit({"exr-info", (dir / "a.exr").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("5 x 4"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("ghost.3.Y"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("flarekit.angle_deg (double): 7.5"), std::string::npos) << r.out;

  auto j = runFlarekit({"exr-info", "--json", (dir / "a.exr").string()});
  ASSERT_EQ(j.exit_code, 0) << j.err;
  auto parsed = nlohmann::json::parse(j.out);
  ASSERT_EQ(parsed.size(), 1u);
  EXPECT_EQ(parsed[0]["layers"], nlohmann::json::array({"", "ghost.3"}));
  for (const auto& c : parsed[0]["channels"])
    if (c["name"] == "B") {
      EXPECT_DOUBLE_EQ(c["mean"].get<double>(), 3.0);
    }

  auto layer = runFlarekit({"exr-info", "--json", "--layer", "ghost.3", (dir / "a.exr").string()});
  ASSERT_EQ(layer.exit_code, 0) << layer.err;
  EXPECT_EQ(nlohmann::json::parse(layer.out)[0]["channels"].size(), 1u);
}

TEST(Cli, OpenExrToolsReadOurFiles) {
  ASSERT_TRUE(testing::onPath("exrheader")) << "exrheader (Debian package openexr) is missing; run scripts/setup.sh";
  TempDir dir;
  writeExr(dir / "a.exr", cv::Mat(3, 3, CV_32FC1, cv::Scalar(1)), {{"flarekit.angle_deg", 1.25}});
  auto r = runProgram("exrheader", {(dir / "a.exr").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("flarekit.angle_deg (type double): 1.25"), std::string::npos) << r.out;
}

TEST(Cli, ExrInfoReadsFilesOfOtherPrograms) {
  TempDir dir;
  cv::Mat bgr(6, 8, CV_32FC3, cv::Scalar(0.25, 0.5, 1.0));
  ASSERT_TRUE(cv::imwrite((dir / "cv.exr").string(), bgr));
  auto r = runFlarekit({"exr-info", (dir / "cv.exr").string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("8 x 6"), std::string::npos) << r.out;

  ASSERT_TRUE(testing::onPath("exrstdattr")) << "exrstdattr (Debian package openexr) is missing";
  auto s = runProgram("exrstdattr", {"-owner", "Someone Else", (dir / "cv.exr").string(),
                                     (dir / "owned.exr").string()});
  ASSERT_EQ(s.exit_code, 0) << s.err;
  auto o = runFlarekit({"exr-info", (dir / "owned.exr").string()});
  EXPECT_EQ(o.exit_code, 0) << o.err;
  EXPECT_NE(o.out.find("owner (string): \"Someone Else\""), std::string::npos) << o.out;
}

// Every bad input: exit code 2, one line naming the file and the problem.
TEST(Cli, BadExrInputsExitTwoWithOneClearLine) {
  TempDir dir;
  { std::ofstream(dir / "text.exr") << "not an image"; }
  writeExr(dir / "good.exr", cv::Mat(64, 64, CV_32FC1, cv::Scalar(1)), {}, ExrWriteOptions{ExrPixelType::kFloat, false});
  std::filesystem::copy_file(dir / "good.exr", dir / "cut.exr");
  std::filesystem::resize_file(dir / "cut.exr", std::filesystem::file_size(dir / "good.exr") / 2);
  cv::Mat nan(4, 4, CV_32FC1, cv::Scalar(0));
  nan.at<float>(1, 2) = std::numeric_limits<float>::quiet_NaN();
  writeExr(dir / "nan.exr", nan);

  struct Case {
    std::vector<std::string> args;
    std::string file, needle;
  };
  std::vector<Case> cases = {
      {{"exr-info", (dir / "missing.exr").string()}, "missing.exr", "no such file"},
      {{"exr-info", (dir / "text.exr").string()}, "text.exr", "not an OpenEXR file"},
      {{"exr-info", (dir / "cut.exr").string()}, "cut.exr", "truncated"},
      {{"exr-info", "--layer", "ghost.9", (dir / "good.exr").string()}, "good.exr", "no layer 'ghost.9'"},
      {{"exr-info", "--require-finite", (dir / "nan.exr").string()}, "nan.exr", "non-finite value at pixel (2, 1)"},
  };
  for (const auto& c : cases) {
    auto r = runFlarekit(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.file << ": " << r.err;
    EXPECT_EQ(lineCount(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(c.file), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(c.needle), std::string::npos) << r.err;
  }
}

// Paths that are not regular files and files that nest without end: every command that reads a
// text input stops at once (the runs time out after 20 s) with one line naming the path.
TEST(Cli, InputsThatAreNotFilesOrNestTooDeepExitTwoAtOnce) {
  TempDir dir;
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
  std::filesystem::create_symlink("loop_b", dir / "loop_a");
  std::filesystem::create_symlink("loop_a", dir / "loop_b");
  { std::ofstream(dir / "deep.json") << std::string(100000, '[') << std::string(100000, ']'); }
  const std::string source = FLAREKIT_SOURCE_DIR;
  const std::string model = source + "/tests/data/model/example_model.json";
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"/dev/zero", "is not a regular file"},
      {(dir / "fifo").string(), "is not a regular file"},
      {(dir / "loop_a").string(), "a loop of symbolic links"},
      {(dir / "deep.json").string(), "nested deeper than 64 levels"}};
  for (const auto& [path, needle] : bad) {
    const std::vector<std::vector<std::string>> commands = {
        {"model-info", path},
        {"lens-info", path},
        {"rig-check", path},
        {"predict", model, "--scene", path, "--out", (dir / "out").string()}};
    for (const auto& args : commands) {
      if (args[0] == "rig-check" && needle.find("nested") != std::string::npos) continue;  // TOML
      auto r = runFlarekit(args, 20);
      EXPECT_EQ(r.exit_code, 2) << args[0] << " " << path << ": " << r.err;
      EXPECT_EQ(lineCount(r.err), 1) << r.err;
      EXPECT_NE(r.err.find("error: " + path + ":"), std::string::npos) << r.err;
      EXPECT_NE(r.err.find(needle), std::string::npos) << args[0] << ": " << r.err;
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out" / "overlay.exr"));
}

// A channel name that is not UTF-8 prints as U+FFFD in exr-info --json, which stays valid JSON.
TEST(Cli, ExrInfoJsonOfANameThatIsNotUtf8) {
  TempDir dir;
  writeExr(dir / "y.exr", cv::Mat(4, 4, CV_32FC1, cv::Scalar(1)), {{"note", std::string("caf\xe9")}});
  auto r = runFlarekit({"exr-info", "--json", (dir / "y.exr").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("caf\xef\xbf\xbd"), std::string::npos) << r.out;
  EXPECT_NO_THROW(nlohmann::json::parse(r.out));
}

}  // namespace
}  // namespace flarekit
