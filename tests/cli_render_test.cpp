// flarekit lens-info, simulate and bench render as a user runs them.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/atomic_file.h"
#include "common/exr.h"
#include "common/testing.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

using testing::lineCount;
using testing::runFlarekit;
using testing::TempDir;

std::string lens(const std::string& name) {
  return (std::filesystem::path(FLAREKIT_SOURCE_DIR) / "lenses" / name).string();
}


TEST(CliRender, LensInfoShowsTheParaxialFacts) {
  auto r = runFlarekit({"lens-info", lens("heliar_tronnier.json")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("effective focal length: 99.236 mm"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("back focal distance:    81.315 mm"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("28 all, 13 with both reflections"), std::string::npos) << r.out;
  auto j = runFlarekit({"lens-info", "--json", lens("nikon_zoom_28_75mm_at_28mm.json")});
  ASSERT_EQ(j.exit_code, 0) << j.err;
  const auto doc = nlohmann::json::parse(j.out);
  EXPECT_NEAR(doc["efl_mm"].get<double>(), 28.9, 0.03);
  EXPECT_EQ(doc["ghosts_all"].get<int>(), 351);
  EXPECT_EQ(doc["surfaces"].size(), 28u);
  auto dat = runFlarekit({"lens-info", lens("pbrt/dgauss.50mm.dat")});
  EXPECT_EQ(dat.exit_code, 0) << dat.err;
}

// Broken lens files: exit 2, one line naming the file and the problem.
TEST(CliRender, BadLensFilesExitTwoWithOneClearLine) {
  TempDir dir;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"nostop.json", R"({"surfaces": [{"radius": 50, "thickness": 5, "ior": 1.5, "semi_aperture": 10},
                       {"radius": -50, "thickness": 40, "ior": 1.0, "semi_aperture": 10}]})"},
      {"negative.json", R"({"surfaces": [{"radius": 50, "thickness": -5, "ior": 1.5, "semi_aperture": 10},
                       {"radius": 0, "thickness": 2, "semi_aperture": 5, "is_stop": true},
                       {"radius": -50, "thickness": 40, "ior": 1.0, "semi_aperture": 10}]})"},
      {"nan.json", R"({"surfaces": [{"radius": NaN, "thickness": 5, "ior": 1.5, "semi_aperture": 10}]})"},
      {"rim.json", R"({"surfaces": [{"radius": 8, "thickness": 5, "ior": 1.5, "semi_aperture": 10},
                       {"radius": 0, "thickness": 2, "semi_aperture": 5, "is_stop": true},
                       {"radius": -50, "thickness": 40, "ior": 1.0, "semi_aperture": 10}]})"},
      {"types.json", R"({"surfaces": [{"radius": "50", "thickness": 5, "ior": 1.5, "semi_aperture": 10}]})"},
      {"empty.json", R"({"surfaces": []})"},
      {"garbage.json", "this is not a lens"},
      {"bad.dat", "29.475 3.76 1.67\n"},
  };
  for (const auto& [name, text] : cases) {
    writeTextFileAtomically(dir / name, text);
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"lens-info", (dir / name).string()},
          std::vector<std::string>{"simulate", "--lens", (dir / name).string(), "--angle", "5", "--out",
                                   (dir / "out.exr").string()}}) {
      auto r = runFlarekit(args);
      EXPECT_EQ(r.exit_code, 2) << name << ": " << r.err;
      EXPECT_EQ(lineCount(r.err), 1) << name << ": " << r.err;
      EXPECT_NE(r.err.find(name), std::string::npos) << r.err;
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "out.exr"));
  auto missing = runFlarekit({"lens-info", (dir / "missing.json").string()});
  EXPECT_EQ(missing.exit_code, 2);
}

TEST(CliRender, SimulateWritesRadianceGhostLayersAndAPreview) {
  TempDir dir;
  auto r = runFlarekit({"simulate", "--lens", lens("heliar_tronnier.json"), "--angle", "6", "--roll", "10",
                        "--width", "240", "--height", "160", "--ghost-layers", "--starburst", "--max-ghosts",
                        "5", "--preview", (dir / "flare.png").string(), "--out", (dir / "flare.exr").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const ExrImage exr = readExr(dir / "flare.exr");
  ASSERT_EQ(exr.layers.size(), 6u);  // main + 5 ghosts
  EXPECT_EQ(exr.main().cols, 240);
  EXPECT_EQ(exr.main().type(), CV_32FC3);
  EXPECT_NEAR(*numericAttribute(exr.attributes, "flarekit.angle_deg"), 6.0, 0);
  EXPECT_NEAR(*numericAttribute(exr.attributes, "flarekit.roll_deg"), 10.0, 0);
  EXPECT_TRUE(stringAttribute(exr.attributes, "flarekit.radiometric_unit"));
  const std::string id = exr.layers[1].name.substr(6);  // "ghost.<id>"
  EXPECT_TRUE(exr.attributes.count("flarekit.ghost." + id + ".surfaces"));
  EXPECT_TRUE(exr.attributes.count("flarekit.ghost." + id + ".bbox_px"));
  const cv::Mat png = cv::imread((dir / "flare.png").string());
  EXPECT_EQ(png.cols, 240);
  // The light sits left of the centre (θ > 0) and far outshines the ghosts.
  double peak;
  cv::Point at;
  cv::Mat g;
  cv::extractChannel(exr.main(), g, 1);
  cv::minMaxLoc(g, nullptr, &peak, nullptr, &at);
  EXPECT_LT(at.x, 120);
  EXPECT_GT(peak, 1000 * cv::mean(g)[0]);
}

TEST(CliRender, SimulateMethodsAndSpectralMode) {
  TempDir dir;
  for (const char* method : {"tiled", "per-ghost", "matrix"}) {
    auto r = runFlarekit({"simulate", "--lens", lens("brendel_tessar_100mm_usp2854889.json"), "--angle", "4",
                          "--width", "160", "--height", "120", "--method", method, "--wavelengths", "6",
                          "--f-number", "5.6", "--aperture", "polygon", "--blades", "7", "--no-source", "--out",
                          (dir / (std::string(method) + ".exr")).string()});
    EXPECT_EQ(r.exit_code, 0) << method << ": " << r.err;
  }
  auto wide = runFlarekit({"simulate", "--lens", lens("brendel_tessar_100mm_usp2854889.json"), "--angle", "4",
                           "--f-number", "1.0", "--out", (dir / "x.exr").string()});
  EXPECT_EQ(wide.exit_code, 2);
  EXPECT_EQ(lineCount(wide.err), 1) << wide.err;
  auto method = runFlarekit({"simulate", "--lens", lens("brendel_tessar_100mm_usp2854889.json"), "--angle", "4",
                             "--method", "fast", "--out", (dir / "x.exr").string()});
  EXPECT_EQ(method.exit_code, 2);
}

TEST(CliRender, BenchPrintsOneJsonObject) {
  auto r = runFlarekit({"bench", "render", "--lens", lens("heliar_tronnier.json"), "--width", "160", "--height",
                        "120", "--grid", "16", "--repetitions", "1", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto doc = nlohmann::json::parse(r.out);
  for (const char* key : {"ghosts", "rays_per_s", "ms_tiled", "ms_per_ghost", "ms_matrix", "threads"})
    EXPECT_TRUE(doc.contains(key)) << key;
  EXPECT_EQ(doc["ghosts"].get<int>(), 28);
  // The speed-ups are the quotients of the medians printed beside them.
  EXPECT_DOUBLE_EQ(doc["tiled_speedup_over_per_ghost"].get<double>(),
                   doc["ms_per_ghost"].get<double>() / doc["ms_tiled"].get<double>());
  EXPECT_DOUBLE_EQ(doc["tiled_raster_speedup_over_per_ghost"].get<double>(),
                   doc["ms_per_ghost_raster"].get<double>() / doc["ms_tiled_raster"].get<double>());
  EXPECT_DOUBLE_EQ(doc["matrix_speedup_over_tiled"].get<double>(),
                   doc["ms_tiled"].get<double>() / doc["ms_matrix"].get<double>());
}

}  // namespace
}  // namespace flarekit
