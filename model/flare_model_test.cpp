#include "model/flare_model.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <random>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/testing.h"

namespace flarekit::model {
namespace {

using flarekit::testing::TempDir;

// A model with two grey ghosts whose parameters are valid over their ranges.
FlareModel sampleModel(int channels = 1) {
  FlareModel m;
  m.capture.camera = "Canon EOS 5D Mark II";
  m.capture.lens = "EF 24mm f/1.4L II";
  m.capture.f_number = 1.4;
  m.capture.iso = 100;
  m.capture.exposure_s = 1.0;
  m.capture.light = "Olympus CLV-S";
  m.capture.image_size = cv::Size(320, 200);
  m.capture.pixel_pitch_um = 6.4;
  m.capture.angle_step_deg = 0.2;
  m.channels = channels;
  const std::vector<double> base = toParameterVector([&] {
    GhostParameters g;
    g.channels = channels;
    g.center_x = 160;
    g.center_y = 100;
    g.left = 20;
    g.right = 15;
    g.height = 18;
    g.border = {1.0, 0.8, 0.6};
    g.inside = {0.2, 0.3, 0.1};
    g.inside_falloff = 6;
    g.outside_falloff = 3;
    return g;
  }());
  for (int id : {3, 7}) {
    GhostTrack t;
    t.id = id;
    t.angle_min_deg = id == 3 ? -10 : 0;
    t.angle_max_deg = id == 3 ? 12.5 : 30;
    for (size_t k = 0; k < base.size(); ++k) t.parameters.push_back(Polynomial{{base[k]}});
    // Mx moves with θ (positive θ moves the light image to −x), the size grows a little.
    t.parameters[param::kMx].coefficients = {160, -3.25 * (id == 3 ? 1 : -0.5), 0.011};
    t.parameters[param::kL].coefficients = {20, 0.1, 0.0013};
    m.ghosts.push_back(t);
  }
  return m;
}

// sampleModel with a pedestal over 0–20°: a glow brightest left of the centre, fading with θ.
FlareModel sampleModelWithPedestal(int channels = 1) {
  FlareModel m = sampleModel(channels);
  PedestalTrack p;
  p.angle_min_deg = 0;
  p.angle_max_deg = 20;
  for (int c = 0; c < channels; ++c) {
    const double gain = 1 - 0.2 * c;
    for (const std::vector<double>& t :
         std::vector<std::vector<double>>{{0.02 * gain, -1e-3 * gain},
                                          {-0.01 * gain},
                                          {0},
                                          {-0.03 * gain, 1e-4},
                                          {0},
                                          {-0.02 * gain}})
      p.terms.push_back(Polynomial{t});
  }
  m.pedestal = p;
  return m;
}

std::string writeModelText(const TempDir& dir, const std::string& name, const nlohmann::json& j) {
  const std::string path = (dir / name).string();
  std::ofstream(path) << j.dump(2);
  return path;
}

TEST(FlareModel, PolynomialEvaluationIsExact) {
  // Integer coefficients and angles: Horner's rule is exact, so the value must equal the integer.
  const Polynomial p{{-7, 3, 0, 2}};  // 2θ³ + 3θ − 7
  for (int theta = -20; theta <= 20; ++theta)
    EXPECT_EQ(p.evaluate(theta), 2.0 * theta * theta * theta + 3.0 * theta - 7.0);
  EXPECT_EQ(Polynomial{}.evaluate(3), 0.0);
  // A fractional case checked by hand: 0.5 + 0.25·2 + 0.125·4 = 1.5.
  EXPECT_EQ((Polynomial{{0.5, 0.25, 0.125}}.evaluate(2)), 1.5);
}

TEST(FlareModel, GhostsExistOnlyWithinTheirRange) {
  const FlareModel m = sampleModel();
  EXPECT_TRUE(m.IsValid(nullptr));
  auto ids = [&](double a) {
    std::vector<int> out;
    for (const auto& g : m.ghostsAt(a)) out.push_back(g.id);
    return out;
  };
  EXPECT_EQ(ids(-10), std::vector<int>({3}));      // the range includes its ends
  EXPECT_EQ(ids(-10.0001), std::vector<int>());
  EXPECT_EQ(ids(5), std::vector<int>({3, 7}));
  EXPECT_EQ(ids(12.5), std::vector<int>({3, 7}));
  EXPECT_EQ(ids(12.5001), std::vector<int>({7}));
  EXPECT_EQ(ids(31), std::vector<int>());
  // The evaluated parameters are the polynomials at θ.
  const auto at = m.ghostsAt(4);
  EXPECT_EQ(at[0].parameters.center_x, m.ghosts[0].parameters[param::kMx].evaluate(4));
  EXPECT_EQ(at[0].parameters.left, m.ghosts[0].parameters[param::kL].evaluate(4));
  // A ghost outside its range contributes nothing to the render.
  FlareModel only7 = m;
  only7.ghosts.erase(only7.ghosts.begin());
  const cv::Mat both = m.render(20), one = only7.render(20);
  EXPECT_EQ(cv::norm(both, one, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::sum(m.render(5))[0], cv::sum(m.render(20))[0]);
}

TEST(FlareModel, FileRoundTripIsExact) {
  TempDir dir;
  for (int channels : {1, 3}) {
    FlareModel m = sampleModel(channels);
    // Awkward doubles must survive the text file bit for bit.
    std::mt19937 rng(4);
    std::uniform_real_distribution<double> tiny(-1e-3, 1e-3);
    for (auto& g : m.ghosts)
      for (auto& p : g.parameters) p.coefficients.push_back(tiny(rng) * 1e-4);
    m.ghosts[0].parameters[param::kMy].coefficients[0] = 100.1 + 1.0 / 3.0;
    if (channels == 3) {  // the optional calibration (one model with it, one without)
      m.capture.light_illuminance_lux = 40.0 / 3.0;
      m.capture.clip_level = 0.006;
      m.capture.focal_length_mm = 99.2358;
    }
    const auto path = dir / ("model" + std::to_string(channels) + ".json");
    m.save(path);
    const FlareModel back = FlareModel::load(path);
    EXPECT_EQ(back.toJson(), m.toJson());
    ASSERT_EQ(back.ghosts.size(), m.ghosts.size());
    for (size_t i = 0; i < m.ghosts.size(); ++i)
      for (size_t k = 0; k < m.ghosts[i].parameters.size(); ++k)
        EXPECT_EQ(back.ghosts[i].parameters[k].coefficients, m.ghosts[i].parameters[k].coefficients);
    EXPECT_EQ(back.capture.lens, m.capture.lens);
    EXPECT_EQ(back.capture.image_size, m.capture.image_size);
    EXPECT_EQ(back.capture.exposure_s, m.capture.exposure_s);
    EXPECT_EQ(back.capture.light_illuminance_lux, m.capture.light_illuminance_lux);
    EXPECT_EQ(back.capture.clip_level, m.capture.clip_level);
    EXPECT_EQ(back.capture.focal_length_mm, m.capture.focal_length_mm);
    EXPECT_EQ(cv::norm(back.render(3, 10), m.render(3, 10), cv::NORM_INF), 0.0);
  }
}

// Version 2 records the optical zero the fit measured; a version 1 file, which has none, loads
// and renders as it did (axis at the image centre, rig angles as field angles).
TEST(FlareModel, TheOpticalZeroRoundTripsAndVersion1FilesLoadAsBefore) {
  TempDir dir;
  FlareModel m = sampleModel();
  m.capture.angle_zero_deg = 0.35;
  m.capture.optical_axis_px = cv::Point2d(167.3, 95.8);
  m.save(dir / "v2.json");
  const FlareModel back = FlareModel::load(dir / "v2.json");
  EXPECT_EQ(back.toJson()["version"], 2);
  EXPECT_EQ(back.capture.angle_zero_deg, 0.35);
  ASSERT_TRUE(back.capture.optical_axis_px.has_value());
  EXPECT_EQ(*back.capture.optical_axis_px, cv::Point2d(167.3, 95.8));
  EXPECT_DOUBLE_EQ(back.capture.fieldAngle(3.35), 3.0);

  nlohmann::json v1 = sampleModel().toJson();
  v1["version"] = 1;
  const FlareModel old = FlareModel::load(writeModelText(dir, "v1.json", v1));
  EXPECT_EQ(old.capture.angle_zero_deg, 0.0);
  EXPECT_FALSE(old.capture.optical_axis_px.has_value());
  EXPECT_EQ(old.capture.opticalAxis(), cv::Point2d(160, 100));
  EXPECT_EQ(cv::norm(old.render(3, 20), sampleModel().render(3, 20), cv::NORM_INF), 0.0);
}

// A roll turns the flare about the optical axis, not the image centre: at 180° every ghost's
// light lands mirrored through the axis.
TEST(FlareModel, RollTurnsTheFlareAboutTheOpticalAxis) {
  FlareModel m = sampleModel();
  const cv::Point2d axis(190, 92);
  m.capture.optical_axis_px = axis;
  auto centroid = [](const cv::Mat& image) {  // pixel (i, j) has its centre at (i + ½, j + ½)
    const cv::Moments mo = cv::moments(image);
    return cv::Point2d(mo.m10 / mo.m00 + 0.5, mo.m01 / mo.m00 + 0.5);
  };
  const cv::Point2d c0 = centroid(m.render(3, 0));
  const cv::Point2d c180 = centroid(m.render(3, 180));
  EXPECT_GT(cv::norm(c0 - axis), 10.0);
  EXPECT_NEAR(c180.x, 2 * axis.x - c0.x, 0.05);
  EXPECT_NEAR(c180.y, 2 * axis.y - c0.y, 0.05);
}

TEST(FlareModel, APedestalRoundTripsAndIsDrawnWithinItsRange) {
  TempDir dir;
  for (int channels : {1, 3}) {
    const FlareModel m = sampleModelWithPedestal(channels);
    const auto path = dir / ("pedestal" + std::to_string(channels) + ".json");
    m.save(path);
    const FlareModel back = FlareModel::load(path);
    EXPECT_EQ(back.toJson(), m.toJson());
    ASSERT_TRUE(back.pedestal.has_value());
    EXPECT_EQ(cv::norm(back.render(3, 10), m.render(3, 10), cv::NORM_INF), 0.0);
    // The render is the ghosts plus the pedestal where the pedestal's range covers θ, the
    // ghosts alone beyond it.
    FlareModel ghosts_only = m;
    ghosts_only.pedestal.reset();
    const cv::Mat with = m.render(5), without = ghosts_only.render(5);
    cv::Mat expected = without.clone();
    m.pedestalAt(5).addTo(expected, m.capture.image_size);
    EXPECT_EQ(cv::norm(with, expected, cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(with, without, cv::NORM_INF), 0.01);
    EXPECT_EQ(cv::norm(m.render(25), ghosts_only.render(25), cv::NORM_INF), 0.0);
    EXPECT_TRUE(m.pedestalAt(25).empty());
  }
  // A model without a pedestal writes none.
  EXPECT_FALSE(sampleModel().toJson().contains("pedestal"));
}

TEST(FlareModel, RenderAtAnotherSizeScalesAboutTheCentre) {
  const FlareModel m = sampleModel();
  const cv::Mat full = m.render(0);
  const cv::Mat half = m.render(0, 0, cv::Size(160, 100));
  ASSERT_EQ(half.size(), cv::Size(160, 100));
  // Same radiance, a quarter of the area.
  EXPECT_NEAR(cv::sum(half)[0] * 4, cv::sum(full)[0], 0.05 * cv::sum(full)[0]);
}

// Every way a model file can be wrong gives an InputError that names the file and the key.
TEST(FlareModel, BadFilesAreRejectedWithTheFileAndKey) {
  TempDir dir;
  const nlohmann::json good = sampleModel().toJson();
  struct Case {
    std::string name;
    std::function<void(nlohmann::json&)> edit;
    std::string expect;  // part of the message
  };
  const std::vector<Case> cases = {
      {"wrong_format", [](auto& j) { j["format"] = "flarekit.lens"; }, "format"},
      {"wrong_version", [](auto& j) { j["version"] = 3; }, "version"},
      {"missing_capture", [](auto& j) { j.erase("capture"); }, "capture"},
      {"missing_lens", [](auto& j) { j["capture"].erase("lens"); }, "lens"},
      {"missing_parameter", [](auto& j) { j["ghosts"][1]["parameters"].erase("Cl"); },
       "ghosts[1].parameters"},
      {"unknown_parameter", [](auto& j) { j["ghosts"][0]["parameters"]["Zz"] = {1}; }, "Zz"},
      {"nan_coefficient", [](auto& j) { j["ghosts"][0]["parameters"]["Mx"][1] = nullptr; }, "Mx"},
      {"string_coefficient", [](auto& j) { j["ghosts"][0]["parameters"]["Fo"] = {"NaN"}; }, "Fo"},
      {"negative_size", [](auto& j) { j["ghosts"][0]["parameters"]["h"] = {-4}; }, "h"},
      {"negative_image_width", [](auto& j) { j["capture"]["image_width"] = -1280; }, "image_width"},
      {"zero_pitch", [](auto& j) { j["capture"]["pixel_pitch_um"] = 0; }, "pixel_pitch_um"},
      {"empty_range", [](auto& j) { j["ghosts"][0]["angle_max_deg"] = -20; }, "empty angle range"},
      {"duplicate_id", [](auto& j) { j["ghosts"][1]["id"] = 3; }, "duplicate"},
      {"bad_channels", [](auto& j) { j["channels"] = 2; }, "channels"},
      {"empty_polynomial",
       [](auto& j) { j["ghosts"][1]["parameters"]["Ei"] = nlohmann::json::array(); }, "Ei"},
      {"size_goes_negative",
       [](auto& j) {
         j["ghosts"][1]["parameters"]["R"] = {15, -1};
       },
       "R"},
      {"ghosts_not_array", [](auto& j) { j["ghosts"] = 3; }, "ghosts"},
      {"pedestal_missing_term", [](auto& j) { j["pedestal"]["terms"].erase("P11"); }, "P11"},
      {"pedestal_unknown_term", [](auto& j) { j["pedestal"]["terms"]["P30"] = {0}; }, "P30"},
      {"pedestal_nan_term", [](auto& j) { j["pedestal"]["terms"]["P20"][0] = nullptr; }, "P20"},
      {"pedestal_too_high_degree",
       [](auto& j) { j["pedestal"]["terms"]["P10"] = std::vector<double>(12, 0.0); }, "P10"},
      {"pedestal_empty_range", [](auto& j) { j["pedestal"]["angle_max_deg"] = -1; },
       "empty angle range"},
      {"pedestal_not_table", [](auto& j) { j["pedestal"] = 1; }, "pedestal"},
  };
  const nlohmann::json with_pedestal = sampleModelWithPedestal().toJson();
  for (const Case& c : cases) {
    nlohmann::json j = c.name.rfind("pedestal", 0) == 0 ? with_pedestal : good;
    c.edit(j);
    const std::string path = writeModelText(dir, c.name + ".json", j);
    try {
      FlareModel::load(path);
      ADD_FAILURE() << c.name << " was accepted";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path), std::string::npos) << c.name << ": " << what;
      EXPECT_NE(what.find(c.expect), std::string::npos) << c.name << ": " << what;
      EXPECT_EQ(what.find('\n'), std::string::npos) << c.name;
    }
  }
  // Not JSON at all, and a missing file.
  const std::string garbage = (dir / "garbage.json").string();
  std::ofstream(garbage) << "{ \"format\": ";
  EXPECT_THROW(FlareModel::load(garbage), InputError);
  EXPECT_THROW(FlareModel::load(dir / "missing.json"), InputError);
}

TEST(FlareModel, SaveRefusesAnInvalidModel) {
  TempDir dir;
  FlareModel m = sampleModel();
  m.ghosts[0].angle_max_deg = -50;
  EXPECT_FALSE(m.IsValid(nullptr));
  EXPECT_THROW(m.save(dir / "bad.json"), std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.json"));
}

}  // namespace
}  // namespace flarekit::model
