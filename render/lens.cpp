#include "render/lens.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "common/input_file.h"
#include "common/config.h"
#include "common/error.h"
#include "render/paraxial.h"

namespace flarekit::render {
namespace {

std::string surfaceName(size_t i) { return "surfaces[" + std::to_string(i) + "]"; }

bool finite(double v) { return std::isfinite(v); }

std::optional<double> optionalNumber(const ConfigNode& node, std::string_view key) {
  auto child = node.find(key);
  if (!child) return std::nullopt;
  return child->number();
}

std::optional<int> optionalInteger(const ConfigNode& node, std::string_view key) {
  auto child = node.find(key);
  if (!child) return std::nullopt;
  return static_cast<int>(child->integer());
}

}  // namespace

int Lens::stopIndex() const {
  for (size_t i = 0; i < surfaces.size(); ++i)
    if (surfaces[i].is_stop) return static_cast<int>(i);
  return -1;
}

std::vector<int> Lens::interfaceIndices() const {
  std::vector<int> out;
  for (size_t i = 0; i < surfaces.size(); ++i)
    if (!surfaces[i].is_stop) out.push_back(static_cast<int>(i));
  return out;
}

double Lens::refractiveIndex(int i, double wavelength_nm) const {
  if (i < 0) return 1.0;
  const Surface& s = surfaces[static_cast<size_t>(i)];
  const double um = wavelength_nm * 1e-3;
  if (s.sellmeier) {
    // Hullin 2011 §3.1: Sellmeier equation, λ in µm.
    const double l2 = um * um;
    double n2 = 1.0;
    for (int k = 0; k < 3; ++k) n2 += s.sellmeier->b[k] * l2 / (l2 - s.sellmeier->c_um2[k]);
    return std::sqrt(std::max(n2, 1e-6));
  }
  if (!s.abbe_d || s.ior_d == 1.0) return s.ior_d;
  // Two-term Cauchy fit through (n_d, V_d), as the Bodonyi/Csoba frameworks (lenses/README.md):
  // B = 0.52345 (n_d − 1) / V_d, A = n_d − B / 0.5876², n(λ) = A + B / λ².
  const double b = 0.52345 * (s.ior_d - 1.0) / *s.abbe_d;
  const double a = s.ior_d - b / (0.5876 * 0.5876);
  return a + b / (um * um);
}

double Lens::stopSemiAperture_mm() const {
  const int s = stopIndex();
  return s < 0 ? 0.0 : surfaces[static_cast<size_t>(s)].semi_aperture_mm;
}

Lens parseLensJson(std::string_view text, const std::string& file) {
  const ConfigNode root = parseJson(text, file);
  if (!root.isObject()) root.fail("a lens file must be a JSON object");
  root.checkKnownKeys({"name", "source", "units", "f_number", "focal_length_mm",
                       "paraxial_efl_mm_computed", "efl_check", "paraxial_bfl_mm_computed",
                       "paraxial_f_number_at_stop_semi_aperture_computed", "sensor_distance_mm",
                       "sum_of_thicknesses_mm_computed", "two_reflection_ghosts_computed",
                       "coating_ior", "notes", "surfaces", "format", "version"});
  Lens lens;
  lens.name = root.string("name", "");
  lens.source = root.string("source", "");
  lens.notes = root.string("notes", "");
  if (auto units = root.find("units"); units && units->string() != "mm")
    units->fail("only \"mm\" is supported, got \"" + units->string() + "\"");
  lens.facts.f_number = optionalNumber(root, "f_number");
  lens.facts.focal_length_mm = optionalNumber(root, "focal_length_mm");
  lens.facts.paraxial_efl_mm = optionalNumber(root, "paraxial_efl_mm_computed");
  lens.facts.paraxial_bfl_mm = optionalNumber(root, "paraxial_bfl_mm_computed");
  lens.facts.paraxial_f_number =
      optionalNumber(root, "paraxial_f_number_at_stop_semi_aperture_computed");
  if (auto g = root.find("two_reflection_ghosts_computed")) {
    g->checkKnownKeys({"all_surface_pairs", "both_reflections_on_same_side_of_stop"});
    lens.facts.ghosts_all = optionalInteger(*g, "all_surface_pairs");
    lens.facts.ghosts_same_side = optionalInteger(*g, "both_reflections_on_same_side_of_stop");
  }
  lens.coating_ior = optionalNumber(root, "coating_ior");

  const ConfigNode surfaces = root["surfaces"];
  if (!surfaces.isArray()) surfaces.fail("must be an array of surfaces");
  if (surfaces.size() == 0) surfaces.fail("the surface list is empty");
  for (size_t i = 0; i < surfaces.size(); ++i) {
    const ConfigNode s = surfaces[i];
    if (!s.isObject()) s.fail("each surface must be a table");
    s.checkKnownKeys({"radius", "thickness", "ior", "abbe", "semi_aperture", "coating_nm",
                      "is_stop", "sellmeier"});
    Surface surface;
    surface.radius_mm = s["radius"].number();
    surface.thickness_mm = s["thickness"].number();
    surface.ior_d = s.has("ior") ? s["ior"].number() : 1.0;
    surface.abbe_d = optionalNumber(s, "abbe");
    surface.semi_aperture_mm = s["semi_aperture"].number();
    surface.coating_nm = optionalNumber(s, "coating_nm");
    surface.is_stop = s.boolean("is_stop", false);
    if (auto sm = s.find("sellmeier")) {
      sm->checkKnownKeys({"b", "c_um2"});
      const auto b = (*sm)["b"].numbers();
      const auto c = (*sm)["c_um2"].numbers();
      if (b.size() != 3 || c.size() != 3) sm->fail("needs three \"b\" and three \"c_um2\" values");
      SellmeierCoefficients coefficients;
      for (int k = 0; k < 3; ++k) {
        coefficients.b[k] = b[k];
        coefficients.c_um2[k] = c[k];
      }
      surface.sellmeier = coefficients;
    }
    lens.surfaces.push_back(surface);
  }
  if (auto d = root.find("sensor_distance_mm"))
    lens.sensor_distance_mm = d->number();
  else
    lens.sensor_distance_mm = lens.surfaces.back().thickness_mm;
  validateLens(lens, file);
  if (lens.sensor_distance_mm <= 0) throw InputError(file, "sensor_distance_mm: must be > 0");
  return lens;
}

Lens parsePbrtLens(std::string_view text, const std::string& file) {
  Lens lens;
  std::istringstream in{std::string(text)};
  std::string line;
  int line_number = 0;
  int stop_by_ior = -1;
  while (std::getline(in, line)) {
    ++line_number;
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<double> values;
    std::string token;
    while (fields >> token) {
      char* end = nullptr;
      const double v = std::strtod(token.c_str(), &end);
      if (end == token.c_str() || *end != '\0' || !std::isfinite(v))
        throw InputError(file, "line " + std::to_string(line_number) + ": '" + token +
                                   "' is not a finite number");
      values.push_back(v);
    }
    if (values.empty()) continue;
    if (values.size() != 4)
      throw InputError(file, "line " + std::to_string(line_number) +
                                 ": expected 4 columns (radius, thickness, ior, aperture "
                                 "diameter), got " + std::to_string(values.size()));
    Surface s;
    s.radius_mm = values[0];
    s.thickness_mm = values[1];
    s.ior_d = values[2];
    s.semi_aperture_mm = values[3] / 2.0;  // pbrt gives the diameter
    if (values[2] == 0.0) {
      // pbrt marks the aperture stop with index 0 (and radius 0); it leaves the medium as air.
      if (stop_by_ior >= 0)
        throw InputError(file, "line " + std::to_string(line_number) +
                                   ": a second aperture stop (ior 0)");
      stop_by_ior = static_cast<int>(lens.surfaces.size());
      s.is_stop = true;
      s.ior_d = 1.0;
    }
    lens.surfaces.push_back(s);
  }
  if (lens.surfaces.empty()) throw InputError(file, "no surfaces (expected lines of 4 numbers)");
  if (stop_by_ior < 0) {
    // pbrt-v3 also treats a flat surface in air as the stop.
    for (auto& s : lens.surfaces)
      if (s.radius_mm == 0.0 && s.ior_d == 1.0) {
        s.is_stop = true;
        break;
      }
  }
  lens.name = std::filesystem::path(file).stem().string();
  lens.source = "pbrt realistic camera lens file " + std::filesystem::path(file).filename().string();
  lens.notes = "Imported from the pbrt .dat format: radius, thickness, ior (0 = stop), aperture "
               "diameter (halved to the semi-aperture). No Abbe numbers or coatings.";
  // Validate with a temporary sensor distance, then focus as pbrt would when the file gives none.
  lens.sensor_distance_mm = lens.surfaces.back().thickness_mm > 0 ? lens.surfaces.back().thickness_mm : 1.0;
  validateLens(lens, file);
  if (lens.surfaces.back().thickness_mm <= 0) {
    const ParaxialProperties p = paraxialProperties(lens);
    if (!(p.bfd_mm > 0) || !std::isfinite(p.bfd_mm))
      throw InputError(file, "the lens does not form a real image (back focal distance " +
                                 std::to_string(p.bfd_mm) + " mm)");
    lens.sensor_distance_mm = p.bfd_mm;
  }
  return lens;
}

Lens loadLens(const std::filesystem::path& path) {
  const std::string text = readInputFile(path);
  const std::string ext = path.extension().string();
  Lens lens = (ext == ".dat") ? parsePbrtLens(text, path.string()) : parseLensJson(text, path.string());
  lens.file = path;
  return lens;
}

void validateLens(const Lens& lens, const std::string& file) {
  if (lens.surfaces.empty()) throw InputError(file, "surfaces: the surface list is empty");
  if (lens.surfaces.size() < 3)
    throw InputError(file, "surfaces: a lens needs at least two refracting surfaces and a stop");
  int stops = 0;
  for (size_t i = 0; i < lens.surfaces.size(); ++i) {
    const Surface& s = lens.surfaces[i];
    const std::string where = surfaceName(i) + ": ";
    auto fail = [&](const std::string& problem) { throw InputError(file, where + problem); };
    if (!finite(s.radius_mm)) fail("radius is not a finite number");
    if (!finite(s.thickness_mm)) fail("thickness is not a finite number");
    if (!finite(s.ior_d)) fail("ior is not a finite number");
    if (!finite(s.semi_aperture_mm)) fail("semi_aperture is not a finite number");
    const bool last = i + 1 == lens.surfaces.size();
    if (s.thickness_mm < 0 || (!last && s.thickness_mm == 0))
      fail("thickness must be positive, got " + std::to_string(s.thickness_mm));
    if (!(s.ior_d >= kMinRefractiveIndex && s.ior_d <= kMaxRefractiveIndex))
      fail("ior must be in [" + numberText(kMinRefractiveIndex) + ", " + numberText(kMaxRefractiveIndex) + "], got " +
           numberText(s.ior_d));
    if (s.abbe_d && !(*s.abbe_d >= kMinAbbeNumber && *s.abbe_d <= kMaxAbbeNumber))
      fail("abbe must be in [" + numberText(kMinAbbeNumber) + ", " + numberText(kMaxAbbeNumber) + "], got " +
           numberText(*s.abbe_d));
    if (std::abs(s.radius_mm) > kMaxRadiusMm)
      fail("|radius| must be at most " + numberText(kMaxRadiusMm) + " mm (write 0 for a flat surface), got " +
           numberText(s.radius_mm));
    if (s.thickness_mm > kMaxLengthMm)
      fail("thickness must be at most " + numberText(kMaxLengthMm) + " mm, got " + numberText(s.thickness_mm));
    if (s.semi_aperture_mm > kMaxLengthMm)
      fail("semi_aperture must be at most " + numberText(kMaxLengthMm) + " mm, got " + numberText(s.semi_aperture_mm));
    if (!(s.semi_aperture_mm > 0))
      fail("semi_aperture must be > 0, got " + std::to_string(s.semi_aperture_mm));
    if (s.radius_mm != 0 && s.semi_aperture_mm >= std::abs(s.radius_mm))
      fail("semi_aperture " + std::to_string(s.semi_aperture_mm) +
           " mm is not below |radius| " + std::to_string(std::abs(s.radius_mm)) + " mm");
    if (s.coating_nm && !(*s.coating_nm > 0 && *s.coating_nm < 10000))
      fail("coating_nm must be in (0, 10000) nm");
    if (s.sellmeier) {
      for (int k = 0; k < 3; ++k)
        if (!finite(s.sellmeier->b[k]) || !finite(s.sellmeier->c_um2[k]))
          fail("sellmeier coefficients must be finite");
      const double n_d = lens.refractiveIndex(static_cast<int>(i), 587.56);
      if (!(n_d >= kMinRefractiveIndex && n_d <= kMaxRefractiveIndex))
        fail("sellmeier coefficients give n = " + numberText(n_d) + " at 587.56 nm, outside [" +
             numberText(kMinRefractiveIndex) + ", " + numberText(kMaxRefractiveIndex) + "]");
    }
    if (s.is_stop) {
      ++stops;
      if (s.radius_mm != 0) fail("the stop must be flat (radius 0)");
      const double before = i == 0 ? 1.0 : lens.surfaces[i - 1].ior_d;
      if (s.ior_d != before) fail("the stop must not change the medium (ior equal to the one before)");
    }
  }
  if (stops == 0) throw InputError(file, "surfaces: no aperture stop (one surface needs \"is_stop\": true)");
  if (stops > 1) throw InputError(file, "surfaces: " + std::to_string(stops) + " stops, expected exactly one");
  if (lens.surfaces.back().ior_d != 1.0)
    throw InputError(file, surfaceName(lens.surfaces.size() - 1) + ": the last medium must be air (ior 1)");
  if (!finite(lens.sensor_distance_mm) || lens.sensor_distance_mm > kMaxLengthMm)
    throw InputError(file, "sensor_distance_mm must be a finite number of at most " + numberText(kMaxLengthMm) + " mm");
  if (lens.coating_ior && !(*lens.coating_ior >= kMinRefractiveIndex && *lens.coating_ior <= kMaxRefractiveIndex))
    throw InputError(file, "coating_ior must be in [" + numberText(kMinRefractiveIndex) + ", " +
                               numberText(kMaxRefractiveIndex) + "]");
}

ParaxialProperties paraxialProperties(const Lens& lens, double wavelength_nm) {
  ParaxialProperties p;
  p.wavelength_nm = wavelength_nm;
  const RayMatrix system = systemMatrix(lens, wavelength_nm);
  p.efl_mm = -1.0 / system.c;
  p.bfd_mm = -system.a / system.c;
  const RayMatrix to_stop = matrixToStop(lens, wavelength_nm);
  // An axial ray at unit height reaches the stop at height A (README: "ray height at the stop for
  // a unit-height axial ray"); a ray aimed at the stop centre crosses the axis in object space at
  // z = B/A from the first vertex: the entrance pupil.
  p.stop_height_per_unit_input = to_stop.a;
  p.entrance_pupil_radius_mm = lens.stopSemiAperture_mm() / std::abs(to_stop.a);
  p.entrance_pupil_z_mm = to_stop.b / to_stop.a;
  p.f_number = p.efl_mm / (2.0 * p.entrance_pupil_radius_mm);
  return p;
}

Lens focusAtInfinity(const Lens& lens) {
  Lens out = lens;
  out.sensor_distance_mm = paraxialProperties(lens).bfd_mm;
  return out;
}

Lens stopDown(const Lens& lens, double f_number) {
  const std::string file = lens.file.empty() ? lens.name : lens.file.string();
  if (!std::isfinite(f_number) || f_number <= 0)
    throw InputError(file, "f-number must be a positive number, got " + std::to_string(f_number));
  const ParaxialProperties p = paraxialProperties(lens);
  if (f_number < p.f_number * (1.0 - 1e-9)) {
    std::ostringstream msg;
    msg.precision(3);
    msg << "f/" << f_number << " is wider than the stop allows (widest f/" << p.f_number << ")";
    throw InputError(file, msg.str());
  }
  Lens out = lens;
  const double ep_radius = std::abs(p.efl_mm) / (2.0 * f_number);
  out.surfaces[static_cast<size_t>(lens.stopIndex())].semi_aperture_mm =
      ep_radius * std::abs(p.stop_height_per_unit_input);
  return out;
}

LensInfo describeLens(const Lens& lens) {
  LensInfo info;
  info.name = lens.name;
  info.source = lens.source;
  info.file = lens.file.string();
  info.surfaces = static_cast<int>(lens.surfaces.size());
  info.interfaces = static_cast<int>(lens.interfaceIndices().size());
  info.stop_index = lens.stopIndex();
  info.paraxial = paraxialProperties(lens);
  info.sensor_distance_mm = lens.sensor_distance_mm;
  const int n = info.interfaces;
  info.ghosts_all = n * (n - 1) / 2;
  int before = 0;
  for (int i : lens.interfaceIndices())
    if (i < info.stop_index) ++before;
  const int after = n - before;
  info.ghosts_same_side = before * (before - 1) / 2 + after * (after - 1) / 2;
  return info;
}

}  // namespace flarekit::render
