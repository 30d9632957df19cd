#include "model/intensity.h"

#include <algorithm>
#include <cmath>
#include <cstring>

namespace flarekit::model {

TransferWeights transferWeights(double d, const GhostParameters& g, bool with_derivatives) {
  // Walch 2018 §3.2, Fig. 6: the value fades from Ib on the outline to Ii inside over Fi (slope
  // exponent Ei) and to 0 outside over Fo (exponent Eo). Both sides have the form
  // I = Ib + (target − Ib)·τ^E with τ the distance relative to the fall-off range, clamped to 1.
  TransferWeights w;
  const bool inside = d < 0;
  w.is_inside = inside;
  const double falloff = inside ? g.inside_falloff : g.outside_falloff;
  const double exponent = inside ? g.inside_exponent : g.outside_exponent;
  const double a = std::abs(d);
  const bool saturated = a >= falloff;
  const double tau = saturated ? 1.0 : a / falloff;
  const double power = transferPower(tau, exponent);  // τ^E
  w.border = 1 - power;
  w.inside = inside ? power : 0.0;
  if (!with_derivatives || saturated) return w;
  const double log_tau = tau > 0 ? std::log(tau) : 0.0;
  // ∂τ^E/∂τ = E·τ^(E−1), finite at τ = 0 by evaluating at max(τ, 1e-9) (the outline is a
  // non-smooth point of the model anyway).
  const double dpower_dtau =
      tau > 1e-9 ? exponent * power / tau : exponent * std::pow(1e-9, exponent - 1);
  const double dtau_dd = (inside ? -1.0 : 1.0) / falloff;
  const double dtau_dfalloff = -tau / falloff;
  const double dpower_dexponent = tau > 0 ? power * log_tau : 0.0;
  const double dpower_dd = dpower_dtau * dtau_dd;
  const double dpower_dfalloff = dpower_dtau * dtau_dfalloff;
  w.border_d_distance = -dpower_dd;
  w.border_d_falloff = -dpower_dfalloff;
  w.border_d_exponent = -dpower_dexponent;
  if (inside) {
    w.inside_d_distance = dpower_dd;
    w.inside_d_falloff = dpower_dfalloff;
    w.inside_d_exponent = dpower_dexponent;
  }
  return w;
}

// One clone per instruction set, chosen when the program loads (the vector code is the same; the
// file has no fused multiply-adds, model/CMakeLists.txt, so every clone gives the same bits).
// Clang (the fuzzing build, scripts/fuzz.sh) refuses the clone's calls of the vector helpers
// (AVX vector arguments without AVX in the callee): one portable version there.
#if !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
void transferValueWeights(const double* d, int count, const GhostParameters& g, double* border,
                          double* inside) {
  using detail::Double4;
  using detail::Int64x4;
  const Double4 zero = {}, one = zero + 1;
  for (int i = 0; i < count; i += 4) {
    const bool full = count - i >= 4;
    Double4 distance = zero;  // lanes beyond `count` compute from d = 0, and are not stored
    if (full)
      std::memcpy(&distance, d + i, sizeof distance);
    else
      for (int l = i; l < count; ++l) distance[l - i] = d[l];
    // The scalar transferValueWeights and transferPower, lane by lane, with selects for branches.
    const Int64x4 is_inside = distance < 0;
    const Double4 falloff = is_inside ? zero + g.inside_falloff : zero + g.outside_falloff;
    const Double4 exponent = is_inside ? zero + g.inside_exponent : zero + g.outside_exponent;
    const Double4 a = detail::bitCast<Double4>(detail::bitCast<Int64x4>(distance) & 0x7FFFFFFFFFFFFFFF);
    const Double4 tau = a >= falloff ? one : a / falloff;
    const Int64x4 in_range = (tau > 0) & (tau < 1);
    const Double4 y = exponent * detail::transferLogCore(in_range ? tau : one);
    const Int64x4 fast_exp = (y > -detail::kExpFastLimit) & (y < detail::kExpFastLimit);
    const Double4 power_fast = detail::transferExpCore(fast_exp ? y : zero);
    Double4 power = tau >= 1 ? one : (tau > 0 ? power_fast : zero);
    // τ subnormal, or τ^E below e^−700: libm's range, as the scalar functions do (rare).
    const Int64x4 slow = in_range & ((tau < detail::kSmallestNormal) | ~fast_exp);
    if ((slow[0] | slow[1] | slow[2] | slow[3]) != 0)
      for (int l = 0; l < 4; ++l)
        if (slow[l]) power[l] = transferPower(tau[l], exponent[l]);
    const Double4 border_weight = one - power, inside_weight = is_inside ? power : zero;
    if (full) {
      std::memcpy(border + i, &border_weight, sizeof border_weight);
      std::memcpy(inside + i, &inside_weight, sizeof inside_weight);
    } else {
      for (int l = i; l < count; ++l) {
        border[l] = border_weight[l - i];
        inside[l] = inside_weight[l - i];
      }
    }
  }
}

double intensity(double d, const GhostParameters& g, int channel) {
  const TransferWeights w = transferWeights(d, g, false);
  return w.border * g.border[channel] + w.inside * g.inside[channel];
}

}  // namespace flarekit::model
