#pragma once
// Helpers for fit/'s tests (header-only; not part of the library).

#include "model/ghost_shape.h"

namespace flarekit::fit::testing {

// A one-channel ghost with the shape the fit tests share: centre (x, y), half-widths l, r, height
// h (px), border and inside intensity ib, ii; curvatures 0.5 / 0.6, fall-offs 6 px inside and
// 3 px outside, exponents 1.5.
inline model::GhostParameters ghost(double x, double y, double l, double r, double h, double ib,
                                    double ii) {
  model::GhostParameters g;
  g.center_x = x;
  g.center_y = y;
  g.left = l;
  g.right = r;
  g.height = h;
  g.curvature_left = 0.5;
  g.curvature_right = 0.6;
  g.border = {ib, 0, 0};
  g.inside = {ii, 0, 0};
  g.inside_falloff = 6;
  g.inside_exponent = 1.5;
  g.outside_falloff = 3;
  g.outside_exponent = 1.5;
  return g;
}

}  // namespace flarekit::fit::testing
