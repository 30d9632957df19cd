#pragma once
// Reflection at lens surfaces: Fresnel equations for unpolarized light and single-layer
// anti-reflection coatings by thin-film interference (Hullin 2011 §3.1 and its supplement).
//
// All functions take the index of the medium the light comes from (n1), the index of the medium
// on the other side (n2), and the cosine of the angle of incidence in n1. Past the critical angle
// the reflectance is 1 (total internal reflection). Pure functions, thread-safe.

#include <string>

namespace flarekit::render {

// Reflectances for s and p polarization, and their mean (unpolarized light).
struct Reflectance {
  double s = 0.0, p = 0.0;
  double unpolarized() const { return 0.5 * (s + p); }
};

// Bare interface: Fresnel equations.
Reflectance fresnelReflectance(double n1, double n2, double cos_incidence);

// A single coating layer of index `coating_ior` and physical thickness `thickness_nm` on the
// interface n1 | n2, at `wavelength_nm`: two-beam-amplitude thin-film interference summed to all
// orders (Airy), for s and p separately.
Reflectance thinFilmReflectance(double n1, double coating_ior, double thickness_nm, double n2,
                                double wavelength_nm, double cos_incidence);

// The physical thickness of a quarter-wave layer designed for `design_wavelength_nm` at normal
// incidence: d = λ0 / (4 n_c).
inline double quarterWaveThickness_nm(double design_wavelength_nm, double coating_ior) {
  return design_wavelength_nm / (4.0 * coating_ior);
}

// How a surface is coated for the renderer.
struct SurfaceCoating {
  bool coated = false;
  double coating_ior = 1.38;    // MgF₂
  double thickness_nm = 0.0;    // physical layer thickness
  // Unpolarized reflectance of the interface from medium n1 to n2.
  double reflectance(double n1, double n2, double wavelength_nm, double cos_incidence) const;
};

}  // namespace flarekit::render
