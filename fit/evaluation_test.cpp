// Tests of fit-eval's measures on hand-made frames whose truth is known: the match gate follows a
// ghost's size, not a caustic's spike on it; the noise floor is the background's noise, not the
// shot noise of the light's core, and a demosaic's smoothing does not lower it; the per-pair
// figures (centroid error in % of the radius, flux error, PSNR over the ghost's support), track
// continuity and the model ghosts drawn on the light.
#include "fit/evaluation.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "common/testing.h"
#include "fit/testing.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {
namespace fs = std::filesystem;
using flarekit::testing::TempDir;

const cv::Size kSize(200, 130);

cv::Mat whiteNoise(cv::Size size, double sigma, uint64_t seed) {
  cv::Mat noise(size, CV_32F);
  cv::RNG(seed).fill(noise, cv::RNG::NORMAL, 0, sigma);
  return noise;
}

model::GhostParameters disc(double x, double y, double radius, double value) {
  model::GhostParameters g;
  g.center_x = x;
  g.center_y = y;
  g.left = g.right = g.height = radius;
  g.border = {value, 0, 0};
  g.inside = {value, 0, 0};
  g.inside_falloff = 2;
  g.outside_falloff = 1;
  return g;
}

cv::Mat render(const model::GhostParameters& g) {
  std::vector<model::GhostParameters> one = {g};
  return model::renderGhosts(one, kSize, 1);
}

// A model holding `g` unchanged over 0–1°.
model::FlareModel modelOf(const model::GhostParameters& g) {
  model::FlareModel m;
  m.channels = 1;
  m.capture.image_size = kSize;
  m.capture.pixel_pitch_um = 10;
  model::GhostTrack t;
  t.id = 0;
  t.angle_min_deg = 0;
  t.angle_max_deg = 1;
  for (double v : model::toParameterVector(g)) t.parameters.push_back({{v}});
  m.ghosts.push_back(t);
  return m;
}

// A one-frame stack at θ = 0.5° with its truth files in `dir`: `radiance` is the noise-free frame
// (light and ghosts), `ghosts` the ghosts' own layers (ids 0, 1, …).
FrameStack stackOf(const TempDir& dir, const cv::Mat& frame, const cv::Mat& radiance,
                   const std::vector<cv::Mat>& ghosts) {
  FrameStack s;
  s.size = kSize;
  s.has_truth = true;
  Frame f;
  f.angle_deg = 0.5;
  f.image = frame;
  f.valid = cv::Mat(kSize, CV_8U, cv::Scalar(255));
  f.truth_file = dir / "truth.exr";
  f.ghosts_file = dir / "ghosts.exr";
  writeExr(f.truth_file, radiance);
  ExrImage layers;
  for (size_t g = 0; g < ghosts.size(); ++g) layers.layers.push_back({"ghost." + std::to_string(g), ghosts[g]});
  writeExr(f.ghosts_file, layers);
  s.frames.push_back(f);
  return s;
}

FrameStack stackOf(const TempDir& dir, const cv::Mat& frame, const cv::Mat& radiance, const cv::Mat& ghost) {
  return stackOf(dir, frame, radiance, std::vector<cv::Mat>{ghost});
}

// Copies of the stack's first frame (pixels and truth) at further angles.
void addFramesAt(FrameStack& stack, std::initializer_list<double> angles_deg) {
  for (double angle : angles_deg) {
    stack.frames.push_back(stack.frames[0]);
    stack.frames.back().angle_deg = angle;
  }
}

TEST(EvaluateModel, MatchGateFollowsTheGhostsSizeNotACausticsSpike) {
  TempDir dir;
  // A disc of radius 50 with a caustic's bright spike on its rim (2×2 px at 100× the disc): the
  // area above 10 % of the peak is 4 px, the disc's is 7850.
  cv::Mat ghost = render(disc(100, 65, 50, 1e-3));
  ghost(cv::Rect(99, 17, 2, 2)) += 0.1;
  // The model's disc 8 px to the right: within a quarter of the radius (12.5 px), well outside the
  // 3 px gate a spike-sized radius would give.
  const auto ev = evaluateModel(modelOf(disc(108, 65, 50, 1e-3)), stackOf(dir, ghost, ghost, ghost));
  ASSERT_EQ(ev.frames.size(), 1u);
  EXPECT_EQ(ev.true_ghosts_visible, 1);
  EXPECT_EQ(ev.true_ghosts_found, 1);
  EXPECT_GT(ev.median_centroid_error_px, 3);
  EXPECT_LT(ev.median_centroid_error_px, 12.5);
  EXPECT_DOUBLE_EQ(ev.precision, 1);
  // The pair is listed with its error and the true ghost's radius (which pairs make the median).
  const auto matched = ev.toJson()["frames"][0]["matched"];
  ASSERT_EQ(matched.size(), 1u);
  EXPECT_EQ(matched[0]["true_id"], 0);
  EXPECT_EQ(matched[0]["model_id"], 0);
  EXPECT_DOUBLE_EQ(matched[0]["centroid_error_px"].get<double>(), ev.median_centroid_error_px);
  EXPECT_NEAR(matched[0]["radius_px"].get<double>(), 50, 2);
}

// A model ghost matched to no true ghost says whose light it draws: a small disc on the rim of a
// large true ghost, beyond the gate of its centroid, draws a piece of it; a disc where no ghost is
// draws light no ghost has.
TEST(EvaluateModel, AnUnmatchedModelGhostSaysWhetherItDrawsAPieceOfATrueGhost) {
  TempDir dir;
  const cv::Mat ghost = render(disc(70, 65, 50, 1e-3));
  model::FlareModel m = modelOf(disc(70, 65, 50, 1e-3));
  for (const auto& [id, g] : {std::pair{1, disc(105, 65, 8, 1e-3)}, std::pair{2, disc(170, 65, 8, 1e-3)}}) {
    model::GhostTrack t = m.ghosts[0];
    t.id = id;
    t.parameters.clear();
    for (double v : model::toParameterVector(g)) t.parameters.push_back({{v}});
    m.ghosts.push_back(t);
  }
  const auto ev = evaluateModel(m, stackOf(dir, ghost, ghost, ghost));
  ASSERT_EQ(ev.frames.size(), 1u);
  EXPECT_EQ(ev.true_ghosts_found, 1);
  EXPECT_EQ(ev.model_ghosts, 3);
  EXPECT_EQ(ev.model_ghosts_matched, 1);
  const auto& unmatched = ev.frames[0].unmatched;
  ASSERT_EQ(unmatched.size(), 2u);
  EXPECT_EQ(unmatched[0].model_id, 1);  // on the true disc, 35 px from its centroid (gate 12.5)
  EXPECT_EQ(unmatched[0].true_id, 0);
  EXPECT_GT(unmatched[0].fraction_in_true, 0.95);
  EXPECT_TRUE(unmatched[0].piece());
  EXPECT_EQ(unmatched[1].model_id, 2);  // 50 px beyond the true disc's rim
  EXPECT_EQ(unmatched[1].true_id, -1);
  EXPECT_FALSE(unmatched[1].piece());
  EXPECT_EQ(ev.model_ghosts_pieces, 1);
  ASSERT_EQ(ev.true_ghosts.size(), 1u);
  EXPECT_EQ(ev.true_ghosts[0].unmatched_pieces, 1);
  const auto j = ev.toJson();
  EXPECT_EQ(j["model_ghosts_pieces"], 1);
  EXPECT_EQ(j["frames"][0]["unmatched"][0]["piece"], true);
  EXPECT_EQ(j["frames"][0]["unmatched"][1]["true_id"], -1);
  EXPECT_NE(ev.BriefReport().find("Unmatched model ghosts: 2; 1 of them draw a piece of a true ghost (ghost 0: 1)"),
            std::string::npos)
      << ev.BriefReport();
}

TEST(EvaluateModel, AMissedGhostSaysWhereItIsAndHowFarTheNearestModelGhostIs) {
  TempDir dir;
  const cv::Mat ghost = render(disc(60, 65, 20, 1e-3));
  // The model's disc 40 px to the right: beyond the gate of max(3, 20 / 4) px.
  const auto ev = evaluateModel(modelOf(disc(100, 65, 20, 1e-3)), stackOf(dir, ghost, ghost, ghost));
  ASSERT_EQ(ev.frames.size(), 1u);
  EXPECT_EQ(ev.true_ghosts_found, 0);
  ASSERT_EQ(ev.frames[0].missed.size(), 1u);
  const auto& miss = ev.frames[0].missed[0];
  EXPECT_EQ(miss.id, 0);
  EXPECT_NEAR(miss.centroid.x, 60, 0.5);
  EXPECT_NEAR(miss.centroid.y, 65, 0.5);
  EXPECT_NEAR(miss.radius_px, 20, 1.5);
  EXPECT_EQ(miss.nearest_model_id, 0);
  EXPECT_NEAR(miss.nearest_distance_px, 40, 0.5);
  EXPECT_EQ(ev.toJson()["frames"][0]["missed"][0]["nearest_model_id"], 0);
}

TEST(EvaluateModel, NoiseFloorIsTheBackgroundsNotTheLightsShotNoise) {
  TempDir dir;
  const model::GhostParameters g = disc(140, 65, 20, 3e-3);
  const cv::Mat ghost = render(g);
  // The light's clipped-free core: bright, with shot noise 500× the background's.
  cv::Mat radiance = ghost.clone();
  radiance(cv::Rect(30, 45, 40, 40)) += 1.0;
  cv::Mat noise(kSize, CV_32F);
  cv::theRNG().state = 7;
  cv::randn(noise, 0, 1e-4);
  cv::Mat core_noise(40, 40, CV_32F);
  cv::randn(core_noise, 0, 0.05);
  noise(cv::Rect(30, 45, 40, 40)) += core_noise;
  // The frame-wide RMS of the noise is ~0.012, which would hide a ghost of peak 3e-3 (30× the
  // background's σ) below the 10 × σ visibility rule.
  const auto ev = evaluateModel(modelOf(g), stackOf(dir, radiance + noise, radiance, ghost));
  ASSERT_EQ(ev.frames.size(), 1u);
  EXPECT_NEAR(ev.frames[0].noise_sigma, 1e-4, 0.2e-4);
  EXPECT_EQ(ev.true_ghosts_visible, 1);
  EXPECT_EQ(ev.true_ghosts_found, 1);
}

// The noise floor of white noise is its σ, per pixel or over blocks. The same photosites' noise
// demosaiced from an RGGB mosaic has half that spread per pixel; over blocks its floor is within
// 10 % of the white noise's.
TEST(NoiseFloor, ADemosaicsSmoothingDoesNotLowerIt) {
  const cv::Size size(320, 240);
  const cv::Mat white = whiteNoise(size, 1e-4, 11);
  const cv::Mat valid(size, CV_8U, cv::Scalar(255));
  EXPECT_NEAR(noiseFloor(white, valid, 1), 1e-4, 3e-6);
  EXPECT_NEAR(noiseFloor(white, valid), 1e-4, 5e-6);
  const cv::Mat bayer = testing::bayerLuminance(white);
  EXPECT_LT(noiseFloor(bayer, valid, 1), 0.6 * noiseFloor(white, valid, 1));
  EXPECT_NEAR(noiseFloor(bayer, valid) / noiseFloor(white, valid), 1, 0.1);
  // Invalid pixels leave their blocks out; with none valid there is no floor.
  cv::Mat half = valid.clone();
  half(cv::Rect(0, 0, size.width / 2, size.height)) = 0;
  EXPECT_NEAR(noiseFloor(white, half), 1e-4, 7e-6);
  EXPECT_EQ(noiseFloor(white, cv::Mat::zeros(size, CV_8U)), 0);
}

// A ghost at 14 σ of the photosites' noise is visible on a mono frame and on an RGGB frame of the
// same noise, demosaiced; one at 7 σ on neither (per pixel, the demosaiced noise is half as wide,
// and the 7 σ ghost would clear 10 × that).
TEST(EvaluateModel, VisibilityDoesNotDependOnTheSensorsLayout) {
  TempDir dir;
  const model::GhostParameters g = disc(100, 65, 20, 1.4e-3);
  const cv::Mat white = whiteNoise(kSize, 1e-4, 5);
  const cv::Mat demosaiced = testing::bayerLuminance(white);
  for (const cv::Mat& noise : {white, demosaiced}) {
    const cv::Mat ghost = render(g);
    const auto ev = evaluateModel(modelOf(g), stackOf(dir, ghost + noise, ghost, ghost));
    ASSERT_EQ(ev.frames.size(), 1u);
    EXPECT_NEAR(ev.frames[0].noise_sigma, 1e-4, 1e-5);
    EXPECT_EQ(ev.true_ghosts_visible, 1);
    const cv::Mat faint = render(disc(100, 65, 20, 0.7e-3));
    EXPECT_EQ(evaluateModel(modelOf(g), stackOf(dir, faint + noise, faint, faint)).true_ghosts_visible, 0);
  }
  EXPECT_LT(noiseFloor(demosaiced, cv::Mat(kSize, CV_8U, cv::Scalar(255)), 1), 0.6e-4);
}

// Two true discs, each matched: ghost 0 drawn exactly, ghost 1 3 px to the right and 1.2× as
// bright. Ghost 1's centroid error is 3 px, 15 % of its 20 px radius; its flux error 20 %; its
// PSNR over its own support that of a 20 % error there, whatever ghost 0's exact pixels.
TEST(EvaluateModel, PerGhostCentroidErrorInRadiiFluxErrorAndPsnrOverItsSupport) {
  TempDir dir;
  const model::GhostParameters t0 = disc(50, 65, 20, 1e-3), t1 = disc(150, 65, 20, 1e-3);
  const cv::Mat g0 = render(t0), g1 = render(t1);
  const cv::Mat noise = whiteNoise(kSize, 1e-5, 3);
  const FrameStack stack = stackOf(dir, g0 + g1 + noise, g0 + g1, std::vector<cv::Mat>{g0, g1});
  FrameFits fits;
  fits.image_size = kSize;
  const model::GhostParameters m1 = disc(153, 65, 20, 1.2e-3);
  fits.frames.push_back({0.5, {{0, t0}, {1, m1}}, {}});
  const auto ev = evaluateFrameFits(fits, stack);
  ASSERT_EQ(ev.frames.size(), 1u);
  const auto& matched = ev.frames[0].matched;
  ASSERT_EQ(matched.size(), 2u);
  EXPECT_NEAR(matched[0].centroid_error_pct, 0, 1e-6);
  EXPECT_NEAR(matched[0].flux_error, 0, 1e-6);
  EXPECT_GT(matched[0].psnr_db, 100);
  EXPECT_NEAR(matched[1].centroid_error_px, 3, 0.05);
  EXPECT_DOUBLE_EQ(matched[1].centroid_error_pct, 100 * matched[1].centroid_error_px / matched[1].radius_px);
  EXPECT_NEAR(matched[1].centroid_error_pct, 15, 1);
  EXPECT_NEAR(matched[1].flux_error, 0.2, 1e-3);
  // Over ghost 1's support (its layer > σ): the peak there and the model's whole image.
  const cv::Mat support = g1 > ev.frames[0].noise_sigma;
  const cv::Mat model_image = render(t0) + render(m1);
  double peak = 0;
  cv::minMaxLoc(g0 + g1, nullptr, &peak, nullptr, nullptr, support);
  cv::Mat d = model_image - (g0 + g1);
  const double mse = cv::mean(d.mul(d), support)[0];
  EXPECT_NEAR(matched[1].psnr_db, 10 * std::log10(peak * peak / mse), 0.01);
  EXPECT_LT(matched[1].psnr_db, 20);
  // Medians over the two pairs.
  EXPECT_NEAR(ev.median_centroid_error_pct, matched[1].centroid_error_pct / 2, 1e-9);
  EXPECT_NEAR(ev.median_flux_error, 0.1, 1e-3);
  EXPECT_NEAR(ev.median_ghost_psnr_db, (matched[0].psnr_db + matched[1].psnr_db) / 2, 1e-9);
  const nlohmann::json j = ev.toJson();
  EXPECT_DOUBLE_EQ(j["median_flux_error"].get<double>(), ev.median_flux_error);
  EXPECT_DOUBLE_EQ(j["median_centroid_error_pct"].get<double>(), ev.median_centroid_error_pct);
  EXPECT_DOUBLE_EQ(j["median_ghost_psnr_db"].get<double>(), ev.median_ghost_psnr_db);
  EXPECT_DOUBLE_EQ(j["frames"][0]["matched"][1]["flux_error"].get<double>(), matched[1].flux_error);
  const std::string brief = ev.BriefReport();
  EXPECT_NE(brief.find("% of the ghost's radius), median flux error 10 %"), std::string::npos) << brief;
}

// Over four frames: true ghost 0 matched by model ghost 4 twice, by 7 once and missed once
// (continuity 2/4); true ghost 1 matched by model ghost 5 throughout (1).
TEST(EvaluateFrameFits, ContinuityIsTheLargestShareOfATrueGhostsFramesMatchedByOneModelGhost) {
  TempDir dir;
  const model::GhostParameters t0 = disc(50, 65, 20, 1e-3), t1 = disc(150, 65, 20, 1e-3);
  const cv::Mat g0 = render(t0), g1 = render(t1);
  FrameStack stack = stackOf(dir, g0 + g1 + whiteNoise(kSize, 1e-5, 9), g0 + g1, std::vector<cv::Mat>{g0, g1});
  addFramesAt(stack, {0.7, 0.9, 1.1});
  model::GhostParameters off = t0;
  off.center_x = 90;  // 40 px away: missed
  FrameFits fits;
  fits.image_size = kSize;
  fits.frames = {{0.5, {{4, t0}, {5, t1}}, {}},
                 {0.7, {{7, t0}, {5, t1}}, {}},
                 {0.9, {{4, t0}, {5, t1}}, {}},
                 {1.1, {{4, off}, {5, t1}}, {}}};
  const auto ev = evaluateFrameFits(fits, stack);
  ASSERT_EQ(ev.true_ghosts.size(), 2u);
  EXPECT_EQ(ev.true_ghosts[0].frames_visible, 4);
  EXPECT_EQ(ev.true_ghosts[0].frames_found, 3);
  EXPECT_DOUBLE_EQ(ev.true_ghosts[0].continuity, 0.5);
  EXPECT_EQ(ev.true_ghosts[0].continuity_model_id, 4);
  EXPECT_DOUBLE_EQ(ev.true_ghosts[1].continuity, 1);
  EXPECT_EQ(ev.true_ghosts[1].continuity_model_id, 5);
  EXPECT_DOUBLE_EQ(ev.continuity, 0.75);
  const nlohmann::json j = ev.toJson();
  EXPECT_DOUBLE_EQ(j["continuity"].get<double>(), 0.75);
  EXPECT_DOUBLE_EQ(j["true_ghosts"][0]["continuity"].get<double>(), 0.5);
  EXPECT_NE(ev.BriefReport().find("continuity 0.75"), std::string::npos) << ev.BriefReport();
}

// The light's image is the truth's main layer less its ghost layers: here a core and two rays
// (vertical stripes) with a gap between them. Model ghosts matched to no true ghost: one on the
// core (its centroid there), one centred in the gap between the rays (its centroid off the light,
// most of its light on it) count; one in the dark and one drawing a piece of the true ghost (on
// the main layer, not on the light) do not.
TEST(EvaluateModel, CountsModelGhostsOnTheLightsCoreOrStarburst) {
  TempDir dir;
  const cv::Mat ghost = render(disc(150, 65, 25, 1e-3));
  cv::Mat light = render(disc(30, 65, 6, 0.5));
  light(cv::Rect(88, 10, 10, 110)) += 0.01;   // rays at x 88–97 and 100–109
  light(cv::Rect(100, 10, 10, 110)) += 0.01;
  const cv::Mat radiance = ghost + light;
  const cv::Mat frame = radiance + whiteNoise(kSize, 1e-5, 13);
  model::FlareModel m = modelOf(disc(150, 65, 25, 1e-3));
  auto add = [&](int id, const model::GhostParameters& g) {
    model::GhostTrack t = m.ghosts[0];
    t.id = id;
    t.parameters.clear();
    for (double v : model::toParameterVector(g)) t.parameters.push_back({{v}});
    m.ghosts.push_back(t);
  };
  add(1, disc(30, 65, 4, 1e-2));   // on the core
  add(2, disc(99, 65, 6, 1e-3));   // centred in the gap, its sides on the rays
  add(3, disc(60, 20, 5, 1e-3));   // in the dark
  add(4, disc(168, 65, 5, 1e-3));  // on the true ghost, beyond its gate
  const auto ev = evaluateModel(m, stackOf(dir, frame, radiance, ghost));
  ASSERT_EQ(ev.frames.size(), 1u);
  const auto& f = ev.frames[0];
  EXPECT_EQ(f.model_ghosts_matched, 1);
  ASSERT_EQ(f.unmatched.size(), 4u);
  EXPECT_TRUE(f.unmatched[0].centroid_on_light);
  EXPECT_TRUE(f.unmatched[0].onLight());
  EXPECT_FALSE(f.unmatched[1].centroid_on_light);
  EXPECT_GT(f.unmatched[1].fraction_on_light, 0.5);
  EXPECT_TRUE(f.unmatched[1].onLight());
  EXPECT_EQ(f.unmatched[2].fraction_on_light, 0);
  EXPECT_FALSE(f.unmatched[2].onLight());
  EXPECT_TRUE(f.unmatched[3].piece());
  EXPECT_FALSE(f.unmatched[3].onLight());
  EXPECT_EQ(f.light_ghosts, 2);
  EXPECT_EQ(ev.light_ghosts, 2);
  const nlohmann::json j = ev.toJson();
  EXPECT_EQ(j["light_ghosts"], 2);
  EXPECT_EQ(j["frames"][0]["light_ghosts"], 2);
  EXPECT_EQ(j["frames"][0]["unmatched"][1]["on_light"], true);
  EXPECT_NE(ev.BriefReport().find("On the light's core or starburst: 2."), std::string::npos) << ev.BriefReport();
}

TEST(EvaluateFrameFits, MeasuresTheFittedFramesAndLeavesTheOthersOut) {
  TempDir dir;
  const model::GhostParameters g = disc(100, 65, 20, 1e-3);
  const cv::Mat ghost = render(g);
  FrameStack stack = stackOf(dir, ghost, ghost, ghost);
  addFramesAt(stack, {0.7});  // a second frame, not fitted
  FrameFits fits;
  fits.image_size = kSize;
  fits.frames.push_back({0.5, {{4, g}}, {}});
  const auto ev = evaluateFrameFits(fits, stack);
  ASSERT_EQ(ev.frames.size(), 1u);
  EXPECT_DOUBLE_EQ(ev.frames[0].angle_deg, 0.5);
  EXPECT_EQ(ev.true_ghosts_found, 1);
  EXPECT_DOUBLE_EQ(ev.precision, 1);
  EXPECT_LT(ev.median_centroid_error_px, 1e-6);
  EXPECT_GT(ev.median_psnr_db, 100);  // the fit is the truth
  EXPECT_EQ(ev.frames[0].matched[0].model_id, 4);
  // The fit 30 px off: found by neither the gate nor the PSNR.
  fits.frames[0].ghosts[0].parameters.center_x = 70;
  const auto off = evaluateFrameFits(fits, stack);
  EXPECT_EQ(off.true_ghosts_found, 0);
  EXPECT_LT(off.median_psnr_db, 10);
}

TEST(EvaluateFrameFits, SummarisesEachTrueGhostOverTheFrames) {
  TempDir dir;
  const model::GhostParameters g = disc(100, 65, 20, 1e-3);
  const cv::Mat ghost = render(g);
  // Noise of σ = 1e-5 on the frame: the disc's peak is 100 σ.
  cv::Mat noise(kSize, CV_32F);
  cv::RNG(7).fill(noise, cv::RNG::NORMAL, 0, 1e-5);
  FrameStack stack = stackOf(dir, ghost + noise, ghost, ghost);
  addFramesAt(stack, {0.7, 0.9});
  // Found at 0.5°; 30 px off, so missed, at 0.7° and 0.9°.
  model::GhostParameters off = g;
  off.center_x = 70;
  FrameFits fits;
  fits.image_size = kSize;
  fits.frames = {{0.5, {{4, g}}, {}}, {0.7, {{4, off}}, {}}, {0.9, {{4, off}}, {}}};
  const auto ev = evaluateFrameFits(fits, stack);
  ASSERT_EQ(ev.true_ghosts.size(), 1u);
  const TrueGhostSummary& t = ev.true_ghosts[0];
  EXPECT_EQ(t.id, 0);
  EXPECT_EQ(t.frames_visible, 3);
  EXPECT_EQ(t.frames_found, 1);
  EXPECT_DOUBLE_EQ(t.missed_min_deg, 0.7);
  EXPECT_DOUBLE_EQ(t.missed_max_deg, 0.9);
  EXPECT_NEAR(t.median_radius_px, 20, 1.5);
  EXPECT_NEAR(t.missed_median_peak_sigma, 100, 10);
  const nlohmann::json j = ev.toJson()["true_ghosts"][0];
  EXPECT_EQ(j["frames_found"], 1);
  EXPECT_DOUBLE_EQ(j["missed_range_deg"][1].get<double>(), 0.9);
  const std::string brief = ev.BriefReport();
  EXPECT_NE(brief.find("Missed most: ghost 0 in 2 of 3 frames (0.7–0.9°"), std::string::npos) << brief;
  // Found everywhere: no range, nothing named as missed.
  fits.frames = {{0.5, {{4, g}}, {}}, {0.7, {{4, g}}, {}}, {0.9, {{4, g}}, {}}};
  const auto all = evaluateFrameFits(fits, stack);
  ASSERT_EQ(all.true_ghosts.size(), 1u);
  EXPECT_EQ(all.true_ghosts[0].frames_found, 3);
  EXPECT_TRUE(all.toJson()["true_ghosts"][0]["missed_range_deg"].is_null());
  EXPECT_EQ(all.BriefReport().find("Missed most"), std::string::npos);
}

TEST(ModelCeiling, ReachesAGhostOfTheModelsShapeAndNamesOneItCannotDescribe) {
  TempDir dir;
  // Ghost 0 has the model's own shape, with a rim twice as bright as its inside (from a circle of
  // its moment radius, the fit settles into a flat disc at 14.9 dB). Ghost 1 is
  // two discs apart at different heights in one layer, as a ghost split by a fold: no one outline,
  // mirror-symmetric about its axis, covers both.
  const cv::Mat own = render(testing::ghost(60, 65, 25, 30, 22, 2e-3, 1e-3));
  const cv::Mat split = render(disc(130, 40, 12, 3e-3)) + render(disc(170, 95, 20, 1e-3));
  cv::Mat noise(kSize, CV_32F);
  cv::RNG(3).fill(noise, cv::RNG::NORMAL, 0, 1e-5);
  const FrameStack stack = stackOf(dir, own + split + noise, own + split, std::vector<cv::Mat>{own, split});
  const ModelCeiling c = measureModelCeiling(stack);
  ASSERT_EQ(c.frames.size(), 1u);
  ASSERT_EQ(c.frames[0].ghosts.size(), 2u);
  const CeilingGhost& described = c.frames[0].ghosts[0];
  const CeilingGhost& beyond = c.frames[0].ghosts[1];
  EXPECT_TRUE(described.visible);
  EXPECT_TRUE(beyond.visible);
  EXPECT_GT(described.psnr_db, 40);
  EXPECT_LT(described.centroid_error_px, 0.1);
  EXPECT_LT(beyond.psnr_db, 20);
  EXPECT_EQ(c.visible_ghosts, 2);
  EXPECT_GE(c.within_half_px, 1);
  // The frame's ceiling is held down by the ghost the model cannot describe.
  EXPECT_LT(c.median_psnr_db, 25);
  const std::string brief = c.BriefReport();
  EXPECT_NE(brief.find("Described worst: ghost 1,"), std::string::npos) << brief;
  const nlohmann::json j = c.toJson();
  EXPECT_EQ(j["true_ghosts"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["frames"][0]["ghosts"][0]["parameters"]["Mx"].get<double>(), described.parameters.center_x);
  // Every other frame: the second frame is left out.
  FrameStack two = stack;
  addFramesAt(two, {0.7});
  CeilingOptions every_other;
  every_other.frame_step = 2;
  EXPECT_EQ(measureModelCeiling(two, every_other).frames.size(), 1u);
}

// Above a level, only the brighter ghosts are fitted and the fainter ones drawn as one flat
// pedestal: here a layer flat over the frame, 10 σ, under a ghost of the model's shape, 200 σ.
TEST(ModelCeiling, AboveALevelTheFainterGhostsAreDrawnAsAPedestal) {
  TempDir dir;
  const cv::Mat own = render(testing::ghost(60, 65, 25, 30, 22, 2e-3, 1e-3));
  const cv::Mat faint(kSize, CV_32F, cv::Scalar(1e-4));
  cv::Mat noise(kSize, CV_32F);
  cv::RNG(5).fill(noise, cv::RNG::NORMAL, 0, 1e-5);
  const FrameStack stack = stackOf(dir, own + faint + noise, own + faint, std::vector<cv::Mat>{own, faint});
  CeilingOptions above;
  above.fit_factor = 20;
  const ModelCeiling c = measureModelCeiling(stack, above);
  ASSERT_EQ(c.frames.size(), 1u);
  const CeilingFrame& f = c.frames[0];
  ASSERT_EQ(f.ghosts.size(), 1u);
  EXPECT_EQ(f.ghosts[0].id, 0);
  EXPECT_NEAR(f.pedestal, 1e-4, 1e-5);
  EXPECT_EQ(c.fit_above_sigma, 20);
  // Without the pedestal the frame would be 1e-4 short everywhere.
  const cv::Mat region = f.flare > f.noise_sigma;
  double peak = 0;
  cv::minMaxLoc(f.flare, nullptr, &peak, nullptr, nullptr, region);
  const cv::Mat short_by = f.described - f.pedestal - f.flare;
  const double without = 10 * std::log10(peak * peak / cv::mean(short_by.mul(short_by), region)[0]);
  EXPECT_GT(f.psnr_db, without + 5) << without;
  EXPECT_NE(c.BriefReport().find("brighter than 20 σ"), std::string::npos) << c.BriefReport();
  // At 0, every ghost is fitted and no pedestal drawn.
  const ModelCeiling every = measureModelCeiling(stack);
  EXPECT_EQ(every.frames[0].ghosts.size(), 2u);
  EXPECT_EQ(every.frames[0].pedestal, 0);
}

// A faint layer that rises across the frame (as the faint ghosts' sum does along the flare axis):
// a flat pedestal draws its mean, a quadratic one the layer itself.
TEST(ModelCeiling, AQuadraticPedestalFollowsWhatAFlatOneCannot) {
  TempDir dir;
  const cv::Mat own = render(testing::ghost(60, 65, 25, 30, 22, 2e-3, 1e-3));
  cv::Mat faint(kSize, CV_32F);
  for (int y = 0; y < kSize.height; ++y)
    for (int x = 0; x < kSize.width; ++x) faint.at<float>(y, x) = static_cast<float>(2e-5 + 2e-4 * x / kSize.width);
  cv::Mat noise(kSize, CV_32F);
  cv::RNG(7).fill(noise, cv::RNG::NORMAL, 0, 1e-5);
  const FrameStack stack = stackOf(dir, own + faint + noise, own + faint, std::vector<cv::Mat>{own, faint});
  CeilingOptions flat;
  flat.fit_factor = 30;
  CeilingOptions quadratic = flat;
  quadratic.quadratic_pedestal = true;
  const ModelCeiling f = measureModelCeiling(stack, flat), q = measureModelCeiling(stack, quadratic);
  ASSERT_EQ(q.frames.size(), 1u);
  ASSERT_EQ(q.frames[0].ghosts.size(), 1u);
  EXPECT_GT(q.median_psnr_db, f.median_psnr_db + 10) << f.median_psnr_db;
  // Its mean over the flare region, the whole frame here: the layer's.
  EXPECT_NEAR(q.frames[0].pedestal, 1.2e-4, 1e-5);
  EXPECT_EQ(q.toJson()["pedestal"], "quadratic");
  EXPECT_EQ(f.toJson()["pedestal"], "flat");
  EXPECT_NE(q.BriefReport().find("quadratic pedestal"), std::string::npos) << q.BriefReport();
}

TEST(ModelCeiling, NeedsGroundTruth) {
  FrameStack stack;
  stack.size = kSize;
  stack.source = "stack/frame_0000.exr";
  Frame f;
  f.image = render(disc(100, 65, 20, 1e-3));
  f.valid = cv::Mat(kSize, CV_8U, cv::Scalar(255));
  stack.frames.push_back(f);
  try {
    measureModelCeiling(stack);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no ground truth"), std::string::npos) << e.what();
  }
}

TEST(ModelCeiling, EachFrameIsSetAgainstTheCeilingMeasuredAtItsAngle) {
  Evaluation ev;
  ev.has_truth = true;
  for (auto [angle, psnr] :
       std::vector<std::pair<double, double>>{{0, 20}, {1, 25}, {2, 31}, {3, 18}}) {
    FrameEvaluation f;
    f.angle_deg = angle;
    f.psnr_db = psnr;
    ev.frames.push_back(f);
  }
  // The ceiling as fit-ceiling writes it, measured every other frame of this capture, and one more
  // frame the evaluation does not have.
  ModelCeiling c;
  c.image_size = kSize;
  for (auto [angle, psnr] : std::vector<std::pair<double, double>>{{0, 30}, {2, 36}, {5, 50}}) {
    CeilingFrame f;
    f.angle_deg = angle;
    f.psnr_db = psnr;
    c.frames.push_back(f);
  }
  ev.setCeiling(parseCeiling(c.toJson(), kSize, "ceiling.json"));
  EXPECT_DOUBLE_EQ(ev.frames[0].ceiling_psnr_db, 30);
  EXPECT_TRUE(std::isnan(ev.frames[1].ceiling_psnr_db));
  EXPECT_DOUBLE_EQ(ev.frames[2].ceiling_psnr_db, 36);
  EXPECT_EQ(ev.ceiling_frames, 2);
  EXPECT_DOUBLE_EQ(ev.median_ceiling_gap_db, 7.5);  // 10 dB and 5 dB below it
  const std::string brief = ev.BriefReport();
  EXPECT_NE(brief.find("Against the model's ceiling (fit-ceiling) in 2 frame(s): median 7.5 dB "
                       "below it; most at 0° (20 against 30 dB), 2° (31 against 36 dB)."),
            std::string::npos)
      << brief;
  nlohmann::json j = ev.toJson();
  EXPECT_EQ(j["median_ceiling_gap_db"].get<double>(), 7.5);
  EXPECT_EQ(j["ceiling"].get<std::string>(), "the model's ceiling (fit-ceiling)");
  EXPECT_TRUE(j["frames"][1]["ceiling_psnr_db"].is_null());

  // A ceiling of only the ghosts a fitter could find (--fit-above) is named as such: the gap to it
  // is not the gap to the model's best.
  c.fit_above_sigma = 10;
  c.quadratic_pedestal = true;
  ev.setCeiling(parseCeiling(c.toJson(), kSize, "ceiling.json"));
  EXPECT_NE(ev.BriefReport().find("Against the ceiling of the ghosts above 10 σ (fit-ceiling "
                                  "--fit-above 10 --quadratic-pedestal) in 2 frame(s)"),
            std::string::npos)
      << ev.BriefReport();
  j = ev.toJson();
  EXPECT_EQ(j["ceiling"].get<std::string>(),
            "the ceiling of the ghosts above 10 σ (fit-ceiling --fit-above 10 --quadratic-pedestal)");
  EXPECT_EQ(ev.ceiling.label(), "ceiling of the ghosts above 10 sigma");

  // A ceiling of another capture's size, and a file that is no ceiling: the file named, and why.
  try {
    parseCeiling(c.toJson(), {640, 427}, "ceiling.json");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(
                  "ceiling.json: was measured on 200x130 frames, the capture's are 640x427"),
              std::string::npos)
        << e.what();
  }
  try {
    parseCeiling(ev.toJson(), kSize, "eval.json");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("eval.json: is not the output of flarekit fit-ceiling"),
              std::string::npos)
        << e.what();
  }
}

TEST(EvaluationOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(EvaluationOptions{}.IsValid(&error)) << error;
  EvaluationOptions bad;
  bad.noise_block_px = 0;
  EXPECT_FALSE(bad.IsValid(&error));
  bad = {};
  bad.light_factor = 0;
  EXPECT_FALSE(bad.IsValid(&error));
}

TEST(FrameFits, SavesAndLoadsEveryParameterExactly) {
  TempDir dir;
  FrameFits fits;
  fits.image_size = kSize;
  fits.channels = 1;
  model::GhostParameters g = disc(100.125, 65.1, 20.3, 1e-3 / 3);
  g.inside_exponent = 2.5;
  fits.frames.push_back({0.1, {{2, g}, {5, disc(10, 20, 3, 0.5)}}, {}});
  fits.frames.push_back({0.30000000000000004, {}, {}});
  fits.save(dir / "frame_fits.json");
  const FrameFits back = FrameFits::load(dir / "frame_fits.json");
  EXPECT_EQ(back.image_size, kSize);
  ASSERT_EQ(back.frames.size(), 2u);
  ASSERT_EQ(back.frames[0].ghosts.size(), 2u);
  EXPECT_EQ(back.frames[0].ghosts[1].id, 5);
  EXPECT_EQ(model::toParameterVector(back.frames[0].ghosts[0].parameters), model::toParameterVector(g));
  ASSERT_NE(back.at(0.30000000000000004), nullptr);
  EXPECT_EQ(back.at(0.2), nullptr);
}

TEST(FrameFits, ABadFileNamesTheFileAndTheKey) {
  const std::string head =
      R"({"format": "flarekit.frame-fits", "version": 1, "image_width": 200, "image_height": 130, "channels": 1, )";
  auto error = [&](const std::string& frames) {
    try {
      FrameFits::parse(head + R"("frames": )" + frames + "}", "fits.json");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  nlohmann::json params;
  for (const auto& name : model::parameterNames(1)) params[name] = 1.0;
  params["Cl"] = 0.5;
  params["Cr"] = 0.5;
  const std::string good = nlohmann::json({{"id", 1}, {"parameters", params}}).dump();
  EXPECT_EQ(error(R"([{"angle_deg": 1, "ghosts": [)" + good + "]}]"), "no error");
  EXPECT_NE(error(R"([{"angle_deg": 1, "ghosts": []}, {"angle_deg": 1, "ghosts": []}])").find("fits.json: frames[1].angle_deg"),
            std::string::npos);
  params["L"] = -3;  // a negative half-width
  const std::string bad = nlohmann::json({{"id", 1}, {"parameters", params}}).dump();
  EXPECT_NE(error(R"([{"angle_deg": 1, "ghosts": [)" + bad + "]}]").find("fits.json: frames[0].ghosts[0].parameters"),
            std::string::npos);
}

TEST(MedianOf, MiddleValueOrMeanOfTheTwoMiddleOnesOfTheFiniteValues) {
  EXPECT_EQ(medianOf({5, 1, 4, 2, 3}), 3);
  EXPECT_EQ(medianOf({7, 1, 4, 2}), 3);  // (2 + 4) / 2
  const double inf = std::numeric_limits<double>::infinity(), nan = std::nan("");
  EXPECT_EQ(medianOf({nan, 10, -inf, 30, 20, inf}), 20);
  EXPECT_EQ(medianOf({2, 2, 9, 2}), 2);
  EXPECT_TRUE(std::isnan(medianOf({})));
  EXPECT_TRUE(std::isnan(medianOf({nan, inf})));
}

}  // namespace
}  // namespace flarekit::fit
