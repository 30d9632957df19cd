// The ghost-model commands as a user meets them: flarekit render, model-info, bench model, and
// what happens with bad model files.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/exr.h"
#include "common/testing.h"
#include "model/flare_model.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

using testing::lineCount;
using testing::runFlarekit;
using testing::TempDir;

const std::string kExample = std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/model/example_model.json";


TEST(CliModel, RenderWritesTheModelImageWithMetadataAndPreview) {
  TempDir dir;
  const auto out = dir / "flare.exr";
  const auto preview = dir / "flare.png";
  auto r = runFlarekit({"render", kExample, "--angle", "10", "--out", out.string(), "--preview", preview.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const ExrImage image = readExr(out);
  const cv::Mat& m = image.main();
  ASSERT_EQ(m.type(), CV_32FC3);
  EXPECT_EQ(m.size(), cv::Size(320, 200));
  // The same as the library renders.
  const model::FlareModel model = model::FlareModel::load(kExample);
  EXPECT_LE(cv::norm(m, model.render(10), cv::NORM_INF), 0.0);
  EXPECT_GT(cv::sum(m)[0], 100);
  EXPECT_EQ(numericAttribute(image.attributes, "flarekit.angle_deg"), 10.0);
  EXPECT_EQ(numericAttribute(image.attributes, "flarekit.exposure_s"), 0.5);
  const cv::Mat png = cv::imread(preview.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(png.empty());
  EXPECT_EQ(png.size(), cv::Size(320, 200));
}

TEST(CliModel, RenderWithRollAndSize) {
  TempDir dir;
  const auto upright = dir / "upright.exr", rolled = dir / "rolled.exr", small = dir / "small.exr";
  ASSERT_EQ(runFlarekit({"render", kExample, "--angle", "5", "--out", upright.string()}).exit_code, 0);
  ASSERT_EQ(runFlarekit({"render", kExample, "--angle", "5", "--roll", "90", "--out", rolled.string()}).exit_code, 0);
  auto r = runFlarekit({"render", kExample, "--angle", "5", "--width", "160", "--height", "100", "--out", small.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const cv::Mat a = readExrLayer(upright, ""), b = readExrLayer(rolled, ""), c = readExrLayer(small, "");
  EXPECT_EQ(c.size(), cv::Size(160, 100));
  // Roll changes the picture but not the light in it (the ghosts stay inside the frame here).
  EXPECT_GT(cv::norm(a, b, cv::NORM_INF), 0.1);
  EXPECT_NEAR(cv::sum(b)[1], cv::sum(a)[1], 0.02 * cv::sum(a)[1]);
  // A 90° roll turns the flare's spread along x into its spread along y and back.
  auto spread = [](const cv::Mat& m, bool along_y) {
    cv::Mat g;
    cv::extractChannel(m, g, 1);
    const cv::Moments mo = cv::moments(g);
    return (along_y ? mo.mu02 : mo.mu20) / mo.m00;
  };
  EXPECT_NEAR(spread(b, true), spread(a, false), 0.03 * spread(a, false));
  EXPECT_NEAR(spread(b, false), spread(a, true), 0.03 * spread(a, true));
  EXPECT_GT(spread(a, false), 1.2 * spread(a, true));  // the test means something
}

TEST(CliModel, OutsideEveryRangeRendersBlack) {
  TempDir dir;
  const auto out = dir / "none.exr";
  ASSERT_EQ(runFlarekit({"render", kExample, "--angle", "-40", "--out", out.string()}).exit_code, 0);
  EXPECT_EQ(cv::norm(readExrLayer(out, ""), cv::NORM_INF), 0.0);
}

TEST(CliModel, ModelInfoShowsGhostsRangesAndParameters) {
  auto text = runFlarekit({"model-info", kExample, "--angle", "10"});
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("3 ghosts"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("ghost 9"), std::string::npos) << text.out;
  auto json = runFlarekit({"model-info", kExample, "--angle", "-18", "--json"});
  ASSERT_EQ(json.exit_code, 0) << json.err;
  const nlohmann::json j = nlohmann::json::parse(json.out);
  ASSERT_EQ(j["ghosts"].size(), 3u);
  EXPECT_EQ(j["channels"], 3);
  EXPECT_TRUE(j["ghosts"][0]["present"].get<bool>());   // ghost 2: −20 .. 20
  EXPECT_FALSE(j["ghosts"][1]["present"].get<bool>());  // ghost 5: −15 .. 25
  EXPECT_FALSE(j["ghosts"][2]["present"].get<bool>());  // ghost 9: 0 .. 30
  // Mx of ghost 2 at −18°: 160 − 2.5·(−18) + 0.01·18².
  EXPECT_DOUBLE_EQ(j["ghosts"][0]["parameters"]["Mx"].get<double>(), 160 + (-2.5 + 0.01 * -18) * -18);
  EXPECT_EQ(j["capture"]["image_width"], 320);
}

TEST(CliModel, BadModelFilesExitTwoWithOneClearLine) {
  TempDir dir;
  nlohmann::json good = nlohmann::json::parse(std::ifstream(kExample));
  struct Case {
    std::string name;
    std::function<void(nlohmann::json&)> edit;
    std::string expect;
  };
  const std::vector<Case> cases = {
      {"wrong_format", [](auto& j) { j["format"] = "flarekit.manifest"; }, "format"},
      {"wrong_version", [](auto& j) { j["version"] = 9; }, "version"},
      {"missing_field", [](auto& j) { j["capture"].erase("iso"); }, "iso"},
      {"nan_coefficient", [](auto& j) { j["ghosts"][2]["parameters"]["Fi"] = {nullptr}; }, "Fi"},
      {"negative_size", [](auto& j) { j["ghosts"][1]["parameters"]["L"] = {-30}; }, "L"},
      {"negative_image_size", [](auto& j) { j["capture"]["image_height"] = -200; }, "image_height"},
      {"empty_angle_range", [](auto& j) { j["ghosts"][0]["angle_min_deg"] = 50; }, "empty angle range"},
      {"negative_focal_length", [](auto& j) { j["capture"]["focal_length_mm"] = -50; }, "focal_length_mm"},
  };
  for (const Case& c : cases) {
    nlohmann::json j = good;
    c.edit(j);
    const std::string path = (dir / (c.name + ".json")).string();
    std::ofstream(path) << j.dump(2);
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"render", path, "--angle", "0", "--out", (dir / "x.exr").string()},
          std::vector<std::string>{"model-info", path}}) {
      auto r = runFlarekit(args);
      EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.err;
      EXPECT_EQ(lineCount(r.err), 1) << c.name << ": " << r.err;
      EXPECT_NE(r.err.find(path), std::string::npos) << c.name << ": " << r.err;
      EXPECT_NE(r.err.find(c.expect), std::string::npos) << c.name << ": " << r.err;
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "x.exr")) << c.name;
  }
  // Not JSON, and a missing file.
  const std::string garbage = (dir / "garbage.json").string();
  std::ofstream(garbage) << "not json";
  auto g = runFlarekit({"model-info", garbage});
  EXPECT_EQ(g.exit_code, 2);
  EXPECT_EQ(lineCount(g.err), 1) << g.err;
  auto missing = runFlarekit({"render", (dir / "nope.json").string(), "--angle", "0", "--out", (dir / "y.exr").string()});
  EXPECT_EQ(missing.exit_code, 2);
  // Bad options.
  auto no_height = runFlarekit({"render", kExample, "--angle", "0", "--width", "100", "--out", (dir / "z.exr").string()});
  EXPECT_EQ(no_height.exit_code, 2);
  EXPECT_EQ(lineCount(no_height.err), 1) << no_height.err;
  auto nan_angle = runFlarekit({"render", kExample, "--angle", "nan", "--out", (dir / "z.exr").string()});
  EXPECT_EQ(nan_angle.exit_code, 2) << nan_angle.err;
}

TEST(CliModel, BenchModelPrintsOneJsonObject) {
  // Tiny sizes: this checks the command and its fields, not the speed (bench/ and the report do).
  auto r = runFlarekit({"bench", "model", "--ghosts", "3", "--width", "160", "--height", "90",
                        "--min-radius", "5", "--max-radius", "12", "--repeats", "1", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"ms_render", "ms_render_with_derivatives", "pixels_per_s", "threads"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_GT(j["ms_render"].get<double>(), 0);
  EXPECT_GE(j["threads"].get<int>(), 1);
  EXPECT_EQ(runFlarekit({"bench", "model", "--ghosts", "0"}).exit_code, 2);
}

}  // namespace
}  // namespace flarekit
