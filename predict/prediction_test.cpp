// Prediction end to end on hand-made models: the flare follows the light's direction, scales by
// Eq. 2, vanishes for lights out of range or behind the camera; ratings, ranking, map, report.
#include "predict/prediction.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/testing.h"
#include "predict/report.h"

namespace flarekit::predict {
namespace {

constexpr double kRad = std::numbers::pi / 180.0;

model::Polynomial poly(std::vector<double> c) { return {std::move(c)}; }

// One grey ghost valid for 0 ≤ θ ≤ 30: a disc of radius 12 that moves 6 px per degree to +x at
// roll 0 (away from the light, which is at −x for positive θ), intensity 1.
model::FlareModel oneGhostModel() {
  model::FlareModel m;
  m.capture.camera = "test";
  m.capture.lens = "test lens";
  m.capture.f_number = 8;
  m.capture.iso = 100;
  m.capture.exposure_s = 0.01;
  m.capture.light = "test light";
  m.capture.image_size = {300, 200};
  m.capture.pixel_pitch_um = 6;
  m.capture.angle_step_deg = 1;
  m.channels = 1;
  model::GhostTrack g;
  g.id = 1;
  g.angle_min_deg = 0;
  g.angle_max_deg = 30;
  const double k = model::kEllipseCurvature;
  // Mx My L R h Cl Cr Ib Ii Fi Ei Fo Eo
  g.parameters = {poly({150, 6}), poly({100}), poly({12}), poly({12}), poly({12}), poly({k}), poly({k}),
                  poly({1}),      poly({1}),   poly({4}),  poly({1}),  poly({2}),  poly({1})};
  m.ghosts.push_back(g);
  return m;
}

Scene sceneWithLights(std::vector<std::pair<double, double>> azimuth_elevation_deg, double intensity_cd = 1000) {
  Scene s;
  s.name = "test";
  s.camera.pose = {0, {0, 0, 0}, {0, 0, -1}, {0, 1, 0}};
  s.camera.focal_length_mm = 24;
  s.camera.sensor_width_mm = 36;
  s.camera.sensor_height_mm = 24;
  s.camera.f_number = 8;
  s.camera.iso = 100;
  s.camera.exposure_s = 0.01;
  s.background_level = 0.01;
  for (auto [az, el] : azimuth_elevation_deg) {
    SceneLight l;
    l.name = cv::format("light %.0f/%.0f", az, el);
    l.kind = LightKind::kIntensity;
    l.intensity_cd = intensity_cd;
    const double a = az * kRad, e = el * kRad;
    l.position = {10 * std::sin(a) * std::cos(e), 10 * std::sin(e), -10 * std::cos(a) * std::cos(e)};
    s.lights.push_back(l);
  }
  return s;
}

cv::Point2d centroid(const cv::Mat& rgb) {
  cv::Mat y;
  cv::extractChannel(rgb, y, 1);
  const cv::Moments mo = cv::moments(y);
  return {mo.m10 / mo.m00, mo.m01 / mo.m00};
}

TEST(PredictOptions, DefaultsAreValidAndBadValuesAreNot) {
  std::string error;
  EXPECT_TRUE(PredictOptions{}.IsValid(&error)) << error;
  PredictOptions o;
  o.capture_illuminance_lux = -1;
  EXPECT_FALSE(o.IsValid(&error));
  o = {};
  o.map_roll_steps = 1;
  EXPECT_FALSE(o.IsValid(&error));
  o = {};
  o.image_width_px = -1;
  EXPECT_FALSE(o.IsValid(&error));
  o = {};
  o.estimators.log_epsilon = -1;
  EXPECT_FALSE(o.IsValid(&error));
}

TEST(Prediction, GhostsLieOppositeTheLightInEveryDirection) {
  const model::FlareModel m = oneGhostModel();
  const cv::Size size{300, 200};
  const cv::Point2d centre{150, 100};
  struct Case {
    double az, el;
    cv::Point2d expected_side;  // unit direction of the ghost from the centre
  };
  for (const Case& c : {Case{-10, 0, {1, 0}}, Case{10, 0, {-1, 0}}, Case{0, 10, {0, 1}}, Case{0, -10, {0, -1}}}) {
    const Scene s = sceneWithLights({{c.az, c.el}});
    const cv::Mat overlay = renderOverlay(m, s, s.camera.pose, size, PredictOptions{});
    const cv::Point2d d = centroid(overlay) - centre;
    // 10° → 60 capture px from the centre, opposite the light.
    EXPECT_NEAR(d.x, 60 * c.expected_side.x, 1.0) << c.az << "/" << c.el;
    EXPECT_NEAR(d.y, 60 * c.expected_side.y, 1.0) << c.az << "/" << c.el;
  }
}

TEST(Prediction, LightColourTintsWithoutChangingLuminance) {
  const model::FlareModel m = oneGhostModel();
  const cv::Size size{300, 200};
  Scene white = sceneWithLights({{-6, 0}});
  Scene warm = white;
  warm.lights[0].color = {1.0, 0.5, 0.25};
  const cv::Mat a = renderOverlay(m, white, white.camera.pose, size, PredictOptions{});
  const cv::Mat b = renderOverlay(m, warm, warm.camera.pose, size, PredictOptions{});
  const cv::Scalar sa = cv::sum(a), sb = cv::sum(b);
  // Same Rec. 709 luminance, channel ratios of the colour.
  const double ya = 0.2126 * sa[0] + 0.7152 * sa[1] + 0.0722 * sa[2];
  const double yb = 0.2126 * sb[0] + 0.7152 * sb[1] + 0.0722 * sb[2];
  EXPECT_NEAR(yb / ya, 1.0, 1e-5);
  EXPECT_NEAR(sb[1] / sb[0], 0.5, 1e-5);
  EXPECT_NEAR(sb[2] / sb[0], 0.25, 1e-5);
}

TEST(Prediction, RgbModelsKeepTheirChannels) {
  // The same ghost with RGB intensities (Ib = Ii = 1, 0.5, 0.2): the overlay keeps the ratios.
  model::FlareModel m = oneGhostModel();
  m.channels = 3;
  auto& p = m.ghosts[0].parameters;
  p = {p[0], p[1], p[2], p[3], p[4], p[5], p[6], poly({1}), poly({0.5}), poly({0.2}), poly({1}), poly({0.5}),
       poly({0.2}), p[9], p[10], p[11], p[12]};
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  Scene s = sceneWithLights({{-6, 0}});
  const cv::Scalar sum = cv::sum(renderOverlay(m, s, s.camera.pose, {300, 200}, PredictOptions{}));
  EXPECT_NEAR(sum[1] / sum[0], 0.5, 1e-5);
  EXPECT_NEAR(sum[2] / sum[0], 0.2, 1e-5);
}

TEST(Prediction, OutOfRangeAndBehindLightsAddNothing) {
  const model::FlareModel m = oneGhostModel();
  const Scene s = sceneWithLights({{40, 0}, {0, 150}, {100, 0}});
  std::vector<LightPrediction> lights;
  const cv::Mat overlay = renderOverlay(m, s, s.camera.pose, {300, 200}, PredictOptions{}, &lights);
  EXPECT_EQ(cv::countNonZero(overlay.reshape(1)), 0);
  ASSERT_EQ(lights.size(), 3u);
  EXPECT_EQ(lights[0].geometry.status, LightStatus::kOutOfRange);
  EXPECT_EQ(lights[1].geometry.status, LightStatus::kBehindCamera);
  EXPECT_EQ(lights[2].geometry.status, LightStatus::kBehindCamera);
  for (const auto& l : lights) EXPECT_EQ(l.ghost_count, 0);
}

TEST(Prediction, OverlayScalesWithEq2AndLightsAdd) {
  const model::FlareModel m = oneGhostModel();
  const cv::Size size{300, 200};
  Scene a = sceneWithLights({{-8, 0}});
  Scene b = sceneWithLights({{5, 5}});
  Scene both = sceneWithLights({{-8, 0}, {5, 5}});
  const PredictOptions o;
  const double sum_a = cv::sum(renderOverlay(m, a, a.camera.pose, size, o))[1];
  const double sum_b = cv::sum(renderOverlay(m, b, b.camera.pose, size, o))[1];
  EXPECT_NEAR(cv::sum(renderOverlay(m, both, both.camera.pose, size, o))[1], sum_a + sum_b, 1e-4 * (sum_a + sum_b));
  // Twice the scene's exposure time, or twice the light, doubles the flare (Eq. 2).
  a.camera.exposure_s *= 2;
  EXPECT_NEAR(cv::sum(renderOverlay(m, a, a.camera.pose, size, o))[1], 2 * sum_a, 1e-4 * sum_a);
  a.camera.exposure_s /= 2;
  a.lights[0].intensity_cd *= 2;
  EXPECT_NEAR(cv::sum(renderOverlay(m, a, a.camera.pose, size, o))[1], 2 * sum_a, 1e-4 * sum_a);
  // One stop more on the capture side (brighter reference) halves it.
  PredictOptions brighter = o;
  brighter.capture_illuminance_lux = 2 * captureIlluminance(m, o);
  a.lights[0].intensity_cd /= 2;
  EXPECT_NEAR(cv::sum(renderOverlay(m, a, a.camera.pose, size, brighter))[1], 0.5 * sum_a, 1e-4 * sum_a);
}

TEST(Prediction, UsesTheCalibrationTheModelRecords) {
  model::FlareModel m = oneGhostModel();
  const Scene a = sceneWithLights({{-5, 0}});
  const cv::Size size = predictionImageSize(m, a, 150);
  PredictOptions o;
  std::string source;
  // Nothing recorded: the placeholder, said to be assumed.
  EXPECT_EQ(captureIlluminance(m, o, &source), kAssumedCaptureIlluminanceLux);
  EXPECT_EQ(source, "assumed");
  const double assumed = cv::sum(renderOverlay(m, a, a.camera.pose, size, o))[1];
  // The rig measured 4× the placeholder: every light's B is 4× smaller.
  m.capture.light_illuminance_lux = 4 * kAssumedCaptureIlluminanceLux;
  EXPECT_EQ(captureIlluminance(m, o, &source), m.capture.light_illuminance_lux);
  EXPECT_EQ(source, "model");
  const double measured = cv::sum(renderOverlay(m, a, a.camera.pose, size, o))[1];
  EXPECT_NEAR(measured, assumed / 4, 1e-4 * assumed);
  // The option overrides the model.
  o.capture_illuminance_lux = kAssumedCaptureIlluminanceLux;
  EXPECT_EQ(captureIlluminance(m, o, &source), kAssumedCaptureIlluminanceLux);
  EXPECT_EQ(source, "option");
  // A recorded clip level turns the overlay into fractions of white: the scene exposed as the
  // capture with the capture's light shows the ghost's peak (intensity 1) at 1 / clip_level.
  o.capture_illuminance_lux = 0;
  m.capture.clip_level = 0.25;
  Scene same = sceneWithLights({{-5, 0}});
  same.camera.f_number = m.capture.f_number;
  same.camera.iso = m.capture.iso;
  same.camera.exposure_s = m.capture.exposure_s;
  same.lights[0].intensity_cd = m.capture.light_illuminance_lux * 100;  // at 10 m
  double peak = 0;
  cv::minMaxLoc(renderOverlay(m, same, same.camera.pose, size, o).reshape(1), nullptr, &peak);
  EXPECT_NEAR(peak, 1 / 0.25, 1e-3);
}

TEST(Prediction, AnalyzeRanksRatesAndMaps) {
  const model::FlareModel m = oneGhostModel();
  // The same light at 5° and at 20°, and one out of range. Farther off-axis the ghost leaves the
  // frame partly, so the 5° light has the larger mean.
  Scene s = sceneWithLights({{-25, 0}, {-5, 0}, {45, 0}});
  s.camera_path = {{0, {0, 0, 0}, {0, 0, -1}, {0, 1, 0}}, {1, {0, 0, 0}, {-0.5, 0, -1}, {0, 1, 0}}};
  PredictOptions o;
  o.map_angle_steps = 6;
  o.map_roll_steps = 8;
  cv::Mat overlay, composite;
  const PredictionSummary r = analyze(m, s, o, &overlay, &composite);
  ASSERT_EQ(r.lights.size(), 3u);
  EXPECT_EQ(r.lights[1].rank, 1);
  EXPECT_EQ(r.lights[0].rank, 2);
  EXPECT_EQ(r.lights[2].rank, 3);
  EXPECT_GT(r.lights[1].severity, r.lights[0].severity);
  EXPECT_TRUE(std::isnan(r.lights[2].severity_percentile));
  for (int k : {0, 1}) {
    EXPECT_GE(r.lights[k].severity_percentile, 0);
    EXPECT_LE(r.lights[k].severity_percentile, 100);
  }
  ASSERT_EQ(r.ratings.size(), allEstimators().size());
  for (const auto& rating : r.ratings) EXPECT_EQ(rating.distribution.size(), 31u);  // 0..30 at 1°
  ASSERT_EQ(r.map.values.size(), 6u);
  ASSERT_EQ(r.map.values[0].size(), 8u);
  EXPECT_NEAR(r.map.max_angle_deg, 30, 1e-12);
  // Near the axis the ghost is in the frame whatever the roll (mean > 0); at the outer ring it
  // leaves the 300 × 200 frame (6 px/° from the centre) when rolled towards the short side.
  for (size_t i = 0; i < 3; ++i)
    for (double v : r.map.values[i]) EXPECT_GT(v, 0) << "ring " << i;
  const auto& outer = r.map.values.back();
  EXPECT_EQ(*std::min_element(outer.begin(), outer.end()), 0);
  EXPECT_GT(*std::max_element(outer.begin(), outer.end()), 0);
  ASSERT_EQ(r.timeline.size(), 2u);
  EXPECT_EQ(r.timeline[0].lights_in_range, 2);
  // The composite is the background plus the overlay.
  EXPECT_NEAR(cv::sum(composite)[1], cv::sum(overlay)[1] + 0.01 * overlay.total(), 1e-3 * cv::sum(composite)[1]);
  EXPECT_NE(r.BriefReport().find("1 out of range"), std::string::npos) << r.BriefReport();
  EXPECT_EQ(toJson(r)["lights"].size(), 3u);
}

// The model draws ghosts at its capture's focal length per sensor width: a scene camera that sees
// wider or narrower gets one warning line, in the summary and estimators.json; one that sees the
// same (another sensor, focal length in proportion) or a model without a focal length gets none.
TEST(Prediction, WarnsWhenTheSceneCameraDoesNotSeeAsTheCaptureDid) {
  model::FlareModel m = oneGhostModel();  // 300 px × 6 µm: a 1.8 mm wide sensor
  Scene s = sceneWithLights({{-5, 0}});   // 24 mm on 36 mm
  s.file = "stage.json";
  PredictOptions o;
  o.map_angle_steps = 2;
  o.map_roll_steps = 2;
  EXPECT_TRUE(analyze(m, s, o).warnings.empty());  // focal length not recorded: nothing to check
  m.capture.focal_length_mm = 1.2;                  // 1.2 / 1.8 = 24 / 36
  EXPECT_EQ(cameraMismatch(m, s), "");
  EXPECT_TRUE(analyze(m, s, o).warnings.empty());
  m.capture.focal_length_mm = 1.2 * 1.03;
  const PredictionSummary r = analyze(m, s, o);
  ASSERT_EQ(r.warnings.size(), 1u);
  EXPECT_NE(r.warnings[0].find("stage.json"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("24 mm"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("1.03×"), std::string::npos) << r.warnings[0];
  EXPECT_EQ(r.warnings[0].find('\n'), std::string::npos);
  EXPECT_EQ(toJson(r)["warnings"].size(), 1u);
  m.capture.focal_length_mm = 1.2 * 1.01;  // within the 2 % tolerance
  EXPECT_EQ(cameraMismatch(m, s), "");
}

TEST(Prediction, SeverityMapCellEqualsTheLightPlacedThere) {
  // A map cell is the estimator of one light of the map's brightness at that direction: place a
  // scene light at a cell's (θ, φ) and compare.
  const model::FlareModel m = oneGhostModel();
  PredictOptions o;
  o.map_angle_steps = 4;
  o.map_roll_steps = 4;
  o.map_image_width_px = 150;
  const Scene base = sceneWithLights({{0, 0}});
  const cv::Size size = predictionImageSize(m, base, 150);
  const SeverityMap map = severityMap(m, sceneImage(base, size), 1.0, o);
  const double theta = map.angles_deg[2], phi = map.rolls_deg[1];
  Scene s = base;
  const Vec3 d = cameraDirectionFromAngles(theta, phi);  // camera frame = world (x, −y, −z) here
  s.lights[0].position = {10 * d[0], -10 * d[1], -10 * d[2]};
  // Brightness 1: the scene light gives the capture's l·α with the same exposure.
  s.lights[0].intensity_cd = captureIlluminance(m, o) * 100;
  const cv::Mat overlay = renderOverlay(m, s, s.camera.pose, size, o);
  EXPECT_NEAR(computeEstimators(overlay, sceneImage(s, size)).mean, map.values[2][1], 1e-6);
}

TEST(Report, IsOneSelfContainedPage) {
  const model::FlareModel m = oneGhostModel();
  const Scene s = sceneWithLights({{-5, 2}, {3, -4}, {50, 0}});
  PredictOptions o;
  o.map_angle_steps = 4;
  o.map_roll_steps = 6;
  testing::TempDir dir;
  const PredictionSummary r = predict(m, s, o, dir / "out", "model.json");
  for (const char* f : {"overlay.exr", "composite.png", "estimators.json", "report.html"})
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / f)) << f;
  const std::string html = reportHtml(r, m, s, cv::Mat(200, 300, CV_32FC3, cv::Scalar::all(0.1)),
                                      cv::Mat(200, 300, CV_32FC3, cv::Scalar::all(0)));
  EXPECT_NE(html.find("id=\"severity-map\""), std::string::npos);
  EXPECT_NE(html.find("data:image/png;base64,"), std::string::npos);
  for (const auto& l : s.lights) EXPECT_NE(html.find(l.name), std::string::npos);
  EXPECT_EQ(html.find("http://"), html.find("http://www.w3.org/2000/svg"));  // no external resources
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
}

TEST(Report, MapLabelsNeitherOverlapNorLeaveThePage) {
  // Two lights 0.3° and 3° apart (their labels would print over each other), and one beyond the
  // model's range on the map's right rim (its label would run off the page).
  SeverityMap map;
  map.max_angle_deg = 20;
  map.angles_deg = {5, 15};
  map.rolls_deg = {90, 270};
  map.values = {{1, 2}, {3, 4}};
  std::vector<LightPrediction> lights(3);
  const double angles[] = {5, 5.3, 48}, rolls[] = {200, 203, 180};
  const char* names[] = {"key spot left", "key spot right", "flood (off-stage)"};
  for (int i = 0; i < 3; ++i) {
    lights[i].name = names[i];
    lights[i].rank = i + 1;
    lights[i].ghost_count = i < 2 ? 1 : 0;
    lights[i].geometry.angle_deg = angles[i];
    lights[i].geometry.roll_deg = rolls[i];
    lights[i].geometry.status = i < 2 ? LightStatus::kInRange : LightStatus::kOutOfRange;
  }
  const int width = 640;
  const std::string svg = polarMapSvg(map, lights, width);
  // Each label's box as the SVG places it: anchor, position, and at most 7 px a character (bold
  // 11 px sans-serif) by 13 px.
  std::vector<cv::Rect2d> boxes;
  for (size_t at = svg.find("font-weight=\"bold\">"); at != std::string::npos;
       at = svg.find("font-weight=\"bold\">", at + 1)) {
    const size_t start = svg.rfind("<text ", at);
    double x = 0, y = 0;
    char anchor[8] = {};
    ASSERT_EQ(std::sscanf(svg.c_str() + start, "<text x=\"%lf\" y=\"%lf\" text-anchor=\"%7[a-z]\"", &x, &y, anchor), 3);
    const size_t text = at + std::strlen("font-weight=\"bold\">");
    const std::string label = svg.substr(text, svg.find('<', text) - text);
    const double w = 7.0 * static_cast<double>(label.size());  // ASCII names here
    boxes.emplace_back(std::string(anchor) == "end" ? x - w : x, y - 11, w, 13);
  }
  ASSERT_EQ(boxes.size(), 3u) << svg;
  for (size_t i = 0; i < boxes.size(); ++i) {
    EXPECT_GE(boxes[i].x, 0) << i;
    EXPECT_LE(boxes[i].x + boxes[i].width, width) << i;
    for (size_t j = 0; j < i; ++j) EXPECT_EQ((boxes[i] & boxes[j]).area(), 0) << i << " over " << j;
  }
}

TEST(Report, Base64OfKnownStrings) {
  auto b = [](std::string s) { return base64(std::vector<unsigned char>(s.begin(), s.end())); };
  EXPECT_EQ(b(""), "");
  EXPECT_EQ(b("f"), "Zg==");
  EXPECT_EQ(b("fo"), "Zm8=");
  EXPECT_EQ(b("foo"), "Zm9v");
  EXPECT_EQ(b("foobar"), "Zm9vYmFy");
}

}  // namespace
}  // namespace flarekit::predict
