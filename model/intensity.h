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

// The weights at signed distance `d` (pixels) for the ghost's Fi, Ei, Fo, Eo.
TransferWeights transferWeights(double d, const GhostParameters& ghost, bool with_derivatives);

// I_c(d) for channel c in [0, ghost.channels).
double intensity(double d, const GhostParameters& ghost, int channel);

}  // namespace flarekit::model
