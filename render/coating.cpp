#include "render/coating.h"

#include <algorithm>
#include <cmath>
#include <complex>

namespace flarekit::render {
namespace {

using Complex = std::complex<double>;

// cos of the refracted angle in a medium of index n for a ray with invariant n1 sin θ1
// (complex past the critical angle: an evanescent wave).
Complex cosineIn(double n, double n1_sin) {
  const double sin_t = n1_sin / n;
  return std::sqrt(Complex(1.0 - sin_t * sin_t, 0.0));
}

// Fresnel amplitude reflection coefficients (Hecht, Optics §4.6) between indices a and b, with
// cosines ca and cb in each medium.
Complex rs(double a, Complex ca, double b, Complex cb) { return (a * ca - b * cb) / (a * ca + b * cb); }
Complex rp(double a, Complex ca, double b, Complex cb) { return (b * ca - a * cb) / (b * ca + a * cb); }

}  // namespace

Reflectance fresnelReflectance(double n1, double n2, double cos_incidence) {
  const double ci = std::clamp(std::abs(cos_incidence), 0.0, 1.0);
  const double si = std::sqrt(std::max(0.0, 1.0 - ci * ci));
  const double st = n1 * si / n2;
  if (st >= 1.0) return {1.0, 1.0};  // total internal reflection
  const double ct = std::sqrt(1.0 - st * st);
  // Hullin 2011 §3.1, Fresnel for the two polarizations.
  const double s = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct);
  const double p = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct);
  return {s * s, p * p};
}

Reflectance thinFilmReflectance(double n1, double coating_ior, double thickness_nm, double n2,
                                double wavelength_nm, double cos_incidence) {
  const double ci = std::clamp(std::abs(cos_incidence), 0.0, 1.0);
  const double n1_sin = n1 * std::sqrt(std::max(0.0, 1.0 - ci * ci));
  if (n1_sin >= n2) return {1.0, 1.0};  // total internal reflection at the substrate
  const Complex c1(ci, 0.0);
  const Complex cc = cosineIn(coating_ior, n1_sin);
  const Complex c2 = cosineIn(n2, n1_sin);
  // Phase difference of one round trip through the layer: δ = 2π/λ · 2 n_c d cos θ_c
  // (Hullin 2011 supplement; Born & Wolf §1.6.4). Complex cos θ_c covers frustrated TIR.
  const Complex delta = 2.0 * M_PI / wavelength_nm * 2.0 * coating_ior * thickness_nm * cc;
  const Complex phase = std::exp(Complex(0.0, 1.0) * delta);
  auto total = [&](Complex r12, Complex r23) {
    const Complex r = (r12 + r23 * phase) / (1.0 + r12 * r23 * phase);
    return std::min(1.0, std::norm(r));
  };
  return {total(rs(n1, c1, coating_ior, cc), rs(coating_ior, cc, n2, c2)),
          total(rp(n1, c1, coating_ior, cc), rp(coating_ior, cc, n2, c2))};
}

double SurfaceCoating::reflectance(double n1, double n2, double wavelength_nm,
                                   double cos_incidence) const {
  if (!coated || thickness_nm <= 0) return fresnelReflectance(n1, n2, cos_incidence).unpolarized();
  return thinFilmReflectance(n1, coating_ior, thickness_nm, n2, wavelength_nm, cos_incidence)
      .unpolarized();
}

}  // namespace flarekit::render
