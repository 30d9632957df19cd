// flarekit fit, fit-eval and bench fit as a user runs them: a small capture folder with known
// ghosts (rendered with model/, with noise and ground truth under truth/) is fitted and the model
// is checked against the truth; bad input gives exit code 2 and one line.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/exr.h"
#include "common/testing.h"
#include "model/flare_model.h"
#include "model/model_renderer.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;
using testing::lineCount;
using testing::runFlarekit;
using testing::TempDir;


// Two ghosts moving along the horizon as θ grows, like a pan rig's.
std::vector<model::GhostParameters> ghostsAt(double theta) {
  model::GhostParameters a;
  a.center_x = 60 + 10 * theta;
  a.center_y = 65;
  a.left = a.right = 18 + theta;
  a.height = 17;
  a.border = {1.0, 0, 0};
  a.inside = {0.5, 0, 0};
  a.inside_falloff = 5;
  a.outside_falloff = 2;
  model::GhostParameters b = a;
  b.center_x = 150 - 8 * theta;
  b.left = b.right = b.height = 10;
  b.border = {0.4, 0, 0};
  b.inside = {0.6, 0, 0};
  return {a, b};
}

void writeCapture(const fs::path& dir, int frames, double brightness = 1) {
  const cv::Size size(200, 130);
  fs::create_directories(dir / "frames");
  fs::create_directories(dir / "truth");
  nlohmann::json m = {{"format", "flarekit.capture"}, {"version", 1}, {"status", "complete"},
                      {"lens", {{"name", "test lens"}}},
                      {"camera", {{"description", "test"}, {"iso", 100}, {"f_number", 8},
                                  {"exposures_s", {1.0}}}},
                      {"light", "test light"},
                      {"image", {{"width", size.width}, {"height", size.height}, {"channels", "Y"},
                                 {"pixel_pitch_um", 10}}},
                      {"plan", {{"step_deg", 0.2}}},
                      {"truth", true}};
  m["frames"] = nlohmann::json::array();
  cv::theRNG().state = 11;
  for (int i = 0; i < frames; ++i) {
    const double theta = 0.2 * i;
    const auto ghosts = ghostsAt(theta);
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d", i);
    ExrImage truth_ghosts;
    cv::Mat clean = cv::Mat::zeros(size, CV_32F);
    for (size_t g = 0; g < ghosts.size(); ++g) {
      std::vector<model::GhostParameters> one = {ghosts[g]};
      cv::Mat img = model::renderGhosts(one, size, 1) * brightness;
      clean += img;
      truth_ghosts.layers.push_back({"ghost." + std::to_string(g), img});
    }
    cv::Mat noise(size, CV_32F);
    cv::randn(noise, 0, 0.01);
    ExrAttributes attrs;
    attrs["flarekit.angle_deg"] = theta;
    writeExr(dir / "frames" / (std::string(name) + ".exr"), clean + noise, attrs);
    writeExr(dir / "truth" / (std::string(name) + ".exr"), clean, attrs);
    truth_ghosts.attributes = attrs;
    writeExr(dir / "truth" / (std::string(name) + ".ghosts.exr"), truth_ghosts);
    m["frames"].push_back({{"index", i}, {"angle_deg", theta},
                           {"file", "frames/" + std::string(name) + ".exr"},
                           {"truth_file", "truth/" + std::string(name) + ".exr"},
                           {"ghosts_file", "truth/" + std::string(name) + ".ghosts.exr"}});
  }
  std::ofstream(dir / "manifest.json") << m.dump(2);
}

TEST(CliFit, FitsAndEvaluatesASmallCapture) {
  TempDir dir;
  writeCapture(dir / "capture", 12);
  const std::string model = (dir / "model.json").string();
  auto fit = runFlarekit({"-q", "fit", (dir / "capture").string(), "--out", model, "--report",
                          (dir / "report").string()});
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  const model::FlareModel m = model::FlareModel::load(model);
  EXPECT_EQ(m.ghosts.size(), 2u);
  // The model keeps the glow its ghosts leave (model/pedestal.h), and model-info shows its terms;
  // --no-pedestal leaves it out.
  ASSERT_TRUE(m.pedestal.has_value());
  auto info = runFlarekit(
      {"-q", "model-info", model, "--angle", std::to_string(m.pedestal->angle_min_deg), "--json"});
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_TRUE(nlohmann::json::parse(info.out)["pedestal"]["P20"].is_number()) << info.out;
  const std::string plain = (dir / "plain.json").string();
  auto without =
      runFlarekit({"-q", "fit", (dir / "capture").string(), "--out", plain, "--no-pedestal"});
  ASSERT_EQ(without.exit_code, 0) << without.err;
  EXPECT_FALSE(model::FlareModel::load(plain).pedestal.has_value());
  ASSERT_TRUE(fs::exists(dir / "report" / "summary.json"));
  // The whole fit's time holds its stages'; both ghosts were found from their two borders; the
  // report draws the sweep image beside the model's.
  const auto summary = nlohmann::json::parse(std::ifstream(dir / "report" / "summary.json"));
  EXPECT_GT(summary["seconds_model_fit"].get<double>(), 0);
  EXPECT_GE(summary["seconds_total"].get<double>(),
            summary["seconds_horizon"].get<double>() + summary["seconds_sweep"].get<double>() +
                summary["seconds_candidates"].get<double>() + summary["seconds_frame_fit"].get<double>() +
                summary["seconds_model_fit"].get<double>());
  EXPECT_EQ(summary["candidates"]["pairs"].get<int>(), 2) << summary.dump();
  const cv::Mat sweep = cv::imread((dir / "report" / "sweep.png").string());
  EXPECT_EQ(sweep.cols, 2 * 200 + 4);
  EXPECT_EQ(sweep.rows, 3 * 12);
  // Each contact sheet shows capture | the frame's fits | model | |capture − model|: on a capture
  // this well fitted, the fits and the model look alike, and both show ghosts.
  int sheets = 0;
  for (const auto& entry : fs::directory_iterator(dir / "report")) {
    if (entry.path().filename().string().rfind("contact_", 0) != 0) continue;
    ++sheets;
    const cv::Mat sheet = cv::imread(entry.path().string(), cv::IMREAD_GRAYSCALE);
    ASSERT_EQ(sheet.cols, 4 * 200) << entry.path();
    ASSERT_EQ(sheet.rows, 130);
    const cv::Mat fits = sheet(cv::Rect(200 + 1, 20, 198, 110)), drawn = sheet(cv::Rect(400 + 1, 20, 198, 110));
    double brightest = 0;
    cv::minMaxLoc(fits, nullptr, &brightest);
    EXPECT_GT(brightest, 100) << entry.path();
    EXPECT_LT(cv::norm(fits, drawn, cv::NORM_L1) / fits.total(), 10) << entry.path();
  }
  EXPECT_GT(sheets, 0);
  auto eval = runFlarekit({"-q", "fit-eval", model, (dir / "capture").string(), "--json"});
  ASSERT_EQ(eval.exit_code, 0) << eval.err;
  const auto j = nlohmann::json::parse(eval.out);
  EXPECT_GE(j["recall"].get<double>(), 0.95) << eval.out;
  EXPECT_GE(j["precision"].get<double>(), 0.95);
  EXPECT_GE(j["median_psnr_db"].get<double>(), 32);
  EXPECT_LE(j["median_centroid_error_px"].get<double>(), 0.5);
  // The per-ghost figures: a fit of this small capture draws each ghost's light and keeps one
  // track per ghost.
  EXPECT_LE(j["median_centroid_error_pct"].get<double>(), 10) << eval.out;
  EXPECT_LE(j["median_flux_error"].get<double>(), 0.2);
  EXPECT_GE(j["median_ghost_psnr_db"].get<double>(), 20);
  EXPECT_GE(j["continuity"].get<double>(), 0.95);
  EXPECT_EQ(j["light_ghosts"].get<int>(), 0);
  // The frames' own fits, which the report keeps (0.8° apart, the fit's default frame step: every
  // fourth frame of this 0.2° capture), measure as the model does.
  auto frames = runFlarekit({"-q", "fit-eval", (dir / "report" / "frame_fits.json").string(),
                             (dir / "capture").string(), "--json"});
  ASSERT_EQ(frames.exit_code, 0) << frames.err;
  const auto f = nlohmann::json::parse(frames.out);
  EXPECT_EQ(f["frames_evaluated"].get<int>(), 3);
  EXPECT_GE(f["recall"].get<double>(), 0.95) << frames.out;
  EXPECT_GE(f["median_psnr_db"].get<double>(), 32);
  EXPECT_LE(f["median_centroid_error_px"].get<double>(), 0.5);

  // Against the model's ceiling, measured every 4th frame: each of those frames gets the ceiling's
  // PSNR at its angle, and the plot shows both over the angles.
  auto ceiling =
      runFlarekit({"-q", "fit-ceiling", (dir / "capture").string(), "--every", "4", "--json"});
  ASSERT_EQ(ceiling.exit_code, 0) << ceiling.err;
  std::ofstream(dir / "ceiling.json") << ceiling.out;
  const auto c = nlohmann::json::parse(ceiling.out);
  auto against = runFlarekit({"-q", "fit-eval", model, (dir / "capture").string(), "--ceiling",
                              (dir / "ceiling.json").string(), "--plot",
                              (dir / "eval.png").string(), "--json"});
  ASSERT_EQ(against.exit_code, 0) << against.err;
  const auto a = nlohmann::json::parse(against.out);
  EXPECT_EQ(a["ceiling_frames"].get<int>(), 3);
  for (const auto& cf : c["frames"])
    for (const auto& ef : a["frames"])
      if (ef["angle_deg"] == cf["angle_deg"]) {
        EXPECT_EQ(ef["ceiling_psnr_db"], cf["psnr_db"]);
      }
  EXPECT_TRUE(a["frames"][1]["ceiling_psnr_db"].is_null());
  const cv::Mat plot = cv::imread((dir / "eval.png").string());
  EXPECT_EQ(plot.size(), cv::Size(960, 600));
  // A plot that is no PNG, and a ceiling file that is not one: one line naming the file, exit 2.
  auto bad = runFlarekit(
      {"fit-eval", model, (dir / "capture").string(), "--plot", (dir / "eval.jpg").string()});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(lineCount(bad.err), 1) << bad.err;
  EXPECT_NE(bad.err.find("eval.jpg"), std::string::npos) << bad.err;
  bad = runFlarekit({"fit-eval", model, (dir / "capture").string(), "--ceiling", model});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_EQ(lineCount(bad.err), 1) << bad.err;
  EXPECT_NE(bad.err.find("model.json: is not the output of flarekit fit-ceiling"),
            std::string::npos)
      << bad.err;
  // The ceiling measured on even frames only, and the odd ones evaluated: nothing to compare.
  bad = runFlarekit({"fit-eval", model, (dir / "capture").string(), "--frames", "odd", "--ceiling",
                     (dir / "ceiling.json").string()});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("ceiling.json: has no frame at the angles evaluated"), std::string::npos)
      << bad.err;
  // Frames without truth (an EXR stack) have no ceiling to compare with.
  bad = runFlarekit({"fit-eval", model, (dir / "capture/frames").string(), "--ceiling",
                     (dir / "ceiling.json").string()});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("the capture has none"), std::string::npos) << bad.err;
}

// The same frames give the same model on any machine: five frames of the committed Heliar capture
// (2–4°, several ghosts beside the light), fitted as an EXR stack with 1, 2 and 3 threads, give
// one model file byte for byte. With Ceres evaluating its residual blocks on 2 threads they did
// not (its per-thread cost sums round differently).
TEST(CliFit, TheModelDoesNotDependOnTheThreadCount) {
  TempDir dir;
  const fs::path frames = fs::path(FLAREKIT_SOURCE_DIR) / "data_synthetic/heliar_tronnier_0-20/frames";
  std::string first;
  for (int threads : {1, 2, 3}) {
    const fs::path model = dir / ("model" + std::to_string(threads) + ".json");
    std::vector<std::string> args = {"-q", "fit"};
    for (int i = 4; i <= 8; ++i) args.push_back((frames / cv::format("frame_%04d.exr", i)).string());
    for (const std::string& a : {std::string("--threads"), std::to_string(threads), std::string("--out"), model.string()})
      args.push_back(a);
    auto r = runFlarekit(args);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    std::ifstream in(model);
    const std::string text((std::istreambuf_iterator<char>(in)), {});
    if (threads == 1) first = text;
    else EXPECT_TRUE(text == first) << threads << " threads gave another model than 1";
  }
  EXPECT_FALSE(first.empty());
}

TEST(CliFit, HeldOutFramesThroughThePolynomials) {
  TempDir dir;
  writeCapture(dir / "capture", 12);
  const std::string model = (dir / "model.json").string();
  auto fit = runFlarekit({"-q", "fit", (dir / "capture").string(), "--out", model, "--holdout", "odd",
                          "--report", (dir / "report").string()});
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  auto eval = runFlarekit({"-q", "fit-eval", model, (dir / "capture").string(), "--frames", "odd", "--json"});
  ASSERT_EQ(eval.exit_code, 0) << eval.err;
  const auto j = nlohmann::json::parse(eval.out);
  EXPECT_EQ(j["frames_evaluated"].get<int>(), 6);
  EXPECT_GE(j["median_psnr_db"].get<double>(), 30) << eval.out;
  // The held-out frames have no fits of their own: one line, exit 2.
  const std::string fits = (dir / "report" / "frame_fits.json").string();
  auto none = runFlarekit({"-q", "fit-eval", fits, (dir / "capture").string(), "--frames", "odd"});
  EXPECT_EQ(none.exit_code, 2);
  EXPECT_EQ(lineCount(none.err), 1) << none.err;
  EXPECT_NE(none.err.find("frame_fits.json"), std::string::npos) << none.err;
}

// `bench fit` starts both optimizers from the same seed on the same cost and says where each
// ended. On two well-separated ghosts in light noise both lower the cost, and Ceres reaches the
// gradient descent's final cost.
TEST(CliFit, BenchStartsBothOptimizersFromOneSeedAndReportsWhereTheyEnd) {
  TempDir dir;
  writeCapture(dir / "capture", 6);
  auto r = runFlarekit({"-q", "bench", "fit", (dir / "capture").string(), "--frames", "2",
                        "--gd-iterations", "60", "--json"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["cases"].size(), 2u) << r.out;
  EXPECT_EQ(j["cases_total"].get<int>(), 2);
  for (const auto& c : j["cases"]) {
    const double initial = c["initial_cost"];
    EXPECT_LT(c["gd_final_cost"].get<double>(), initial) << c.dump();
    EXPECT_LT(c["ceres_final_cost"].get<double>(), initial) << c.dump();
    EXPECT_FALSE(c["ceres_termination"].get<std::string>().empty());
    const size_t parameters = c["seed"].size();
    EXPECT_EQ(c["gd_final_parameters"].size(), parameters);
    EXPECT_EQ(c["ceres_final_parameters"].size(), parameters);
    EXPECT_NE(c["ceres_final_parameters"], c["seed"]);
    EXPECT_TRUE(c["ceres_reached_gd_cost"].get<bool>()) << c.dump();
  }
}

// The ceiling of a capture whose ghosts have the model's own shape: every ghost described to the
// pixel, in every other frame.
TEST(CliFit, CeilingOfACaptureOfModelShapedGhosts) {
  TempDir dir;
  writeCapture(dir / "capture", 4);
  auto r = runFlarekit({"-q", "fit-ceiling", (dir / "capture").string(), "--every", "2", "--json", "--sheets",
                        (dir / "sheets").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // One picture per measured frame: noise-free flare | ceiling | |flare − ceiling|; the ghosts are
  // described exactly, so the ceiling looks like the flare and the difference is dark.
  for (const char* name : {"ceiling_0.00.png", "ceiling_0.40.png"}) {
    const cv::Mat sheet = cv::imread((dir / "sheets" / name).string(), cv::IMREAD_GRAYSCALE);
    ASSERT_EQ(sheet.cols, 3 * 200) << name;
    // Below the labels (their descenders reach row 24).
    const cv::Mat flare = sheet(cv::Rect(1, 26, 198, 104)), ceiling = sheet(cv::Rect(200 + 1, 26, 198, 104)),
                  difference = sheet(cv::Rect(400 + 1, 26, 198, 104));
    EXPECT_LT(cv::norm(flare, ceiling, cv::NORM_L1) / flare.total(), 2) << name;
    double brightest = 0, brightest_difference = 0;
    cv::minMaxLoc(flare, nullptr, &brightest);
    cv::minMaxLoc(difference, nullptr, &brightest_difference);
    EXPECT_GT(brightest, 100) << name;
    EXPECT_LT(brightest_difference, 0.5 * brightest) << name;
  }
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["frames_measured"].get<int>(), 2);
  EXPECT_EQ(j["visible_ghosts"].get<int>(), 4);
  EXPECT_EQ(j["within_half_px"].get<int>(), 4);
  EXPECT_GT(j["median_psnr_db"].get<double>(), 40);
  EXPECT_LT(j["median_centroid_error_px"].get<double>(), 0.1);
  // Without --json: one line that says what was measured.
  r = runFlarekit({"-q", "fit-ceiling", (dir / "capture").string(), "--every", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("Model ceiling over 2 frame(s)", 0), 0u) << r.out;
  // Frames without truth (an EXR stack) and a step of 0: one line, exit 2.
  r = runFlarekit({"fit-ceiling", (dir / "capture/frames").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("no ground truth"), std::string::npos) << r.err;
  r = runFlarekit({"fit-ceiling", (dir / "capture").string(), "--every", "0"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--every"), std::string::npos) << r.err;
  // --fit-above: only the ghosts brighter than that many σ are described, the rest as a flat
  // pedestal. Above every ghost's peak, none is: the ceiling is the flare's mean, far below the
  // ceiling of every ghost, and the file says so.
  r = runFlarekit({"-q", "fit-ceiling", (dir / "capture").string(), "--every", "2", "--json", "--fit-above", "1e9"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto none = nlohmann::json::parse(r.out);
  EXPECT_EQ(none["fit_above_sigma"].get<double>(), 1e9);
  EXPECT_EQ(none["visible_ghosts"].get<int>(), 0);
  EXPECT_LT(none["median_psnr_db"].get<double>(), j["median_psnr_db"].get<double>() - 20) << r.out;
  for (const auto& f : none["frames"]) {
    EXPECT_TRUE(f["ghosts"].empty());
    EXPECT_GT(f["pedestal"].get<double>(), 0);
  }
  EXPECT_EQ(j["fit_above_sigma"].get<double>(), 0);
  EXPECT_EQ(j["frames"][0]["pedestal"].get<double>(), 0);
  r = runFlarekit({"fit-ceiling", (dir / "capture").string(), "--quadratic-pedestal"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--fit-above"), std::string::npos) << r.err;
  r = runFlarekit({"fit-ceiling", (dir / "capture").string(), "--fit-above", "-1"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("--fit-above"), std::string::npos) << r.err;
}

TEST(CliFit, BadInputGivesOneLineAndExitTwo) {
  TempDir dir;
  writeCapture(dir / "capture", 4);
  // A corrupt frame.
  std::ofstream(dir / "capture/frames/frame_0002.exr", std::ios::trunc) << "garbage";
  auto r = runFlarekit({"fit", (dir / "capture").string(), "--out", (dir / "m.json").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("frame_0002.exr"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir / "m.json"));
  // An EXR stack without angles.
  writeExr(dir / "plain.exr", cv::Mat::ones(10, 10, CV_32F));
  r = runFlarekit({"fit", (dir / "plain.exr").string(), "--out", (dir / "m.json").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("angle"), std::string::npos) << r.err;
  // A focal length that is not a positive number, in the manifest or as an option.
  {
    TempDir bad;
    writeCapture(bad / "capture", 4);
    auto m = nlohmann::json::parse(std::ifstream(bad / "capture/manifest.json"));
    m["lens"]["focal_length_mm"] = -50;
    std::ofstream(bad / "capture/manifest.json", std::ios::trunc) << m.dump(2);
    r = runFlarekit({"fit", (bad / "capture").string(), "--out", (bad / "m.json").string()});
    EXPECT_EQ(r.exit_code, 2);
    EXPECT_EQ(lineCount(r.err), 1) << r.err;
    EXPECT_NE(r.err.find("lens.focal_length_mm"), std::string::npos) << r.err;
    r = runFlarekit({"fit", (dir / "capture/frames/frame_0000.exr").string(), "--out", (bad / "m.json").string(),
                     "--focal-length-mm", "-50"});
    EXPECT_EQ(r.exit_code, 2);
    EXPECT_NE(r.err.find("--focal-length-mm"), std::string::npos) << r.err;
  }
  // A frame file that is missing, frames of different sizes, an angle given twice, a frame
  // without its angle: one line naming the file, exit 2.
  auto edited = [&](const std::string& name, const std::function<void(const fs::path&, nlohmann::json&)>& edit,
                    const std::string& expect) {
    TempDir bad;
    writeCapture(bad / "capture", 4);
    auto m = nlohmann::json::parse(std::ifstream(bad / "capture/manifest.json"));
    edit(bad / "capture", m);
    std::ofstream(bad / "capture/manifest.json", std::ios::trunc) << m.dump(2);
    auto e = runFlarekit({"fit", (bad / "capture").string(), "--out", (bad / "m.json").string()});
    EXPECT_EQ(e.exit_code, 2) << name;
    EXPECT_EQ(lineCount(e.err), 1) << name << ": " << e.err;
    EXPECT_NE(e.err.find(expect), std::string::npos) << name << ": " << e.err;
    EXPECT_FALSE(fs::exists(bad / "m.json")) << name;
  };
  edited("missing frame", [](const fs::path& c, nlohmann::json&) { fs::remove(c / "frames/frame_0001.exr"); },
         "frame_0001.exr");
  edited("other size", [](const fs::path& c, nlohmann::json&) {
    ExrAttributes attrs;
    attrs["flarekit.angle_deg"] = 0.4;
    writeExr(c / "frames/frame_0002.exr", cv::Mat::zeros(100, 150, CV_32F) + 0.1, attrs);
  }, "frame_0002.exr");
  edited("repeated angle", [](const fs::path& c, nlohmann::json& m) {
    m["frames"][2]["angle_deg"] = 0.2;
    ExrAttributes attrs;
    attrs["flarekit.angle_deg"] = 0.2;
    writeExr(c / "frames/frame_0002.exr", readExrLayer(c / "frames/frame_0002.exr", ""), attrs);
  }, "0.2");
  edited("no angle", [](const fs::path&, nlohmann::json& m) { m["frames"][3].erase("angle_deg"); },
         "angle_deg");
  // A capture with no ghost in it: an empty model and a clear message, exit 0.
  {
    TempDir empty;
    writeCapture(empty / "capture", 6, 0.0);
    auto e = runFlarekit({"fit", (empty / "capture").string(), "--out", (empty / "m.json").string()});
    EXPECT_EQ(e.exit_code, 0) << e.err;
    EXPECT_NE(e.err.find("No ghost"), std::string::npos) << e.err;
    EXPECT_TRUE(model::FlareModel::load(empty / "m.json").ghosts.empty());
  }
  // An unknown optimizer.
  r = runFlarekit({"fit", (dir / "capture").string(), "--out", (dir / "m.json").string(),
                   "--optimizer", "newton"});
  EXPECT_EQ(r.exit_code, 2);
  // A model file in a folder that does not exist: an I/O failure, said before any fitting.
  r = runFlarekit({"fit", (dir / "capture").string(), "--out", (dir / "missing/m.json").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace flarekit
