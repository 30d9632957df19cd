#pragma once
// A flare model as GLSL: the model's coefficients baked into a shader library whose function
//
//   vec3 flare(vec2 uv, float theta, float phi)
//
// draws the model as FlareModel::render does (model/flare_model.h): every ghost's outline, signed
// distance and shade (Walch et al. 2018 §3.2) and the pedestal, summed and clamped at 0, in the
// capture's linear units, R, G, B (a grey model repeats its value). uv is the point's offset from
// the image's centre in image widths (x right, y down, so the image spans uv.x in [−0.5, 0.5]); θ
// is the light's field angle and φ the roll about the optical axis, degrees, as on the command line.
// The flare keeps its size relative to the image's width, as `flarekit render --width` draws it.
//
// The library is GLSL ES 3.00 (WebGL2), which desktop GLSL 3.30 and later also compile after a
// `#version` line of their own. Besides flare() it declares what a renderer needs to draw ghosts
// one at a time (the viewer draws each as a quad over its box): FlareGhost, flareGhostAt,
// flareGhostValue, flarePedestal, flareCapturePoint, flareImagePoint. `flarekit export-shader` and
// `flarekit view` write the same text.
//
// Differences from the CPU renderer: single-precision arithmetic, and the nearest point on the
// outline from even samples refined by a safeguarded Newton (model/signed_distance.h adds samples
// where the outline turns sharply); both are far below a pixel.

#include <string>

#include "model/flare_model.h"

namespace flarekit::view {

struct FlareShaderOptions {
  // Samples of each upper-half Bézier segment from which the nearest point is refined (≥ 4).
  int samples_per_segment = 12;
  // Safeguarded Newton steps refining the nearest point (≥ 1).
  int newton_steps = 6;
  // Shown in the library's first comment line: where the model came from.
  std::string source_name;

  bool IsValid(std::string* error) const;
};

// The GLSL library of `model` (which must be valid). Throws std::invalid_argument for invalid
// options.
std::string flareShader(const model::FlareModel& model, const FlareShaderOptions& options = {});

}  // namespace flarekit::view
