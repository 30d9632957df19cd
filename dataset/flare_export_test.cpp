#include "dataset/flare_export.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"

namespace flarekit::dataset {
namespace {

namespace fs = std::filesystem;
using testing::filesUnder;
using testing::TempDir;

const std::string kData = std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/";
// Fitted models: an RGB one with 39 ghosts and a focal length (Nikon 80 mm), a grey one (the demo's
// Heliar), and a hand-made one with neither a focal length nor a clip level.
const std::string kNikon = kData + "view/nikon_model.json";
const std::string kHeliar = kData + "view/demo_model.json";
const std::string kExample = kData + "model/example_model.json";

ExportOptions smallSet(long long count) {
  ExportOptions o;
  o.count = count;
  o.size = {96, 64};
  o.seed = 7;
  return o;
}

// Every file under `dir` (relative path → content), for comparing sets byte for byte.
std::string readText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(ExportOptions, DefaultsAreValidAndBadValuesAreNamed) {
  std::string why;
  EXPECT_TRUE(ExportOptions{}.IsValid(&why)) << why;
  ExportOptions o;
  o.count = 0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("--count"), std::string::npos) << why;
  o.count = -5;
  EXPECT_FALSE(o.IsValid(&why));
  o = {};
  o.ev_min = 2;
  o.ev_max = 1;
  EXPECT_FALSE(o.IsValid(&why));
}

TEST(ExportOptions, ParsesSizesAndShards) {
  EXPECT_EQ(parseSize("512x512"), cv::Size(512, 512));
  EXPECT_EQ(parseSize("640×360"), cv::Size(640, 360));
  for (const char* bad : {"512", "0x10", "x", "512x", "12x-4", "1e3x10", "99999x10", "512x512x3"})
    EXPECT_THROW(parseSize(bad), InputError) << bad;
  const Shard s = parseShard("2/8");
  EXPECT_EQ(s.index, 2);
  EXPECT_EQ(s.count, 8);
  for (const char* bad : {"0/3", "4/3", "3", "a/b", "1/0", "-1/3", "1/3/4", ""})
    EXPECT_THROW(parseShard(bad), InputError) << bad;
}

TEST(ShardRange, PartsAreDisjointAndCoverTheSetInOrder) {
  for (long long count : {1LL, 7LL, 10LL, 1001LL})
    for (int n : {1, 2, 3, 8, 13}) {
      long long next = 0;
      for (int k = 1; k <= n; ++k) {
        const SampleRange r = shardRange(count, {k, n});
        EXPECT_EQ(r.begin, next) << count << " " << k << "/" << n;
        EXPECT_GE(r.size(), count / n);
        EXPECT_LE(r.size(), count / n + 1);
        next = r.end;
      }
      EXPECT_EQ(next, count);
    }
}

TEST(SampleParameters, DependOnSeedAndIndexOnly) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon), ExportModel::load(kHeliar)};
  ExportOptions o = smallSet(1000);
  const SampleParameters a = sampleParameters(models, o, 417);
  // Another shard, thread count or set of neighbours does not change a sample.
  ExportOptions other = o;
  other.shard = {3, 5};
  other.threads = 1;
  const SampleParameters b = sampleParameters(models, other, 417);
  EXPECT_EQ(a.theta_deg, b.theta_deg);
  EXPECT_EQ(a.roll_deg, b.roll_deg);
  EXPECT_EQ(a.exposure_ev, b.exposure_ev);
  EXPECT_EQ(a.light.position_px, b.light.position_px);
  EXPECT_EQ(a.light.core_value, b.light.core_value);
  EXPECT_EQ(a.ghost_ids, b.ghost_ids);
  EXPECT_EQ(a.name, "000417");
  // Neighbours and other seeds differ.
  EXPECT_NE(sampleParameters(models, o, 418).theta_deg, a.theta_deg);
  o.seed = 8;
  EXPECT_NE(sampleParameters(models, o, 417).theta_deg, a.theta_deg);
}

TEST(SampleParameters, StayWithinEachModelsRangesAndOptions) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon), ExportModel::load(kHeliar)};
  const ExportOptions o = smallSet(400);
  double roll_min = 360, roll_max = 0;
  for (long long i = 0; i < o.count; ++i) {
    const SampleParameters s = sampleParameters(models, o, i);
    ASSERT_EQ(s.model_index, i % 2);  // the models in turn
    const auto& m = models[static_cast<size_t>(s.model_index)];
    bool covered = false;
    for (const auto& g : m.model.ghosts) covered = covered || g.covers(s.theta_deg);
    ASSERT_TRUE(covered) << "θ = " << s.theta_deg << " has no ghost";
    ASSERT_FALSE(s.ghost_ids.empty());
    ASSERT_GE(s.exposure_ev, o.ev_min);
    ASSERT_LT(s.exposure_ev, o.ev_max);
    ASSERT_NEAR(s.scale, std::exp2(s.exposure_ev) / m.white, 1e-12 * s.scale);
    ASSERT_GE(s.light.core_radius_px, o.core_radius_min * o.size.width);
    ASSERT_LE(s.light.core_radius_px, o.core_radius_max * o.size.width);
    roll_min = std::min(roll_min, s.roll_deg);
    roll_max = std::max(roll_max, s.roll_deg);
  }
  EXPECT_LT(roll_min, 10);
  EXPECT_GT(roll_max, 350);
  // The white level: the clip level where the model records one, else from its brightest ghost.
  EXPECT_EQ(models[0].white_source, "clip_level");
  EXPECT_EQ(models[0].white, 0.006);
  const ExportModel example = ExportModel::load(kExample);
  EXPECT_EQ(example.white_source, "brightest ghost");
  EXPECT_NEAR(example.white, 4 * 0.9, 1e-9);  // its brightest ghost value is 0.9
}

TEST(SampleParameters, LightInFrameKeepsTheLightInside) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon)};
  ExportOptions o = smallSet(200);
  int outside = 0;
  for (long long i = 0; i < o.count; ++i) outside += !sampleParameters(models, o, i).light.in_frame;
  EXPECT_GT(outside, 20);  // the Nikon's range reaches far beyond its frame
  o.light_in_frame = true;
  for (long long i = 0; i < o.count; ++i) {
    const SampleParameters s = sampleParameters(models, o, i);
    ASSERT_TRUE(s.light.in_frame);
    ASSERT_GE(s.light.position_px.x, 0);
    ASSERT_LT(s.light.position_px.x, o.size.width);
    ASSERT_GE(s.light.position_px.y, 0);
    ASSERT_LT(s.light.position_px.y, o.size.height);
  }
}

TEST(LightPosition, IsWhereTheViewerPutsTheLight) {
  // flarekit view (view/viewer.html, lightPoint): the optical axis plus f·tan θ / pitch towards
  // (−cos φ, sin φ), capture pixels scaled by the width ratio about the image's middle.
  const model::FlareModel m = model::FlareModel::load(kNikon);
  const auto& c = m.capture;
  const cv::Size size(512, 384);
  const double scale = 512.0 / c.image_size.width;
  for (double theta : {0.0, 3.0, 12.5})
    for (double phi : {0.0, 90.0, 200.0}) {
      const double r = c.focal_length_mm * std::tan(theta * std::numbers::pi / 180) / (c.pixel_pitch_um * 1e-3);
      const double p = phi * std::numbers::pi / 180;
      const cv::Point2d axis = *c.optical_axis_px;
      const cv::Point2d expected(256 + (axis.x - 0.5 * c.image_size.width - std::cos(p) * r) * scale,
                                 192 + (axis.y - 0.5 * c.image_size.height + std::sin(p) * r) * scale);
      const cv::Point2d got = lightPosition(m, theta, phi, size);
      EXPECT_NEAR(got.x, expected.x, 1e-9) << theta << " " << phi;
      EXPECT_NEAR(got.y, expected.y, 1e-9) << theta << " " << phi;
    }
  // Positive θ at roll 0 puts the light left of the axis (docs/design.md).
  EXPECT_LT(lightPosition(m, 5, 0, size).x, lightPosition(m, 0, 0, size).x);
}

TEST(RenderSample, FlareIsTheModelsRenderingExposed) {
  for (const std::string& file : {kNikon, kHeliar}) {
    const std::vector<ExportModel> models = {ExportModel::load(file)};
    ExportOptions o = smallSet(10);
    o.size = {160, 120};
    for (long long i : {0LL, 3LL}) {
      const SampleParameters s = sampleParameters(models, o, i);
      const SampleImages images = renderSample(models[0], s, o);
      cv::Mat expected;
      models[0].model.render(s.theta_deg, s.roll_deg, o.size).convertTo(expected, CV_32F, s.scale);
      if (expected.channels() == 1) cv::cvtColor(expected, expected, cv::COLOR_GRAY2RGB);
      ASSERT_EQ(images.flare.type(), CV_32FC3);
      EXPECT_EQ(cv::norm(images.flare, expected, cv::NORM_INF), 0.0) << file << " sample " << i;
      EXPECT_GT(cv::sum(images.flare)[0], 0.0);
    }
  }
}

TEST(RenderSample, EachMaskIsWhereItsGhostAloneReachesTheThreshold) {
  const std::vector<ExportModel> models = {ExportModel::load(kNikon)};
  ExportOptions o = smallSet(10);
  o.size = {160, 120};
  const SampleParameters s = sampleParameters(models, o, 2);
  const SampleImages images = renderSample(models[0], s, o);
  const model::FlareModel& m = models[0].model;
  const auto ghosts = m.ghostsAt(s.theta_deg);
  ASSERT_EQ(images.masks.size(), ghosts.size());
  ASSERT_EQ(images.mask_pixels.size(), ghosts.size());
  int shown = 0;
  for (size_t k = 0; k < ghosts.size(); ++k) {
    EXPECT_EQ(s.ghost_ids[k], ghosts[k].id);
    const cv::Mat alone = model::renderGhosts(std::span(&ghosts[k].parameters, 1), o.size, m.channels, {},
                                              m.viewAt(s.roll_deg, o.size));
    cv::Mat peak;
    cv::Mat planes[3];
    cv::split(alone, planes);
    peak = cv::max(cv::max(planes[0], planes[1]), planes[2]);
    const cv::Mat expected = peak >= static_cast<float>(o.mask_threshold / s.scale);
    const long long count = cv::countNonZero(expected);
    EXPECT_EQ(images.mask_pixels[k], count) << "ghost " << ghosts[k].id;
    if (count == 0) {
      EXPECT_TRUE(images.masks[k].empty());
      continue;
    }
    ++shown;
    ASSERT_EQ(images.masks[k].type(), CV_8UC1);
    EXPECT_EQ(cv::norm(images.masks[k], expected, cv::NORM_INF), 0.0) << "ghost " << ghosts[k].id;
  }
  EXPECT_GT(shown, 3);
}

TEST(RenderSample, LightIsACoreAboveWhiteWithAGlowAtItsPosition) {
  const std::vector<ExportModel> models = {ExportModel::load(kHeliar)};
  ExportOptions o = smallSet(50);
  o.size = {200, 150};
  o.light_in_frame = true;
  const SampleParameters s = sampleParameters(models, o, 5);
  const SampleImages images = renderSample(models[0], s, o);
  const cv::Point p(static_cast<int>(s.light.position_px.x), static_cast<int>(s.light.position_px.y));
  const cv::Vec3f centre = images.light.at<cv::Vec3f>(p);
  EXPECT_GT(centre[0], 1.0f);                // clips: a light's core
  EXPECT_EQ(centre[0], centre[2]);           // white
  EXPECT_NEAR(centre[0], s.light.core_value + s.light.glow_value, 0.05 * s.light.core_value);
  double peak = 0;
  cv::minMaxLoc(images.light.reshape(1), nullptr, &peak);
  EXPECT_NEAR(peak, centre[0], 0.05 * centre[0]);
  // Beyond the core only the glow, falling with distance; nothing far away.
  const int beyond = static_cast<int>(s.light.core_radius_px + 3);
  const cv::Point side(std::min(o.size.width - 1, p.x + beyond), p.y);
  EXPECT_LT(images.light.at<cv::Vec3f>(side)[0], s.light.glow_value * 1.01);
}

TEST(EncodeSrgb8, IsTheRoundedSrgbCurveOfTheClippedValue) {
  auto reference = [](double v) {
    v = std::clamp(v, 0.0, 1.0);
    const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
    return static_cast<int>(std::lround(255 * e));
  };
  std::mt19937 rng(3);
  cv::Mat linear(64, 64, CV_32FC3);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const float v = y < 32 ? std::pow(std::uniform_real_distribution<float>(0, 1)(rng), 3.0f)
                             : std::uniform_real_distribution<float>(-0.2f, 1.5f)(rng);
      linear.at<cv::Vec3f>(y, x) = cv::Vec3f(v, 0.5f * v, x == 0 ? 1.0f : 0.0f);
    }
  const cv::Mat out = encodeSrgb8(linear);
  int off = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const cv::Vec3f v = linear.at<cv::Vec3f>(y, x);
      const cv::Vec3b b = out.at<cv::Vec3b>(y, x);  // B, G, R
      off += b[2] != reference(v[0]) || b[1] != reference(v[1]) || b[0] != reference(v[2]);
    }
  EXPECT_EQ(off, 0);
  EXPECT_EQ(encodeSrgb8(cv::Mat(1, 1, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5))).at<cv::Vec3b>(0, 0)[0], 188);
}

TEST(ExportModel, BadFilesAreInputErrorsNamingTheFile) {
  TempDir dir;
  EXPECT_THROW(ExportModel::load(dir / "missing.json"), InputError);
  {
    std::ofstream(dir / "lens.json") << R"({"format": "flarekit.lens", "version": 1})";
    std::ofstream(dir / "broken.json") << "{ not json";
  }
  for (const char* name : {"lens.json", "broken.json"}) {
    try {
      ExportModel::load(dir / name);
      ADD_FAILURE() << name << " loaded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
    }
  }
  model::FlareModel empty = model::FlareModel::load(kHeliar);
  empty.ghosts.clear();
  empty.pedestal.reset();
  EXPECT_THROW(ExportModel::fromModel(empty, "empty.json"), InputError);
}

TEST(ExportFlares, WritesTheFlare7kFoldersWithMatchingNames) {
  TempDir dir;
  const std::vector<ExportModel> models = {ExportModel::load(kNikon), ExportModel::load(kHeliar)};
  const ExportOptions o = smallSet(5);
  const ExportSummary summary = exportFlares(models, o, dir.path());
  EXPECT_EQ(summary.samples, 5);
  for (const char* folder : {kFlareFolder, kLightFolder, kCompoundFolder})
    for (int i = 0; i < 5; ++i) {
      const cv::Mat png = cv::imread((dir.path() / folder / (sampleName(i, 5) + ".png")).string(), cv::IMREAD_UNCHANGED);
      ASSERT_EQ(png.type(), CV_8UC3) << folder << " " << i;
      EXPECT_EQ(png.size(), o.size);
    }
  // The JSON lines and the CSV rows say the same, one per sample in index order.
  std::istringstream jsonl(readText(summary.jsonl)), csv(readText(summary.csv));
  std::string line, row;
  std::getline(csv, row);
  EXPECT_EQ(row, csvHeader());
  for (int i = 0; i < 5; ++i) {
    ASSERT_TRUE(std::getline(jsonl, line));
    ASSERT_TRUE(std::getline(csv, row));
    const nlohmann::json j = nlohmann::json::parse(line);
    EXPECT_EQ(j["index"], i);
    EXPECT_EQ(j["model"], i % 2 ? kHeliar : kNikon);
    EXPECT_EQ(row.substr(0, row.find(',')), std::to_string(i));
    // The EXR holds the exposed flare and the sample's angles; a mask per ghost that shows.
    const ExrImage exr = readExr(dir.path() / kFlareExrFolder / (j["name"].get<std::string>() + ".exr"));
    EXPECT_EQ(numericAttribute(exr.attributes, "flarekit.angle_deg"), j["theta_deg"].get<double>());
    EXPECT_EQ(exr.main().size(), o.size);
    const auto ids = j["ghost_ids"].get<std::vector<int>>();
    const auto pixels = j["mask_pixels"].get<std::vector<long long>>();
    ASSERT_EQ(ids.size(), pixels.size());
    for (size_t k = 0; k < ids.size(); ++k) {
      const fs::path mask = dir.path() / kMaskFolder / j["name"].get<std::string>() / ("ghost_" + std::to_string(ids[k]) + ".png");
      EXPECT_EQ(fs::exists(mask), pixels[k] > 0) << mask;
      if (pixels[k] > 0) {
        EXPECT_EQ(cv::countNonZero(cv::imread(mask.string(), cv::IMREAD_GRAYSCALE)), pixels[k]);
      }
    }
  }
  EXPECT_FALSE(std::getline(jsonl, line));
  const nlohmann::json d = nlohmann::json::parse(readText(dir.path() / "dataset.json"));
  EXPECT_EQ(d["format"], kDatasetFormat);
  EXPECT_EQ(d["count"], 5);
}

TEST(ExportFlares, SameSeedWritesTheSameBytesOnAnyThreadCount) {
  TempDir a, b, c;
  const std::vector<ExportModel> models = {ExportModel::load(kNikon), ExportModel::load(kHeliar)};
  ExportOptions o = smallSet(6);
  o.threads = 2;
  exportFlares(models, o, a.path());
  o.threads = 1;
  exportFlares(models, o, b.path());
  const auto first = filesUnder(a.path()), second = filesUnder(b.path());
  EXPECT_GT(first.size(), 6u * 5);
  EXPECT_TRUE(first == second);
  // Another seed is another set.
  o.seed = 8;
  exportFlares(models, o, c.path());
  EXPECT_NE(filesUnder(c.path()).at("Flare/000000.png"), first.at("Flare/000000.png"));
}

TEST(ExportFlares, ShardsTogetherAreTheWholeSet) {
  TempDir whole, parts;
  const std::vector<ExportModel> models = {ExportModel::load(kNikon), ExportModel::load(kHeliar)};
  ExportOptions o = smallSet(8);
  exportFlares(models, o, whole.path());
  std::string jsonl, csv_rows;
  for (int k = 1; k <= 3; ++k) {
    o.shard = {k, 3};
    const ExportSummary s = exportFlares(models, o, parts.path());  // one folder, as on a cluster
    EXPECT_EQ(s.range.begin, shardRange(8, {k, 3}).begin);
    EXPECT_EQ(s.jsonl.filename(), "samples." + std::to_string(k) + "-of-3.jsonl");
    jsonl += readText(s.jsonl);
    const std::string csv = readText(s.csv);
    csv_rows += csv.substr(csv.find('\n') + 1);
  }
  auto all = filesUnder(whole.path()), union_of_parts = filesUnder(parts.path());
  // The parameter files are named per shard; their concatenation is the whole run's.
  EXPECT_EQ(jsonl, all.at("samples.jsonl"));
  const std::string whole_csv = all.at("samples.csv");
  EXPECT_EQ(csv_rows, whole_csv.substr(whole_csv.find('\n') + 1));
  for (auto* files : {&all, &union_of_parts})
    for (auto it = files->begin(); it != files->end();)
      it = it->first.rfind("samples", 0) == 0 ? files->erase(it) : std::next(it);
  EXPECT_GT(all.size(), 8u * 5);
  EXPECT_TRUE(all == union_of_parts);
}

TEST(ExportFlares, RefusesAFolderThatHoldsAnotherSet) {
  TempDir dir;
  const std::vector<ExportModel> models = {ExportModel::load(kHeliar)};
  ExportOptions o = smallSet(2);
  exportFlares(models, o, dir.path());
  o.seed = 9;
  try {
    exportFlares(models, o, dir.path());
    ADD_FAILURE() << "a second set went into the folder";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("seed"), std::string::npos) << e.what();
  }
  // The same set again is fine (a shard run twice, or a rerun after a crash).
  o.seed = 7;
  EXPECT_NO_THROW(exportFlares(models, o, dir.path()));
}

}  // namespace
}  // namespace flarekit::dataset
