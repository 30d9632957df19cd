#pragma once
// The intensity transfer function of a ghost (Walch et al. 2018 §3.2, Fig. 6): the value at a
// point as a function of its signed distance d to the outline (negative inside).
//
//   inside  (d < 0): τ = min(−d / Fi, 1),  I = Ib + (Ii − Ib)·τ^Ei
//   outside (d ≥ 0): τ = min( d / Fo, 1),  I = Ib·(1 − τ^Eo)
//
// so I = Ib on the outline, Ii deeper than Fi inside, 0 farther than Fo outside; the slope
// exponents shape the fall-off (1 linear, < 1 steep at the outline, > 1 flat at the outline).
// The function is linear in Ib and Ii: I_c = w_border·Ib_c + w_inside·Ii_c with weights that
// depend on d, Fi, Ei, Fo, Eo only; colour (ours; the paper is grey) applies the same weights to
// each channel's Ib and Ii.
//
// Non-smooth points: d = 0 (the two sides meet; with exponents < 1 the slope is infinite there),
// d = −Fi and d = Fo (the fall-off ends). Derivatives there are one-sided values, always finite:
// τ^(E−1) is evaluated at max(τ, 1e-9), and τ^E·ln τ is 0 at τ = 0.

#include <cmath>

#include "model/detail/transfer_math.h"
#include "model/ghost_shape.h"

namespace flarekit::model {

// Weights of Ib and Ii at one signed distance, with their partial derivatives.
struct TransferWeights {
  double border = 0;  // w_border = ∂I_c/∂Ib_c
  double inside = 0;  // w_inside = ∂I_c/∂Ii_c

  // ∂w/∂d, ∂w/∂F, ∂w/∂E for the side d lies on (F, E = Fi, Ei inside, Fo, Eo outside; the other
  // side's derivatives are 0). Filled only when asked for.
  double border_d_distance = 0, inside_d_distance = 0;
  double border_d_falloff = 0, inside_d_falloff = 0;
  double border_d_exponent = 0, inside_d_exponent = 0;
  bool is_inside = false;  // d < 0: the falloff/exponent derivatives are ∂/∂Fi, ∂/∂Ei
};

// τ^E for the relative distance τ in [0, 1] (1 at and beyond the fall-off range): the one place
// the transfer function's power is computed, so that every path (renderer, derivative images,
// per-point evaluation) gives the same bits.
inline double transferPower(double tau, double exponent) {
  // exp(E·ln τ) rather than std::pow: about 40 % fewer instructions with glibc, same accuracy
  // for τ in (0, 1) and E in [0.1, 10] (a few ulp). The inline exp and log (detail/
  // transfer_math.h) agree with glibc's to 1–2 ulp and save the calls into libm, about a quarter
  // of a fall-off pixel's instructions besides the distance.
  return tau >= 1 ? 1.0 : (tau > 0 ? detail::transferExp(exponent * detail::transferLog(tau)) : 0.0);
}

// The value weights only (border, inside) at signed distance `d`: what transferWeights returns
// without derivatives, for the renderer's inner loop.
inline void transferValueWeights(double d, const GhostParameters& g, double& border, double& inside) {
  const bool is_inside = d < 0;
  const double falloff = is_inside ? g.inside_falloff : g.outside_falloff;
  const double a = std::abs(d);
  const double power = a >= falloff ? 1.0 : transferPower(a / falloff, is_inside ? g.inside_exponent : g.outside_exponent);
  border = 1 - power;
  inside = is_inside ? power : 0.0;
}

// transferValueWeights for `count` signed distances at once (a renderer's pixels): the same bits
// per distance, computed in vector lanes (four doubles per instruction where the machine has
// AVX2, two with SSE2).
void transferValueWeights(const double* d, int count, const GhostParameters& g, double* border,
                          double* inside);

// The weights at signed distance `d` (pixels) for the ghost's Fi, Ei, Fo, Eo.
TransferWeights transferWeights(double d, const GhostParameters& ghost, bool with_derivatives);

// I_c(d) for channel c in [0, ghost.channels).
double intensity(double d, const GhostParameters& ghost, int channel);

}  // namespace flarekit::model
