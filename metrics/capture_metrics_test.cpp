// The figures' definitions on a small synthetic capture whose every number is known: a Gaussian
// light, one ghost, a light exposure per frame, noise-free truth.
#include "metrics/capture_metrics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include <nlohmann/json.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"
#include "metrics/report.h"
#include "model/flare_model.h"
#include "model/model_renderer.h"

namespace flarekit::metrics {
namespace {

namespace fs = std::filesystem;

const cv::Size kSize(160, 107);
constexpr double kLightFlux = 1e4, kLightSigma = 1.2, kClip = 5.0;

cv::Mat gaussian(cv::Point2d c, double sigma, double flux) {
  cv::Mat m(kSize, CV_32F);
  for (int y = 0; y < kSize.height; ++y)
    for (int x = 0; x < kSize.width; ++x) {
      const double r2 = std::pow(x + 0.5 - c.x, 2) + std::pow(y + 0.5 - c.y, 2);
      m.at<float>(y, x) = static_cast<float>(flux / (2 * M_PI * sigma * sigma) * std::exp(-r2 / (2 * sigma * sigma)));
    }
  return m;
}

// The light at x = 80 − 6·θ on row 53.5; a ghost (a disc) mirrored through the axis.
cv::Point2d lightAt(double theta) { return {80 - 6 * theta, 53.5}; }

model::GhostParameters ghostAt(double theta) {
  model::GhostParameters g;
  g.center_x = 80 + 4 * theta;
  g.center_y = 53.5;
  g.left = g.right = g.height = 9;
  g.border = {0.02, 0, 0};
  g.inside = {0.01, 0, 0};
  g.inside_falloff = 3;
  g.outside_falloff = 1.5;
  return g;
}

// A capture folder of `frames` frames 1° apart; the frames clip at kClip (saturated layer) and
// carry noise of σ `noise`; light exposures with the light unclipped; truth with the ghost layer.
void writeCapture(const fs::path& dir, int frames, double noise, bool light_exposures = true,
                  bool truth = true) {
  fs::create_directories(dir / "frames");
  fs::create_directories(dir / "light");
  fs::create_directories(dir / "truth");
  nlohmann::json m = {{"format", "flarekit.capture"}, {"version", 1}, {"status", "complete"},
                      {"lens", {{"name", "test lens"}}},
                      {"camera", {{"description", "test"}, {"iso", 100}, {"f_number", 8}, {"exposures_s", {1.0}}}},
                      {"light", "test light"},
                      {"image", {{"width", kSize.width}, {"height", kSize.height}, {"channels", "Y"},
                                 {"pixel_pitch_um", 10}, {"units", "test units"}}},
                      {"plan", {{"step_deg", 1.0}}},
                      {"truth", truth}};
  if (light_exposures) {
    m["plan"]["light_exposures_s"] = {1e-3};
    m["plan"]["light_nd_factor"] = 1;
  }
  m["frames"] = nlohmann::json::array();
  cv::theRNG().state = 5;
  for (int i = 0; i < frames; ++i) {
    const double theta = i;
    char name[32];
    std::snprintf(name, sizeof name, "frame_%04d", i);
    const cv::Mat light = gaussian(lightAt(theta), kLightSigma, kLightFlux);
    const model::GhostParameters g = ghostAt(theta);
    const cv::Mat ghost = model::renderGhosts(std::span<const model::GhostParameters>(&g, 1), kSize, 1);
    const cv::Mat clean = light + ghost;
    cv::Mat n(kSize, CV_32F);
    cv::randn(n, 0, noise);
    cv::Mat frame = clean + n;
    cv::Mat saturated = clean >= kClip;
    saturated.convertTo(saturated, CV_32F, 1.0 / 255);
    frame.setTo(kClip, clean >= kClip);
    ExrAttributes attrs;
    attrs["flarekit.angle_deg"] = theta;
    writeExr(dir / "frames" / (std::string(name) + ".exr"), ExrImage{{{"", frame}, {"saturated", saturated}}, attrs});
    nlohmann::json e = {{"index", i}, {"angle_deg", theta}, {"file", std::string("frames/") + name + ".exr"}};
    if (light_exposures) {
      cv::Mat ln(kSize, CV_32F);
      cv::randn(ln, 0, 0.05);
      writeExr(dir / "light" / (std::string(name) + ".exr"),
               ExrImage{{{"", cv::Mat(clean + ln)}, {"saturated", cv::Mat::zeros(kSize, CV_32F)}}, attrs});
      e["light"] = {{"file", std::string("light/") + name + ".exr"}};
    }
    if (truth) {
      writeExr(dir / "truth" / (std::string(name) + ".exr"), ExrImage{{{"", clean}, {"ghost.0", ghost}}, attrs});
      e["truth_file"] = std::string("truth/") + name + ".exr";
    }
    m["frames"].push_back(e);
  }
  m["frames_done"] = frames;
  std::ofstream(dir / "manifest.json") << m.dump(1);
}

TEST(Metrics, FiguresOfAKnownCapture) {
  testing::TempDir dir;
  writeCapture(dir / "cap", 9, 1e-4);
  const Metrics m = measureCapture(dir / "cap");
  EXPECT_EQ(m.light.method, "light exposure");
  // The reference: the light nearest the optical zero (θ = 0) whole in the frame.
  EXPECT_NEAR(m.light.angle_deg, 0, 1e-9);
  ASSERT_EQ(m.capture.frames.size(), 9u);
  // The flux disc holds the whole Gaussian (and the ghost's part inside it).
  EXPECT_NEAR(m.light.flux, m.truth_light.flux, 0.002 * m.truth_light.flux);
  EXPECT_NEAR(m.light.peak, kLightFlux / (2 * M_PI * kLightSigma * kLightSigma), 0.1 * m.light.peak);
  EXPECT_GE(m.core_radius_px, 2.0);
  // Flux outside the core: the ghost and the Gaussian's tail beyond the core.
  for (size_t i = 0; i < m.capture.frames.size(); ++i) {
    const FrameFigures &c = m.capture.frames[i], &t = m.truth.frames[i];
    SCOPED_TRACE(c.angle_deg);
    EXPECT_NEAR(c.flare_flux_ratio, t.flare_flux_ratio, 0.01 * t.flare_flux_ratio);
    EXPECT_NEAR(c.ghost_peak_stops, t.ghost_peak_stops, 0.1);
    // With the light's pattern taken out at its sub-pixel centre, the peak is the ghost's own.
    EXPECT_NEAR(t.ghost_peak_stops, t.ghost_layers_peak_stops, 0.05);
    EXPECT_GT(t.ghost_flux_ratio, 0);
    EXPECT_EQ(t.visible_ghosts, 1);
    EXPECT_NEAR(c.light_flux_ratio, 1, 0.01);
  }
  const TruthAgreement a = compareWithTruth(m);
  EXPECT_EQ(a.frames, 9);
  EXPECT_LT(a.flare_flux_rel_max, 0.01);
  EXPECT_LT(a.ghost_peak_stops_max, 0.1);
}

TEST(Metrics, WithoutTruthOrLightExposureSaysSo) {
  testing::TempDir dir;
  writeCapture(dir / "cap", 6, 1e-4, /*light_exposures=*/false, /*truth=*/false);
  const Metrics m = measureCapture(dir / "cap");
  EXPECT_TRUE(m.truth.empty());
  EXPECT_EQ(m.light.method, "merged frame (clipped: lower bound)");
  EXPECT_TRUE(m.light.lower_bound);
  bool said_truth = false, said_light = false;
  for (const auto& n : m.notes) {
    said_truth = said_truth || n.find("no truth/") != std::string::npos;
    said_light = said_light || n.find("no light exposures") != std::string::npos;
  }
  EXPECT_TRUE(said_truth);
  EXPECT_TRUE(said_light);
  // The figures are there, as upper bounds.
  EXPECT_TRUE(std::isfinite(m.capture.frames[0].flare_flux_ratio));
}

TEST(Metrics, BadInputIsOneLine) {
  testing::TempDir dir;
  EXPECT_THROW(measureCapture(dir / "nothing"), InputError);
  std::ofstream(dir / "x.txt") << "hello";
  EXPECT_THROW(measureModel(dir / "x.txt"), InputError);
  fs::create_directories(dir / "empty");
  try {
    isCaptureFolder(dir / "empty");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
  }
}

TEST(Metrics, ReportFiles) {
  testing::TempDir dir;
  writeCapture(dir / "cap", 6, 1e-4);
  const std::vector<Metrics> ms = {measureCapture(dir / "cap")};
  const auto files = writeMetricsReport(dir / "out", ms);
  for (const char* f : {"metrics.csv", "metrics.json", "metrics.html", "flare_flux.png", "ghost_peak.png",
                        "share_above.png", "visible_ghosts.png", "light.png"})
    EXPECT_TRUE(fs::exists(dir / "out" / f)) << f;
  const nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "out" / "metrics.json"));
  EXPECT_EQ(j["format"], "flarekit.metrics");
  EXPECT_EQ(j["inputs"][0]["series"]["capture"]["frames"].size(), 6u);
  EXPECT_TRUE(j["inputs"][0].contains("truth_agreement"));
}

}  // namespace
}  // namespace flarekit::metrics
