// flarekit export-flares as a user meets it: a set written by one run and by shards in separate
// processes, bad input, and the benchmark.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/testing.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;
using testing::lineCount;
using testing::runFlarekit;
using testing::filesUnder;
using testing::TempDir;

const std::string kNikon = std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/view/nikon_model.json";
const std::string kHeliar = std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/view/demo_model.json";


std::vector<std::string> exportArgs(const fs::path& out, const std::string& count) {
  return {"-q", "export-flares", kNikon, kHeliar, "--count", count, "--size", "96x64", "--seed", "11",
          "--out", out.string()};
}

TEST(CliDataset, ShardsFromSeparateRunsAreTheWholeSetBitForBit) {
  TempDir whole, parts;
  auto r = runFlarekit(exportArgs(whole.path(), "7"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // As a Slurm job array runs it: three processes, one folder.
  std::string jsonl;
  for (const char* shard : {"1/3", "2/3", "3/3"}) {
    auto args = exportArgs(parts.path(), "7");
    args.insert(args.end(), {"--shard", shard});
    auto s = runFlarekit(args);
    ASSERT_EQ(s.exit_code, 0) << shard << ": " << s.err;
  }
  auto all = filesUnder(whole.path()), union_of_parts = filesUnder(parts.path());
  for (int k = 1; k <= 3; ++k) jsonl += union_of_parts.at("samples." + std::to_string(k) + "-of-3.jsonl");
  EXPECT_EQ(jsonl, all.at("samples.jsonl"));
  EXPECT_EQ(std::count(jsonl.begin(), jsonl.end(), '\n'), 7);
  for (auto* files : {&all, &union_of_parts})
    for (auto it = files->begin(); it != files->end();)
      it = it->first.rfind("samples", 0) == 0 ? files->erase(it) : std::next(it);
  EXPECT_GT(all.size(), 7u * 5);
  EXPECT_TRUE(all == union_of_parts);
  // The same command again writes the same bytes.
  TempDir again;
  ASSERT_EQ(runFlarekit(exportArgs(again.path(), "7")).exit_code, 0);
  EXPECT_TRUE(filesUnder(again.path()) == filesUnder(whole.path()));
  // Flare7K's loaders pair Compound_Flare/ and Light_Source/ by sorted names.
  for (const char* folder : {"Flare", "Light_Source", "Compound_Flare"}) {
    const cv::Mat png = cv::imread((whole.path() / folder / "000006.png").string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(png.empty()) << folder;
    EXPECT_EQ(png.size(), cv::Size(96, 64));
  }
}

TEST(CliDataset, BadInputIsOneLineAndExitTwo) {
  TempDir dir;
  const std::string out = (dir / "set").string();
  {
    std::ofstream(dir / "garbage.json") << "{ not json";
    std::ofstream(dir / "lens.json") << R"({"format": "flarekit.lens", "version": 1})";
  }
  struct Case {
    std::string name;
    std::vector<std::string> args;
    std::string expect;  // in the message
  };
  const std::vector<Case> cases = {
      {"zero count", {"export-flares", kHeliar, "--count", "0", "--out", out}, "--count"},
      {"negative count", {"export-flares", kHeliar, "--count", "-3", "--out", out}, "count"},
      {"missing model", {"export-flares", (dir / "nope.json").string(), "--count", "2", "--out", out}, "nope.json"},
      {"invalid model", {"export-flares", (dir / "garbage.json").string(), "--count", "2", "--out", out}, "garbage.json"},
      {"not a model", {"export-flares", kHeliar, (dir / "lens.json").string(), "--count", "2", "--out", out}, "lens.json"},
      {"bad size", {"export-flares", kHeliar, "--count", "2", "--size", "512", "--out", out}, "--size"},
      {"bad shard", {"export-flares", kHeliar, "--count", "2", "--shard", "4/3", "--out", out}, "--shard"},
      {"zero shard", {"export-flares", kHeliar, "--count", "2", "--shard", "0/3", "--out", out}, "--shard"},
      {"bad exposure", {"export-flares", kHeliar, "--count", "2", "--ev-min", "4", "--ev-max", "1", "--out", out}, "exposure"},
  };
  for (const auto& c : cases) {
    auto r = runFlarekit(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.err;
    EXPECT_EQ(lineCount(r.err), 1) << c.name << ": " << r.err;
    EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.name << ": " << r.err;
  }
  EXPECT_FALSE(fs::exists(dir / "set" / "Flare")) << "bad input wrote samples";
  // A folder that holds another set.
  ASSERT_EQ(runFlarekit({"-q", "export-flares", kHeliar, "--count", "2", "--size", "32x32", "--out", out}).exit_code, 0);
  auto other = runFlarekit({"export-flares", kHeliar, "--count", "3", "--size", "32x32", "--out", out});
  EXPECT_EQ(other.exit_code, 2) << other.err;
  EXPECT_EQ(lineCount(other.err), 1) << other.err;
  EXPECT_NE(other.err.find("dataset.json"), std::string::npos) << other.err;
}

TEST(CliDataset, BenchPrintsOneJsonObject) {
  auto r = runFlarekit({"-q", "bench", "export-flares", kHeliar, "--count", "4", "--size", "64x64", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["benchmark"], "export-flares");
  EXPECT_EQ(j["samples"], 4);
  EXPECT_GT(j["samples_per_s"].get<double>(), 0);
  EXPECT_FALSE(fs::exists(j["folder"].get<std::string>())) << "the benchmark left its set behind";
  EXPECT_EQ(runFlarekit({"bench", "export-flares", kHeliar, "--count", "0"}).exit_code, 2);
}

}  // namespace
}  // namespace flarekit
