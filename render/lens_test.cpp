#include "render/lens.h"

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/testing.h"
#include "render/ghosts.h"

namespace flarekit::render {
namespace {

namespace fs = std::filesystem;

std::vector<fs::path> shippedLenses() {
  std::vector<fs::path> out;
  for (const auto& e : fs::directory_iterator(fs::path(FLAREKIT_SOURCE_DIR) / "lenses"))
    if (e.path().extension() == ".json") out.push_back(e.path());
  std::sort(out.begin(), out.end());
  return out;
}

fs::path lensPath(const std::string& name) { return fs::path(FLAREKIT_SOURCE_DIR) / "lenses" / name; }

TEST(Lens, ShipsEveryPrescriptionOfTheSharedLibrary) {
  EXPECT_GE(shippedLenses().size(), 43u);
  for (const auto& p : shippedLenses()) {
    const Lens lens = loadLens(p);
    EXPECT_FALSE(lens.name.empty()) << p;
    EXPECT_FALSE(lens.source.empty()) << p;
    EXPECT_FALSE(lens.notes.empty()) << p;
    EXPECT_GE(lens.stopIndex(), 0) << p;
  }
}

// The lens files carry focal lengths computed independently from the same tables
// (lenses/README.md); ours must agree to 0.1 %.
TEST(Lens, ParaxialFocalLengthsOfEveryShippedLensMatchTheFiles) {
  int checked = 0;
  for (const auto& p : shippedLenses()) {
    const Lens lens = loadLens(p);
    ASSERT_TRUE(lens.facts.paraxial_efl_mm && lens.facts.paraxial_bfl_mm) << p;
    const ParaxialProperties q = paraxialProperties(lens);
    const double efl = *lens.facts.paraxial_efl_mm, bfl = *lens.facts.paraxial_bfl_mm;
    EXPECT_NEAR(q.efl_mm, efl, 1e-3 * std::abs(efl)) << p.filename();
    EXPECT_NEAR(q.bfd_mm, bfl, 1e-3 * std::abs(bfl)) << p.filename();
    if (lens.facts.paraxial_f_number) {  // given to 3 decimals
      EXPECT_NEAR(q.f_number, *lens.facts.paraxial_f_number, 5e-4 + 1e-3 * *lens.facts.paraxial_f_number)
          << p.filename();
    }
    ++checked;
  }
  EXPECT_GE(checked, 43);
}

TEST(Lens, GhostCountsOfEveryShippedLensMatchTheFiles) {
  for (const auto& p : shippedLenses()) {
    const Lens lens = loadLens(p);
    ASSERT_TRUE(lens.facts.ghosts_all && lens.facts.ghosts_same_side) << p;
    const std::vector<Ghost> ghosts = enumerateGhosts(lens);
    EXPECT_EQ(static_cast<int>(ghosts.size()), *lens.facts.ghosts_all) << p.filename();
    const auto same = std::count_if(ghosts.begin(), ghosts.end(), [](const Ghost& g) { return g.same_side_of_stop; });
    EXPECT_EQ(static_cast<int>(same), *lens.facts.ghosts_same_side) << p.filename();
    const LensInfo info = describeLens(lens);
    EXPECT_EQ(info.ghosts_all, *lens.facts.ghosts_all);
    EXPECT_EQ(info.ghosts_same_side, *lens.facts.ghosts_same_side);
  }
}

TEST(Lens, HeliarEntrancePupilAndFNumber) {
  const Lens lens = loadLens(lensPath("heliar_tronnier.json"));
  const ParaxialProperties p = paraxialProperties(lens);
  // f/# = EFL / entrance pupil diameter, and the README's 3.43 for the 11.6 mm stop.
  EXPECT_NEAR(p.f_number, p.efl_mm / (2 * p.entrance_pupil_radius_mm), 1e-12);
  EXPECT_NEAR(p.f_number, 3.43, 0.005);
  // The pupil is the image of the stop (19.1 mm behind the first vertex) seen through the front
  // group, whose negative third element pushes it slightly behind the stop.
  EXPECT_NEAR(p.entrance_pupil_z_mm, 20.03, 0.01);
}

TEST(Lens, StopDownReachesTheRequestedFNumberAndRefusesWider) {
  const Lens lens = loadLens(lensPath("brendel_tessar_100mm_usp2854889.json"));
  const double wide = paraxialProperties(lens).f_number;
  for (double n : {4.0, 8.0, 16.0}) {
    const Lens stopped = stopDown(lens, n);
    EXPECT_NEAR(paraxialProperties(stopped).f_number, n, 1e-9 * n);
    EXPECT_LT(stopped.stopSemiAperture_mm(), lens.stopSemiAperture_mm());
    EXPECT_NEAR(paraxialProperties(stopped).efl_mm, paraxialProperties(lens).efl_mm, 1e-12);
  }
  EXPECT_THROW(stopDown(lens, wide * 0.9), InputError);
  EXPECT_THROW(stopDown(lens, -2), InputError);
}

TEST(Lens, FocusAtInfinityPutsTheSensorAtTheBackFocus) {
  const Lens lens = loadLens(lensPath("heliar_tronnier.json"));
  EXPECT_NEAR(lens.sensor_distance_mm, 82.857, 1e-9);  // the file's own distance
  EXPECT_NEAR(focusAtInfinity(lens).sensor_distance_mm, 81.315, 0.0815);
}

TEST(Lens, CauchyDispersionReproducesNdAndAbbeNumber) {
  const Lens lens = loadLens(lensPath("heliar_tronnier.json"));
  for (int i = 0; i < static_cast<int>(lens.surfaces.size()); ++i) {
    const Surface& s = lens.surfaces[static_cast<size_t>(i)];
    EXPECT_NEAR(lens.refractiveIndex(i, 587.6), s.ior_d, 1e-9);
    if (!s.abbe_d) continue;
    const double nf = lens.refractiveIndex(i, 486.1), nc = lens.refractiveIndex(i, 656.3);
    EXPECT_NEAR((s.ior_d - 1.0) / (nf - nc), *s.abbe_d, 0.005 * *s.abbe_d);
    EXPECT_GT(lens.refractiveIndex(i, 400), lens.refractiveIndex(i, 700));  // normal dispersion
  }
}

TEST(Lens, SellmeierCoefficientsWhenGiven) {
  // Schott N-BK7: n_d = 1.5168, n_F = 1.52238, n_C = 1.51432 (Schott data sheet).
  const std::string text = R"({"name": "bk7 singlet", "surfaces": [
    {"radius": 50, "thickness": 5, "ior": 1.5168, "abbe": 64.17, "semi_aperture": 10,
     "sellmeier": {"b": [1.03961212, 0.231792344, 1.01046945],
                   "c_um2": [0.00600069867, 0.0200179144, 103.560653]}},
    {"radius": -50, "thickness": 2, "ior": 1.0, "semi_aperture": 10},
    {"radius": 0, "thickness": 45, "ior": 1.0, "semi_aperture": 8, "is_stop": true}]})";
  const Lens lens = parseLensJson(text, "bk7.json");
  EXPECT_NEAR(lens.refractiveIndex(0, 587.56), 1.5168, 1e-4);
  EXPECT_NEAR(lens.refractiveIndex(0, 486.13), 1.52238, 1e-4);
  EXPECT_NEAR(lens.refractiveIndex(0, 656.27), 1.51432, 1e-4);
}

// Each broken file is refused with one line naming the file and what is wrong.
struct BadLens {
  const char* what;
  const char* json;
  const char* expected;  // in the message
};

class LensRejects : public ::testing::TestWithParam<BadLens> {};

TEST_P(LensRejects, WithOneClearLine) {
  const BadLens& bad = GetParam();
  try {
    parseLensJson(bad.json, "bad_lens.json");
    FAIL() << bad.what << " was accepted";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("bad_lens.json"), std::string::npos) << m;
    EXPECT_NE(m.find(bad.expected), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
}

#define SURF(r, t, n, h) "{\"radius\": " #r ", \"thickness\": " #t ", \"ior\": " #n ", \"semi_aperture\": " #h "}"
#define STOP "{\"radius\": 0, \"thickness\": 40, \"ior\": 1.0, \"semi_aperture\": 5, \"is_stop\": true}"
#define BACK SURF(-50, 2, 1.0, 10)

INSTANTIATE_TEST_SUITE_P(
    BadFiles, LensRejects,
    ::testing::Values(
        BadLens{"no stop", "{\"surfaces\": [" SURF(50, 5, 1.5, 10) "," SURF(-50, 40, 1.0, 10) "]}", "stop"},
        BadLens{"two stops", "{\"surfaces\": [" SURF(50, 5, 1.5, 10) "," BACK "," STOP "," STOP "]}", "2 stops"},
        BadLens{"negative thickness", "{\"surfaces\": [" SURF(50, -5, 1.5, 10) "," BACK "," STOP "]}", "surfaces[0]: thickness"},
        BadLens{"NaN", "{\"surfaces\": [{\"radius\": NaN, \"thickness\": 5, \"ior\": 1.5, \"semi_aperture\": 10}]}", "syntax error"},
        BadLens{"infinite", "{\"surfaces\": [" SURF(1e999, 5, 1.5, 10) "," BACK "," STOP "]}", "overflow"},
        BadLens{"semi-aperture above radius", "{\"surfaces\": [" SURF(8, 5, 1.5, 10) "," BACK "," STOP "]}", "surfaces[0]: semi_aperture"},
        BadLens{"zero semi-aperture", "{\"surfaces\": [" SURF(50, 5, 1.5, 0) "," BACK "," STOP "]}", "semi_aperture must be > 0"},
        BadLens{"radius as text", "{\"surfaces\": [{\"radius\": \"fifty\", \"thickness\": 5, \"ior\": 1.5, \"semi_aperture\": 10}," BACK "," STOP "]}", "surfaces[0].radius: must be a number"},
        BadLens{"stop flag as number", "{\"surfaces\": [" SURF(50, 5, 1.5, 10) "," BACK ",{\"radius\": 0, \"thickness\": 2, \"semi_aperture\": 5, \"is_stop\": 1}]}", "is_stop"},
        BadLens{"unknown surface key", "{\"surfaces\": [{\"radius\": 50, \"thickness\": 5, \"ior\": 1.5, \"semi_aperture\": 10, \"thicknes\": 3}," BACK "," STOP "]}", "thicknes"},
        BadLens{"empty surface list", "{\"surfaces\": []}", "empty"},
        BadLens{"surfaces not a list", "{\"surfaces\": 3}", "surfaces"},
        BadLens{"missing surfaces", "{\"name\": \"x\"}", "surfaces"},
        BadLens{"index below 1", "{\"surfaces\": [" SURF(50, 5, 0.5, 10) "," BACK "," STOP "]}", "surfaces[0]: ior must be in [1, 3], got 0.5"},
        BadLens{"index far above glass", "{\"surfaces\": [" SURF(50, 5, 1e308, 10) "," BACK "," STOP "]}", "surfaces[0]: ior must be in [1, 3], got 1e+308"},
        BadLens{"Abbe number of no glass", "{\"surfaces\": [{\"radius\": 50, \"thickness\": 5, \"ior\": 1.5, \"abbe\": 1e-300, \"semi_aperture\": 10}," BACK "," STOP "]}", "surfaces[0]: abbe must be in [5, 150], got 1e-300"},
        BadLens{"radius beyond flat", "{\"surfaces\": [" SURF(1e300, 5, 1.5, 10) "," BACK "," STOP "]}", "surfaces[0]: |radius| must be at most 1e+06 mm (write 0 for a flat surface), got 1e+300"},
        BadLens{"thickness of a kilometre", "{\"surfaces\": [" SURF(50, 1e6, 1.5, 10) "," BACK "," STOP "]}", "surfaces[0]: thickness must be at most 10000 mm, got 1e+06"},
        BadLens{"glass after the last surface", "{\"surfaces\": [" SURF(50, 5, 1.5, 10) "," BACK "," STOP "," SURF(-50, 40, 1.5, 10) "]}", "last medium"}),
    [](const ::testing::TestParamInfo<BadLens>& info) {
      std::string n = info.param.what;
      for (char& c : n)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
      return n;
    });

TEST(Lens, TheBaseOfTheBadFilesIsAValidLens) {
  // Each bad file above breaks this one lens in one place.
  const Lens lens = parseLensJson("{\"surfaces\": [" SURF(50, 5, 1.5, 10) "," BACK "," STOP "]}", "good.json");
  EXPECT_EQ(lens.stopIndex(), 2);
}

TEST(Lens, PbrtDatImportMatchesTheJsonTranscription) {
  const Lens json = loadLens(lensPath("pbrt_dgauss_50mm.json"));
  std::string dat = "# pbrt realistic camera lens: radius thickness ior aperture-diameter\n";
  for (const Surface& s : json.surfaces) {
    char line[160];
    std::snprintf(line, sizeof line, "%.4f\t%.4f\t%.4f\t%.4f\n", s.radius_mm, s.thickness_mm,
                  s.is_stop ? 0.0 : s.ior_d, 2 * s.semi_aperture_mm);
    dat += line;
  }
  testing::TempDir dir;
  writeTextFileAtomically(dir / "dgauss.50mm.dat", dat);
  const Lens lens = loadLens(dir / "dgauss.50mm.dat");
  ASSERT_EQ(lens.surfaces.size(), json.surfaces.size());
  EXPECT_EQ(lens.stopIndex(), json.stopIndex());
  EXPECT_NEAR(paraxialProperties(lens).efl_mm, *json.facts.paraxial_efl_mm, 1e-3 * 50);
  // The last thickness is 0: the sensor goes to the paraxial focus, like the JSON file's.
  EXPECT_NEAR(lens.sensor_distance_mm, json.sensor_distance_mm, 0.01);
  writeTextFileAtomically(dir / "bad.dat", "29.475 3.76 1.67\n");
  try {
    loadLens(dir / "bad.dat");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("line 1"), std::string::npos) << e.what();
  }
}

TEST(Lens, ShipsAPbrtDatFile) {
  const Lens lens = loadLens(fs::path(FLAREKIT_SOURCE_DIR) / "lenses" / "pbrt" / "dgauss.50mm.dat");
  EXPECT_NEAR(paraxialProperties(lens).efl_mm, 50.358, 0.05);
}

}  // namespace
}  // namespace flarekit::render
