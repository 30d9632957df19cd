// `flarekit predict` as a light planner runs it: the files it writes, the report in a real browser
// (Debian's chromium, headless), and bad scenes that exit 2 with one clear line.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/exr.h"
#include "common/image.h"
#include "common/testing.h"
#include "predict/report.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

using nlohmann::json;
using testing::lineCount;
using testing::runFlarekit;
using testing::runProgram;
using testing::TempDir;
using testing::chromiumArgs;
using testing::consoleLines;

const std::filesystem::path kSource = FLAREKIT_SOURCE_DIR;
const std::filesystem::path kModel = kSource / "tests/data/predict/test_model.json";
const std::filesystem::path kScene = kSource / "predict/examples/stage.json";


std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

TEST(CliPredict, WritesOverlayCompositeEstimatorsAndReport) {
  TempDir dir;
  auto r = runFlarekit({"predict", kModel.string(), "--scene", kScene.string(), "--out", (dir / "out").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("report.html"), std::string::npos) << r.out;
  // overlay.exr: linear float RGB at the model's capture width and the scene's 3:2 sensor.
  const cv::Mat overlay = readExrLayer(dir / "out/overlay.exr", "");
  EXPECT_EQ(overlay.size(), cv::Size(640, 427));
  EXPECT_EQ(overlay.type(), CV_32FC3);
  const cv::Mat png = cv::imread((dir / "out/composite.png").string());
  EXPECT_EQ(png.size(), overlay.size());
  const json e = json::parse(readFile(dir / "out/estimators.json"));
  // The example's lights: four within the model's range, the off-stage flood out of range and
  // the follow spot behind the camera.
  std::map<std::string, std::string> status;
  for (const auto& l : e["lights"]) status[l["name"]] = l["status"];
  EXPECT_EQ(status["key spot"], "in range");
  EXPECT_EQ(status["flood (off-stage)"], "out of range");
  EXPECT_EQ(status["follow spot (behind)"], "behind camera");
  // The overlay file and the estimators agree: mean luminance of the overlay.
  EXPECT_NEAR(cv::mean(luminance(overlay))[0], e["estimators"]["mean"].get<double>(),
              1e-5 * e["estimators"]["mean"].get<double>());
  for (const auto& [name, rating] : e["ratings"].items()) {
    ASSERT_TRUE(rating["percentile"].is_number()) << name;
    EXPECT_GE(rating["percentile"].get<double>(), 0);
    EXPECT_LE(rating["percentile"].get<double>(), 100);
  }
  EXPECT_EQ(e["timeline"].size(), 17u);
}

TEST(CliPredict, ReportOpensOfflineInChromiumWithMapAndImages) {
  ASSERT_TRUE(testing::onPath("chromium")) << "chromium (Debian package) is missing; run scripts/setup.sh";
  TempDir dir;
  auto r = runFlarekit({"predict", kModel.string(), "--scene", kScene.string(), "--out", (dir / "out").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string url = "file://" + (dir / "out/report.html").string();

  // The DOM after loading: no console messages, the map, both images and every light.
  auto args = chromiumArgs((dir / "profile-dom").string());
  args.push_back("--dump-dom");
  args.push_back(url);
  auto dom = runProgram("chromium", args, 120);
  ASSERT_EQ(dom.exit_code, 0) << dom.err;
  EXPECT_TRUE(consoleLines(dom.err).empty()) << consoleLines(dom.err).front();
  EXPECT_NE(dom.out.find("id=\"severity-map\""), std::string::npos);
  EXPECT_NE(dom.out.find("id=\"severity-timeline\""), std::string::npos);
  EXPECT_NE(dom.out.find("id=\"overlay\""), std::string::npos);
  EXPECT_NE(dom.out.find("data:image/png;base64,"), std::string::npos);
  // Each light in range links to the viewer beside the report at its θ and φ.
  EXPECT_TRUE(std::filesystem::exists(dir / "out/view.html"));
  EXPECT_NE(dom.out.find("href=\"view.html#theta="), std::string::npos);
  for (const char* name : {"key spot", "practical lamp", "rim light", "window", "flood (off-stage)"})
    EXPECT_NE(dom.out.find(name), std::string::npos) << name;

  // A screenshot: the composite appears as rendered (template match of the tone-mapped PNG at its
  // displayed size), and the polar map covers a large disc of the severity colours.
  auto shot_args = chromiumArgs((dir / "profile-shot").string());
  const std::filesystem::path shot = dir / "shot.png";
  shot_args.push_back("--screenshot=" + shot.string());
  shot_args.push_back("--window-size=1400,2200");
  shot_args.push_back("--hide-scrollbars");
  shot_args.push_back(url);
  auto s = runProgram("chromium", shot_args, 120);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_TRUE(consoleLines(s.err).empty()) << consoleLines(s.err).front();
  const cv::Mat page = cv::imread(shot.string());
  ASSERT_FALSE(page.empty()) << "no screenshot at " << shot;
  if (const char* keep = std::getenv("FLAREKIT_KEEP_SCREENSHOT")) std::filesystem::copy_file(shot, keep,
      std::filesystem::copy_options::overwrite_existing);

  const cv::Mat composite = cv::imread((dir / "out/composite.png").string());
  cv::Mat shown;
  cv::resize(composite, shown, {640, static_cast<int>(std::lround(640.0 * composite.rows / composite.cols))}, 0, 0,
             cv::INTER_AREA);
  cv::Mat score;
  cv::matchTemplate(page, shown, score, cv::TM_CCOEFF_NORMED);
  double best = 0;
  cv::minMaxLoc(score, nullptr, &best);
  EXPECT_GT(best, 0.9) << "the composite is not visible in the screenshot";

  // Pixels of the map's colour scale (within a few levels of a ramp colour, and coloured rather
  // than grey so the flare images do not count).
  std::vector<cv::Vec3b> ramp;
  for (int k = 0; k <= 256; ++k) ramp.push_back(predict::severityRampColor(k / 256.0));
  int map_pixels = 0;
  for (int y = 0; y < page.rows; ++y)
    for (int x = 0; x < page.cols; ++x) {
      const cv::Vec3b bgr = page.at<cv::Vec3b>(y, x);
      const int spread = std::max({bgr[0], bgr[1], bgr[2]}) - std::min({bgr[0], bgr[1], bgr[2]});
      if (spread < 40) continue;
      for (const auto& c : ramp)
        if (std::abs(c[0] - bgr[2]) + std::abs(c[1] - bgr[1]) + std::abs(c[2] - bgr[0]) <= 9) {
          ++map_pixels;
          break;
        }
    }
  // The map disc has a radius of 190 px (π·190² ≈ 113 000 px); grid lines and labels cover some.
  EXPECT_GT(map_pixels, 60000) << "the severity map is not visible in the screenshot";
}

TEST(CliPredict, GltfExampleMatchesTheJsonExample) {
  // predict/examples/stage.gltf holds the same camera and lights as stage.json (the window as a
  // point light of the same l·α): the same angles and brightness scales.
  TempDir dir;
  auto a = runFlarekit({"predict", kModel.string(), "--scene", kScene.string(), "--out", (dir / "json").string()});
  auto b = runFlarekit({"predict", kModel.string(), "--scene", (kSource / "predict/examples/stage.gltf").string(),
                        "--out", (dir / "gltf").string()});
  ASSERT_EQ(a.exit_code, 0) << a.err;
  ASSERT_EQ(b.exit_code, 0) << b.err;
  const json ja = json::parse(readFile(dir / "json/estimators.json"));
  const json jb = json::parse(readFile(dir / "gltf/estimators.json"));
  ASSERT_EQ(ja["lights"].size(), jb["lights"].size());
  for (size_t k = 0; k < ja["lights"].size(); ++k) {
    const auto& la = ja["lights"][k];
    const auto& lb = jb["lights"][k];
    EXPECT_EQ(la["name"], lb["name"]);
    EXPECT_EQ(la["status"], lb["status"]);
    EXPECT_NEAR(la["angle_deg"].get<double>(), lb["angle_deg"].get<double>(), 1e-6) << la["name"];
    EXPECT_NEAR(la["roll_deg"].get<double>(), lb["roll_deg"].get<double>(), 1e-6) << la["name"];
    EXPECT_NEAR(la["brightness_scale"].get<double>() / lb["brightness_scale"].get<double>(), 1.0, 1e-5) << la["name"];
  }
  EXPECT_NEAR(ja["estimators"]["mean"].get<double>(), jb["estimators"]["mean"].get<double>(),
              1e-5 * ja["estimators"]["mean"].get<double>());
}

// The demo predicts predict/examples/stage_100mm.json with the model it fitted on the sim-heliar
// rig: the scene's camera must carry that rig's lens, and its lights must cover the cases a light
// planner meets (in the frame, beside it, out of the model's range, behind the camera).
TEST(CliPredict, DemoSceneMatchesTheDemoRigsLens) {
  auto lens = runFlarekit({"lens-info", (kSource / "lenses/heliar_tronnier.json").string(), "--json"});
  ASSERT_EQ(lens.exit_code, 0) << lens.err;
  const json scene = json::parse(readFile(kSource / "predict/examples/stage_100mm.json"));
  EXPECT_NEAR(scene["camera"]["focal_length_mm"].get<double>(), json::parse(lens.out)["efl_mm"].get<double>(), 1.0);
  TempDir dir;
  auto r = runFlarekit({"predict", kModel.string(), "--scene", (kSource / "predict/examples/stage_100mm.json").string(),
                        "--out", (dir / "out").string(), "--map-angles", "4", "--map-rolls", "4"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json e = json::parse(readFile(dir / "out/estimators.json"));
  std::map<std::string, std::string> status;
  for (const auto& l : e["lights"]) status[l["name"]] = l["status"];
  for (const char* name : {"key spot", "practical lamp", "rim light", "window"}) EXPECT_EQ(status[name], "in range") << name;
  EXPECT_EQ(status["flood (off-stage)"], "out of range");
  EXPECT_EQ(status["follow spot (behind)"], "behind camera");
}

TEST(CliPredict, BadScenesExitTwoWithOneLine) {
  TempDir dir;
  const json good = json::parse(readFile(kScene));
  struct Case {
    std::string name, text, expected;
  };
  std::vector<Case> cases;
  auto edited = [&](auto edit) {
    json j = good;
    edit(j);
    return j.dump();
  };
  cases.push_back({"nocamera.json", edited([](json& j) { j.erase("camera"); }), "camera"});
  cases.push_back({"zerosolid.json", edited([](json& j) { j["lights"][3]["solid_angle_sr"] = 0; }), "solid_angle_sr"});
  cases.push_back({"format.json", edited([](json& j) { j["format"] = "flarekit.lens"; }), "format"});
  cases.push_back({"version.json", edited([](json& j) { j["version"] = 7; }), "version"});
  std::string nan_text = good.dump();
  const std::string pos = "\"position\":[";
  nan_text.replace(nan_text.find(pos), pos.size() + 1, "\"position\":[NaN");
  cases.push_back({"nan.json", nan_text, "nan.json"});
  cases.push_back({"broken.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"nodes\": [", "broken.gltf"});
  cases.push_back({"nocamera.gltf", R"({"asset": {"version": "2.0"}, "nodes": [{"name": "empty"}]})", "camera"});
  for (const auto& c : cases) {
    std::ofstream(dir / c.name) << c.text;
    auto r = runFlarekit({"predict", kModel.string(), "--scene", (dir / c.name).string(), "--out", (dir / "out").string()});
    EXPECT_EQ(r.exit_code, 2) << c.name << ": " << r.err;
    EXPECT_EQ(lineCount(r.err), 1) << c.name << ": " << r.err;
    EXPECT_NE(r.err.find(c.name), std::string::npos) << c.name << ": " << r.err;
    EXPECT_NE(r.err.find(c.expected), std::string::npos) << c.name << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir / "out/report.html")) << c.name;
  }
  auto missing = runFlarekit({"predict", (dir / "none.json").string(), "--scene", kScene.string(), "--out",
                              (dir / "out").string()});
  EXPECT_EQ(missing.exit_code, 2) << missing.err;
  EXPECT_EQ(lineCount(missing.err), 1) << missing.err;
}

}  // namespace
}  // namespace flarekit
