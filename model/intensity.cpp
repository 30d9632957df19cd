#include "model/intensity.h"

#include <algorithm>
#include <cmath>

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

double intensity(double d, const GhostParameters& g, int channel) {
  const TransferWeights w = transferWeights(d, g, false);
  return w.border * g.border[channel] + w.inside * g.inside[channel];
}

}  // namespace flarekit::model
