#pragma once
// Lens prescriptions: the sequence of spherical surfaces from the object side to the sensor
// (docs/design.md, "The physical renderer"; schema in lenses/README.md), their validation, the
// pbrt "realistic camera" .dat import, paraxial analysis and stopping down.
//
// Conventions: millimetres, surfaces in object-to-image order, radius > 0 when the centre of
// curvature lies on the image side, 0 = flat; `thickness_mm` is the axial distance from this
// vertex to the next one (for the last surface: to the sensor as the file gives it); `ior_d` and
// `abbe_d` describe the medium *after* the surface. Exactly one surface is the aperture stop (flat,
// no change of medium). Wavelengths in nanometres.

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace flarekit::render {

// The d line (helium, 587.56 nm): the wavelength at which lens files give n_d and V_d.
inline constexpr double kWavelengthD_nm = 587.56;

// Sellmeier coefficients of a glass, n² = 1 + Σ B_i λ² / (λ² − C_i), λ in micrometres
// (Hullin 2011 §3.1). Used instead of (n_d, V_d) when a lens file gives them.
struct SellmeierCoefficients {
  std::array<double, 3> b{};      // dimensionless
  std::array<double, 3> c_um2{};  // µm²

  bool operator==(const SellmeierCoefficients&) const = default;
};

struct Surface {
  double radius_mm = 0.0;          // signed radius of curvature; 0 = flat
  double thickness_mm = 0.0;       // axial distance to the next vertex (last: to the sensor)
  double ior_d = 1.0;              // refractive index at 587.56 nm of the medium after it
  std::optional<double> abbe_d;    // Abbe number V_d of that medium; none = no dispersion
  std::optional<SellmeierCoefficients> sellmeier;  // when given, replaces (ior_d, abbe_d)
  double semi_aperture_mm = 0.0;   // clear semi-diameter (height from the axis)
  std::optional<double> coating_nm;  // design wavelength of a single-layer quarter-wave AR coat
  bool is_stop = false;            // the aperture stop (iris)

  bool isFlat() const { return radius_mm == 0.0; }
  bool operator==(const Surface&) const = default;
};

// What the lens file itself states about the lens, kept for checks and reports (all optional).
struct LensFileFacts {
  std::optional<double> f_number;                  // design f-number stated by the source
  std::optional<double> focal_length_mm;           // nominal focal length stated by the source
  std::optional<double> paraxial_efl_mm;           // "paraxial_efl_mm_computed"
  std::optional<double> paraxial_bfl_mm;           // "paraxial_bfl_mm_computed"
  std::optional<double> paraxial_f_number;         // "paraxial_f_number_at_stop_semi_aperture_computed"
  std::optional<int> ghosts_all;                   // "two_reflection_ghosts_computed.all_surface_pairs"
  std::optional<int> ghosts_same_side;             // "...both_reflections_on_same_side_of_stop"

  bool operator==(const LensFileFacts&) const = default;
};

struct Lens {
  std::string name;    // human-readable name
  std::string source;  // where the numbers came from (kept verbatim from the file)
  std::string notes;   // how the source was converted, known problems
  std::filesystem::path file;  // the file it was loaded from (empty when built in code)
  std::vector<Surface> surfaces;  // object side first
  // Distance from the last vertex to the sensor plane. Loaded from "sensor_distance_mm" (or the
  // last thickness); see focusAtInfinity().
  double sensor_distance_mm = 0.0;
  // Index of the single-layer AR coating named by the file, if any (else the renderer's default,
  // MgF₂ 1.38).
  std::optional<double> coating_ior;
  LensFileFacts facts;

  // Index of the stop surface in `surfaces` (validated lenses have exactly one).
  int stopIndex() const;
  // Indices (into `surfaces`) of the refracting interfaces, i.e. every surface but the stop.
  std::vector<int> interfaceIndices() const;
  // Refractive index of the medium after surface `i` at `wavelength_nm`; i = −1 is the object
  // space (air, 1.0). Sellmeier when given, else the two-term Cauchy fit through (n_d, V_d)
  // used by Hullin's supplement and the Bodonyi/Csoba frameworks (lenses/README.md):
  // B = 0.52345 (n_d − 1) / V_d, A = n_d − B / 0.5876², n = A + B / λ_µm².
  double refractiveIndex(int i, double wavelength_nm) const;
  // Stop semi-aperture (the iris opening) in mm.
  double stopSemiAperture_mm() const;
  // Every field the same (name and notes too).
  bool operator==(const Lens&) const = default;
};

// Loads a lens: ".json" in the schema of lenses/README.md, ".dat" as a pbrt realistic-camera file.
// Validates (see validateLens). Throws InputError "<file>: <key path>: <problem>" on bad input.
Lens loadLens(const std::filesystem::path& path);
// Parses JSON lens text; `file` names it in messages.
Lens parseLensJson(std::string_view text, const std::string& file);
// Parses a pbrt-v3/v4 realistic camera lens table: one surface per line, columns radius,
// thickness (to the next surface), ior (0 = the aperture stop), aperture *diameter*; '#' starts a
// comment. Radii, ior 0 and the sensor distance follow pbrt: the last thickness is the distance to
// the sensor when non-zero, else the paraxial back focal distance is used.
Lens parsePbrtLens(std::string_view text, const std::string& file);

// Physical ranges of a prescription's values. Optical glasses and crystals for visible light have
// 1.3 < n_d < 2.2 and 17 < V_d < 96; the ranges leave room and keep the tracer's arithmetic far
// from overflow. A flatter surface than kMaxRadiusMm is written as radius 0.
inline constexpr double kMinRefractiveIndex = 1.0;
inline constexpr double kMaxRefractiveIndex = 3.0;
inline constexpr double kMinAbbeNumber = 5.0;
inline constexpr double kMaxAbbeNumber = 150.0;
inline constexpr double kMaxRadiusMm = 1e6;
inline constexpr double kMaxLengthMm = 1e4;  // thickness, semi-aperture, sensor distance

// Checks the prescription: at least two surfaces, exactly one stop (flat, ior 1), positive
// thicknesses (the last may be 0 when the sensor distance comes from elsewhere), semi-apertures
// > 0 and below |radius| for curved surfaces, finite numbers, indices (also a Sellmeier glass's
// at 587.56 nm and a coating's) and Abbe numbers in the physical ranges above, radii and lengths
// within them, coating wavelengths in (0, 10000) nm, sensor distance > 0. Throws InputError
// naming `file`, the surface and the problem.
void validateLens(const Lens& lens, const std::string& file);

// First-order (paraxial) properties at one wavelength, object at infinity (ABCD matrices with
// reduced angles, as in lenses/README.md "How the computed fields were obtained").
struct ParaxialProperties {
  double wavelength_nm = kWavelengthD_nm;
  double efl_mm = 0.0;   // effective focal length, −1/C of the first-to-last-surface matrix
  double bfd_mm = 0.0;   // back focal distance, last vertex → paraxial focus, −A/C
  // Entrance pupil: image of the stop through the surfaces in front of it. Position measured from
  // the first vertex along +z (towards the image); radius for the current stop opening.
  double entrance_pupil_z_mm = 0.0;
  double entrance_pupil_radius_mm = 0.0;
  double f_number = 0.0;  // efl / (2 · entrance pupil radius)
  // Height at the stop of an axial ray entering at unit height (stop semi-aperture / this =
  // entrance pupil radius).
  double stop_height_per_unit_input = 0.0;
};
ParaxialProperties paraxialProperties(const Lens& lens, double wavelength_nm = kWavelengthD_nm);

// The lens with the sensor at the paraxial infinity focus (sensor distance = back focal distance).
Lens focusAtInfinity(const Lens& lens);
// The lens with the stop closed to `f_number` (paraxial, at the d line). Throws InputError when
// f_number is below the widest the stop allows or is not finite and positive.
Lens stopDown(const Lens& lens, double f_number);

// Summary lines for `flarekit lens-info`.
struct LensInfo {
  std::string name, source, file;
  int surfaces = 0, interfaces = 0, stop_index = -1;
  ParaxialProperties paraxial;
  double sensor_distance_mm = 0.0;
  int ghosts_all = 0;        // n(n−1)/2 two-reflection sequences
  int ghosts_same_side = 0;  // both reflections on the same side of the stop
};
LensInfo describeLens(const Lens& lens);

}  // namespace flarekit::render
