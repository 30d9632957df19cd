// flarekit metrics as a user runs it, on small simulated captures (160×107, the Heliar at f/4):
// the targets — the figures of a capture agree with the same figures of its noise-free
// truth within 5 % (flux ratios) and 0.2 stops (peak ratios); a light drifting 2 % over the
// capture is reported at 2 ± 0.3 % — the files it writes, several inputs on one set of plots, and
// bad input (one line, exit 2).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "common/config.h"
#include "common/testing.h"
#include "model/flare_model.h"
#include "tests/cli_util.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;
using testing::lineCount;
using testing::runFlarekit;
using testing::TempDir;

const fs::path kSource = FLAREKIT_SOURCE_DIR;


// sim-heliar at 160×107 with the capture-trust keys: two light exposures (the shortest keeps the
// light's core unclipped, the second measures its spread that 0.25 s clips), a light that drifts
// `drift_pct` over the capture, a tiny settle pause.
fs::path writeRig(const fs::path& dir, const std::string& name, double drift_pct,
                  const std::string& lens = "lenses/heliar_tronnier.json", const std::string& cfa = "mono",
                  double f_number = 4.0) {
  const fs::path path = dir / (name + ".toml");
  std::ofstream(path) << "name = \"" << name << "\"\n"
                      << "[head]\ndriver = \"simulated\"\nsettle_s = 0.001\n"
                      << "[camera]\ndriver = \"simulated\"\n"
                      << "[sensor]\ncfa = \"" << cfa << "\"\ngain_e_per_dn = 4.0\nread_noise_e = 3.0\n"
                      << "full_well_e = 60000\nelectrons_per_unit_s = 2.5e6\n"
                      << "[simulation]\nlens = \"" << (kSource / lens).string()
                      << "\"\nwidth_px = 160\nheight_px = 107\nlight_drift_pct = " << drift_pct << "\n"
                      << "[capture]\nf_number = " << f_number
                      << "\nretry_delay_s = 0.0\nexposures_s = [0.25, 1.0, 4.0]\n"
                      << "light_exposure_s = [3e-6, 1e-4]\n";
  return path;
}

nlohmann::json jsonOf(const fs::path& file) { return loadJsonFile(file).json(); }

// One capture for the whole suite: 0–10° in 0.5° steps, the light in the frame throughout and
// beyond its edge at the end.
class CliMetrics : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    const fs::path rig = writeRig(dir_->path(), "sim-heliar-160", 2.0);
    const auto r = runFlarekit({"capture", "--rig", rig.string(), "--out", (*dir_ / "cap").string(), "--from",
                                "0", "--to", "10", "--step", "0.5", "-q"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static fs::path capture() { return *dir_ / "cap"; }
  static TempDir* dir_;
};
TempDir* CliMetrics::dir_ = nullptr;

TEST_F(CliMetrics, CaptureAgreesWithItsTruthAndReportsTheLightsDrift) {
  TempDir out;
  const auto r = runFlarekit({"metrics", capture().string(), "--out", (out / "m").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* f : {"metrics.csv", "ghost_flux.csv", "metrics.json", "metrics.html", "flare_flux.png",
                        "ghost_peak.png", "share_above.png", "visible_ghosts.png", "ghost_flux.png", "light.png"})
    EXPECT_TRUE(fs::exists(out / "m" / f)) << f;
  const auto j = jsonOf(out / "m" / "metrics.json");
  ASSERT_EQ(j["inputs"].size(), 1u);
  const auto& in = j["inputs"][0];
  // The light measured by its light exposures, unclipped, at the frame nearest the optical zero.
  EXPECT_EQ(in["light"]["method"], "light exposure");
  EXPECT_FALSE(in["light"]["lower_bound"].get<bool>());
  EXPECT_EQ(in["light"]["exposures_s"], nlohmann::json({3e-6, 1e-4}));
  const auto& a = in["truth_agreement"];
  ASSERT_EQ(a["frames"], 21);
  const double flux = a["flare_flux_rel_max"].get<double>(), peak = a["ghost_peak_stops_max"].get<double>();
  const double light_flux = a["light_flux_rel"].get<double>(), light_peak = a["light_peak_stops"].get<double>();
  const double light_ratio = a["light_flux_ratio_rel_max"].get<double>();
  EXPECT_LT(flux, 0.05);
  EXPECT_LT(light_flux, 0.05);
  EXPECT_LT(light_ratio, 0.05);
  EXPECT_LT(peak, 0.2);
  EXPECT_LT(light_peak, 0.2);
  for (const auto& s : a["share_abs_max"]) EXPECT_LT(s.get<double>(), 0.005);  // of the frame
  // The light's drift: in the manifest and in the metrics, 2 ± 0.3 %.
  const double drift = in["trust"]["light_stability"]["drift_pct"].get<double>();
  EXPECT_NEAR(drift, 2.0, 0.3);
  EXPECT_NEAR(jsonOf(capture() / "manifest.json")["light_stability"]["drift_pct"].get<double>(), drift, 1e-9);
  EXPECT_NE(in["trust"]["light_stability"]["warning"].get<std::string>().find("drifted"), std::string::npos);
  EXPECT_NE(r.err.find("drifted"), std::string::npos) << r.err;
  // The rest of the capture's trust: the settle pause, the horizon (the optical axis's row, 53.5
  // on this ideal rig) and the optical zero's figures.
  EXPECT_DOUBLE_EQ(in["trust"]["settle_s"].get<double>(), 0.001);
  EXPECT_NEAR(in["trust"]["horizon_y_px"].get<double>(), 53.5, 0.5);
  EXPECT_NEAR(in["trust"]["optical_zero"]["axis_x_px"].get<double>(), 80, 1.0);
  EXPECT_GT(in["trust"]["light_frames"].get<int>(), 15);
  // Every frame has its figures; the worst angle is named.
  const auto& frames = in["series"]["capture"]["frames"];
  ASSERT_EQ(frames.size(), 21u);
  for (const auto& f : frames) {
    EXPECT_TRUE(f["flare_flux_ratio"].is_number());
    EXPECT_TRUE(f["ghost_peak_stops"].is_number());
    EXPECT_TRUE(f["visible_ghosts"].is_number());
  }
  EXPECT_TRUE(in["series"]["capture"]["worst"]["angle_deg"].is_number());
  // CSV: a header and a row per frame for the capture and for the truth.
  std::ifstream csv(out / "m" / "metrics.csv");
  const std::string text((std::istreambuf_iterator<char>(csv)), {});
  EXPECT_EQ(lineCount(text), 1 + 2 * 21);
  std::printf("[ figures  ] flare flux ratio within %.2f %% of the truth's (max over 21 frames, median %.2f %%), "
              "ghost peak within %.3f stops (median %.3f), light flux %.2f %%, light peak %.4f stops, the frames' "
              "light flux ratios %.2f %%; light drift %.2f %% (set 2 %%), scatter %.2f %%\n",
              100 * flux, 100 * a["flare_flux_rel_median"].get<double>(), peak,
              a["ghost_peak_stops_median"].get<double>(), 100 * light_flux, light_peak, 100 * light_ratio, drift,
              in["trust"]["light_stability"]["scatter_pct"].get<double>());
}

// The other simulated rig's kind: a colour (RGGB) sensor, the Nikon 80–200 mm at 80 mm and f/5.6.
// Its frames are the mosaic demosaiced, and its truth is seen alike (docs/metrics.md).
TEST(CliMetricsColour, BayerCaptureAgreesWithItsTruth) {
  TempDir dir;
  const fs::path rig = writeRig(dir.path(), "sim-nikon-160", 0.0, "lenses/nikon_tele_zoom_80_200mm_80mm.json",
                                "RGGB", 5.6);
  auto r = runFlarekit({"capture", "--rig", rig.string(), "--out", (dir / "cap").string(), "--from", "0", "--to",
                        "10", "--step", "1", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = runFlarekit({"metrics", (dir / "cap").string(), "--out", (dir / "m").string(), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto in = jsonOf(dir / "m" / "metrics.json")["inputs"][0];
  EXPECT_EQ(in["light"]["method"], "light exposure");
  const auto& a = in["truth_agreement"];
  ASSERT_EQ(a["frames"], 11);
  EXPECT_LT(a["flare_flux_rel_max"].get<double>(), 0.05);
  EXPECT_LT(a["light_flux_rel"].get<double>(), 0.05);
  EXPECT_LT(a["ghost_peak_stops_max"].get<double>(), 0.2);
  EXPECT_LT(a["light_peak_stops"].get<double>(), 0.2);
  const double drift = in["trust"]["light_stability"]["drift_pct"].get<double>();
  // A steady light: its drift is only the noise of the light check's repeated exposures, bounded
  // at about three of its standard deviations.
  EXPECT_LT(std::abs(drift), 1.5);
  std::printf("[ figures  ] RGGB: flare flux ratio within %.2f %% of the truth's (11 frames, median %.2f %%), ghost "
              "peak within %.3f stops, light flux %.2f %%, light peak %.4f stops; a steady light's drift %.2f %%\n",
              100 * a["flare_flux_rel_max"].get<double>(), 100 * a["flare_flux_rel_median"].get<double>(),
              a["ghost_peak_stops_max"].get<double>(), 100 * a["light_flux_rel"].get<double>(),
              a["light_peak_stops"].get<double>(), drift);
}

// A model of 160×107 images with one ghost over [lo, hi] degrees.
fs::path writeModel(const fs::path& dir, const std::string& name, double lo, double hi, cv::Size size = {160, 107}) {
  model::FlareModel m;
  m.capture.camera = "simulated";
  m.capture.lens = "test";
  m.capture.f_number = 4;
  m.capture.iso = 100;
  m.capture.exposure_s = 4;
  m.capture.light = "test";
  m.capture.image_size = size;
  m.capture.pixel_pitch_um = 224;
  m.capture.angle_step_deg = 0.5;
  m.channels = 1;
  model::GhostParameters g;
  g.center_x = 80;
  g.center_y = 53.5;
  g.left = g.right = g.height = 12;
  g.border = {0.01, 0, 0};
  g.inside = {0.005, 0, 0};
  g.inside_falloff = 3;
  g.outside_falloff = 2;
  const std::vector<double> base = model::toParameterVector(g);
  model::GhostTrack t;
  t.id = 4;
  t.angle_min_deg = lo;
  t.angle_max_deg = hi;
  for (double v : base) t.parameters.push_back(model::Polynomial{{v}});
  t.parameters[model::param::kMx].coefficients = {80, 4};  // moves with θ
  m.ghosts.push_back(t);
  const fs::path file = dir / (name + ".json");
  m.save(file);
  return file;
}

// Captures without truth work, the truth figures skipped and said so; several captures and a
// model share the plots, each input's worst angle named; --model gives each ghost's flux.
TEST_F(CliMetrics, SeveralInputsAndACaptureWithoutTruth) {
  TempDir out;
  const fs::path rig = writeRig(out.path(), "steady", 0.0);
  auto r = runFlarekit({"capture", "--rig", rig.string(), "--out", (out / "notruth").string(), "--from", "0",
                        "--to", "6", "--step", "1", "--no-truth", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path model = writeModel(out.path(), "model", 0, 8);
  r = runFlarekit({"metrics", capture().string(), (out / "notruth").string(), model.string(), "--model",
                   model.string(), "--out", (out / "m").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = jsonOf(out / "m" / "metrics.json");
  ASSERT_EQ(j["inputs"].size(), 3u);
  const auto &a = j["inputs"][0], &b = j["inputs"][1], &c = j["inputs"][2];
  EXPECT_EQ(a["kind"], "capture");
  EXPECT_TRUE(a["series"].contains("model"));  // --model went with the first capture
  EXPECT_FALSE(b["series"].contains("truth"));
  bool said = false;
  for (const auto& n : b["notes"]) said = said || n.get<std::string>().find("no truth/") != std::string::npos;
  EXPECT_TRUE(said) << b["notes"];
  EXPECT_TRUE(b["series"]["capture"]["worst"]["angle_deg"].is_number());
  // A steady light stays within 1 %.
  EXPECT_LT(std::abs(b["trust"]["light_stability"]["drift_pct"].get<double>()), 1.0);
  EXPECT_EQ(c["kind"], "model");
  // Each model ghost's flux over θ, relative to the capture's light.
  const auto& mf = a["series"]["model"]["frames"];
  int with_flux = 0;
  for (const auto& f : mf) with_flux += f.contains("ghost_flux") && f["ghost_flux"].contains("4");
  EXPECT_EQ(with_flux, 17);  // 0–8° of the capture's 0–10° in 0.5° steps
  std::ifstream csv(out / "m" / "ghost_flux.csv");
  const std::string text((std::istreambuf_iterator<char>(csv)), {});
  EXPECT_NE(text.find("model,0,4,"), std::string::npos) << text.substr(0, 400);
  // The page names every input.
  std::ifstream html(out / "m" / "metrics.html");
  const std::string page((std::istreambuf_iterator<char>(html)), {});
  for (const char* name : {"cap", "notruth", "model"}) EXPECT_NE(page.find(name), std::string::npos) << name;
}

TEST_F(CliMetrics, BadInputIsOneLineAndExit2) {
  TempDir out;
  // An unknown file.
  auto r = runFlarekit({"metrics", (out / "no-such").string(), "--out", (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("no-such"), std::string::npos) << r.err;
  // A folder that is not a capture.
  fs::create_directories(out / "empty");
  r = runFlarekit({"metrics", (out / "empty").string(), "--out", (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  // A model outside the capture's angle range.
  const fs::path far = writeModel(out.path(), "far", 30, 40);
  r = runFlarekit({"metrics", capture().string(), "--model", far.string(), "--out", (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_NE(r.err.find("outside the capture"), std::string::npos) << r.err;
  // A model of other images; an unknown --model file; a file that is not a model.
  const fs::path big = writeModel(out.path(), "big", 0, 8, {320, 214});
  r = runFlarekit({"metrics", capture().string(), "--model", big.string(), "--out", (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  r = runFlarekit({"metrics", capture().string(), "--model", (out / "none.json").string(), "--out",
                   (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  std::ofstream(out / "text.json") << "{\"hello\": 1}";
  r = runFlarekit({"metrics", (out / "text.json").string(), "--out", (out / "m").string()});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(lineCount(r.err), 1) << r.err;
  EXPECT_FALSE(fs::exists(out / "m" / "metrics.json"));
}

}  // namespace
}  // namespace flarekit
