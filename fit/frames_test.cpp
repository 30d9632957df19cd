// Tests of frame-stack loading: capture folders and EXR stacks, and the errors a user sees.
#include "fit/frames.h"

#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"

namespace flarekit::fit {
namespace {
namespace fs = std::filesystem;
using testing::TempDir;

cv::Mat blob(float value) {
  cv::Mat m = cv::Mat::zeros(20, 30, CV_32F);
  m(cv::Rect(10, 5, 6, 6)).setTo(value);
  return m;
}

void writeFrame(const fs::path& path, const cv::Mat& image, std::optional<double> angle) {
  ExrAttributes attrs;
  if (angle) attrs["flarekit.angle_deg"] = *angle;
  writeExr(path, image, attrs);
}

template <typename F>
std::string errorOf(F&& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(FrameLoadOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(FrameLoadOptions{}.IsValid(&error)) << error;
  FrameLoadOptions bad;
  bad.angle_pattern = "theta_[0-9]+";  // no group
  EXPECT_FALSE(bad.IsValid(&error));
}

TEST(LoadExrStack, SortsByTheAngleAttribute) {
  TempDir dir;
  writeFrame(dir / "b.exr", blob(2), 1.5);
  writeFrame(dir / "a.exr", blob(1), 3.0);
  FrameStack s = loadExrStack({dir.path()});
  ASSERT_EQ(s.frames.size(), 2u);
  EXPECT_DOUBLE_EQ(s.frames[0].angle_deg, 1.5);
  EXPECT_DOUBLE_EQ(s.frames[1].angle_deg, 3.0);
  EXPECT_EQ(s.channels, 1);
  EXPECT_EQ(s.size, cv::Size(30, 20));
  EXPECT_DOUBLE_EQ(s.info.angle_step_deg, 1.5);
}

TEST(LoadExrStack, AnglesFromCsvAndPattern) {
  TempDir dir;
  writeFrame(dir / "theta_2.5.exr", blob(1), std::nullopt);
  writeFrame(dir / "theta_-1.exr", blob(1), std::nullopt);
  FrameLoadOptions pattern;
  pattern.angle_pattern = "theta_([-0-9.]+)\\.exr";
  FrameStack s = loadExrStack({dir.path()}, pattern);
  EXPECT_DOUBLE_EQ(s.frames[0].angle_deg, -1);
  std::ofstream(dir / "angles.csv") << "file,angle_deg\ntheta_2.5.exr,7\ntheta_-1.exr,8\n";
  FrameLoadOptions csv;
  csv.angles_csv = dir / "angles.csv";
  s = loadExrStack({dir / "theta_2.5.exr", dir / "theta_-1.exr"}, csv);
  EXPECT_DOUBLE_EQ(s.frames[0].angle_deg, 7);
  EXPECT_DOUBLE_EQ(s.frames[1].angle_deg, 8);
}

TEST(LoadExrStack, ClearErrorsForMissingAndRepeatedAngles) {
  TempDir dir;
  writeFrame(dir / "a.exr", blob(1), std::nullopt);
  EXPECT_NE(errorOf([&] { loadExrStack({dir / "a.exr"}); }).find("no flarekit.angle_deg"),
            std::string::npos);
  writeFrame(dir / "b.exr", blob(1), 2.0);
  writeFrame(dir / "c.exr", blob(1), 2.0);
  const std::string e = errorOf([&] { loadExrStack({dir / "b.exr", dir / "c.exr"}); });
  EXPECT_NE(e.find("repeats"), std::string::npos) << e;
  EXPECT_NE(e.find("b.exr"), std::string::npos) << e;
  EXPECT_NE(errorOf([&] { loadExrStack({dir / "missing.exr"}); }).find("missing"),
            std::string::npos);
  std::ofstream(dir / "corrupt.exr") << "not an exr";
  EXPECT_NE(errorOf([&] { loadExrStack({dir / "corrupt.exr"}); }).find("corrupt.exr"),
            std::string::npos);
}

TEST(LoadExrStack, WarnsAboutBlackFramesAndRejectsAllBlack) {
  TempDir dir;
  writeFrame(dir / "a.exr", blob(1), 0.0);
  writeFrame(dir / "b.exr", blob(0), 1.0);
  FrameStack s = loadExrStack({dir.path()});
  ASSERT_EQ(s.frames.size(), 1u);
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("all-black"), std::string::npos);
  EXPECT_NE(errorOf([&] { loadExrStack({dir / "b.exr"}); }).find("black"), std::string::npos);
}

TEST(LoadExrStack, MasksSaturatedAndNonFinitePixels) {
  TempDir dir;
  ExrImage image;
  cv::Mat main = blob(1);
  main.at<float>(0, 0) = std::numeric_limits<float>::quiet_NaN();
  cv::Mat saturated = cv::Mat::zeros(20, 30, CV_32F);
  saturated.at<float>(7, 12) = 1;
  image.layers = {{"", main}, {"saturated", saturated}};
  image.attributes["flarekit.angle_deg"] = 0.0;
  writeExr(dir / "a.exr", image);
  FrameStack s = loadExrStack({dir / "a.exr"});
  const Frame& f = s.frames[0];
  EXPECT_EQ(f.valid.at<uchar>(0, 0), 0);
  EXPECT_EQ(f.image.at<float>(0, 0), 0.0f);
  EXPECT_EQ(f.valid.at<uchar>(7, 12), 0);
  EXPECT_EQ(f.valid.at<uchar>(7, 11), 255);
}

void writeCapture(const fs::path& dir, int frames, bool break_angle) {
  fs::create_directories(dir / "frames");
  nlohmann::json m = {{"format", "flarekit.capture"}, {"version", 1}, {"status", "complete"},
                      {"lens", {{"name", "Test lens"}}},
                      {"camera", {{"description", "sim"}, {"iso", 200}, {"f_number", 4},
                                  {"exposures_s", {0.1, 1.0}}}},
                      {"light", "lamp"},
                      {"image", {{"width", 30}, {"height", 20}, {"channels", "Y"},
                                 {"pixel_pitch_um", 5}}},
                      {"plan", {{"step_deg", 0.5}}},
                      {"truth", false}};
  m["frames"] = nlohmann::json::array();
  for (int i = 0; i < frames; ++i) {
    const std::string file = "frames/frame_000" + std::to_string(i) + ".exr";
    writeFrame(dir / file, blob(1), 0.5 * i);
    m["frames"].push_back({{"index", i}, {"angle_deg", break_angle && i == 1 ? 9.0 : 0.5 * i},
                           {"file", file}});
  }
  std::ofstream(dir / "manifest.json") << m.dump(2);
}

TEST(LoadCapture, ReadsManifestAndMetadata) {
  TempDir dir;
  writeCapture(dir.path(), 3, false);
  FrameStack s = loadFrames({dir.path()});
  ASSERT_EQ(s.frames.size(), 3u);
  EXPECT_EQ(s.info.lens, "Test lens");
  EXPECT_DOUBLE_EQ(s.info.iso, 200);
  EXPECT_DOUBLE_EQ(s.info.exposure_s, 1.0);
  EXPECT_DOUBLE_EQ(s.info.angle_step_deg, 0.5);
  EXPECT_FALSE(s.has_truth);
}

TEST(LoadCapture, InconsistentManifestAndMissingFrames) {
  TempDir dir;
  writeCapture(dir.path(), 3, true);
  std::string e = errorOf([&] { loadCapture(dir.path()); });
  EXPECT_NE(e.find("frames[1].angle_deg"), std::string::npos) << e;
  TempDir dir2;
  writeCapture(dir2.path(), 3, false);
  fs::remove(dir2 / "frames/frame_0002.exr");
  e = errorOf([&] { loadCapture(dir2.path()); });
  EXPECT_NE(e.find("frame_0002.exr is missing"), std::string::npos) << e;
}

// A capture with ground truth whose truth file is missing for one frame is measured without the
// truth, and the user is told which file is missing.
TEST(LoadCapture, SaysWhichTruthFileIsMissing) {
  TempDir dir;
  writeCapture(dir.path(), 3, false);
  nlohmann::json m = nlohmann::json::parse(std::ifstream(dir / "manifest.json"));
  m["truth"] = true;
  fs::create_directories(dir / "truth");
  for (int i = 0; i < 3; ++i) {
    const std::string file = "truth/frame_000" + std::to_string(i) + ".exr";
    m["frames"][i]["truth_file"] = file;
    writeFrame(dir / file, blob(0.5), 0.5 * i);
  }
  std::ofstream(dir / "manifest.json") << m.dump(2);
  EXPECT_TRUE(loadCapture(dir.path()).has_truth);
  fs::remove(dir / "truth/frame_0001.exr");
  const FrameStack s = loadCapture(dir.path());
  EXPECT_FALSE(s.has_truth);
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("truth/frame_0001.exr is missing"), std::string::npos) << s.warnings[0];
}

// Frames are decoded in parallel; the error a user sees is still the first bad frame's, in angle
// order, however the threads ran.
TEST(LoadCapture, NamesTheFirstBadFrameWhenSeveralAreBad) {
  TempDir dir;
  writeCapture(dir.path(), 3, false);
  std::ofstream(dir / "frames/frame_0001.exr") << "not an exr";
  std::ofstream(dir / "frames/frame_0002.exr") << "not an exr either";
  for (int run = 0; run < 5; ++run) {
    const std::string e = errorOf([&] { loadCapture(dir.path()); });
    EXPECT_NE(e.find("frame_0001.exr"), std::string::npos) << e;
    EXPECT_EQ(e.find("frame_0002.exr"), std::string::npos) << e;
  }
}

}  // namespace
}  // namespace flarekit::fit
