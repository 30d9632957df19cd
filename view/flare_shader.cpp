#include "view/flare_shader.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "model/ghost_shape.h"
#include "model/pedestal.h"

namespace flarekit::view {
namespace {

using model::ParameterLayout;

// A float literal GLSL reads back to the nearest single-precision value of v.
std::string glslFloat(double v) {
  const double largest = std::numeric_limits<float>::max();
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", std::clamp(v, -largest, largest));
  std::string s = text;
  if (s.find_first_of(".e") == std::string::npos) s += ".0";
  return s;
}

// A name from the model file, made safe for one line of a GLSL comment (and of an HTML page).
std::string commentText(const std::string& s) {
  std::string out;
  for (unsigned char c : s) out += (c < 0x20 || c == 0x7f || c == '<' || c == '>' || c == '\\') ? ' ' : char(c);
  return out;
}

// A constant float array; GLSL has no arrays of size 0, so an empty one holds a single 0.
std::string floatArray(const std::string& name, const std::vector<double>& values) {
  std::ostringstream out;
  const size_t n = std::max<size_t>(values.size(), 1);
  out << "const float " << name << "[" << n << "] = float[](";
  for (size_t i = 0; i < n; ++i) {
    out << (i ? (i % 8 ? ", " : ",\n    ") : "") << (i < values.size() ? glslFloat(values[i]) : "0.0");
  }
  out << ");\n";
  return out.str();
}

// Coefficients per polynomial: the highest degree in the model plus one (at least 1).
int termsOf(const model::FlareModel& m) {
  size_t terms = 1;
  for (const auto& g : m.ghosts)
    for (const auto& p : g.parameters) terms = std::max(terms, p.coefficients.size());
  if (m.pedestal)
    for (const auto& p : m.pedestal->terms) terms = std::max(terms, p.coefficients.size());
  return static_cast<int>(terms);
}

void appendPolynomial(std::vector<double>& out, const model::Polynomial& p, int terms) {
  for (int k = 0; k < terms; ++k)
    out.push_back(k < static_cast<int>(p.coefficients.size()) ? p.coefficients[k] : 0.0);
}

// The parts of the library that do not depend on the model.
constexpr char kFunctions[] = R"GLSL(
// One ghost at one angle (model/ghost_shape.h): lengths in capture pixels.
struct FlareGhost {
  vec2 center;                 // (Mx, My); the outline is mirror-symmetric about y = My
  float left, right, height;   // L, R, h
  float curvature_left;        // Cl
  float curvature_right;       // Cr
  vec3 border;                 // Ib per channel: the value on the outline
  vec3 inside;                 // Ii per channel: the value deeper than Fi inside
  float inside_falloff, inside_exponent;    // Fi (pixels), Ei
  float outside_falloff, outside_exponent;  // Fo (pixels), Eo
};

// p(θ) by Horner's rule from FLARE_TERMS coefficients starting at `first`.
float flarePolynomial(int first, float theta) {
  float v = 0.0;
  for (int k = FLARE_TERMS - 1; k >= 0; --k) v = v * theta + FLARE_COEFFICIENTS[first + k];
  return v;
}

float flarePedestalPolynomial(int first, float theta) {
  float v = 0.0;
  for (int k = FLARE_TERMS - 1; k >= 0; --k) v = v * theta + FLARE_PEDESTAL_COEFFICIENTS[first + k];
  return v;
}

// Ghost `ghost` (0 ≤ ghost < FLARE_GHOSTS) at field angle θ (degrees), its parameters clamped to
// their bounds; false where θ is outside the ghost's range (it is not drawn there).
bool flareGhostAt(int ghost, float theta, out FlareGhost g) {
  float p[FLARE_PARAMETERS];
  int first = ghost * FLARE_PARAMETERS * FLARE_TERMS;
  for (int k = 0; k < FLARE_PARAMETERS; ++k)
    p[k] = clamp(flarePolynomial(first + k * FLARE_TERMS, theta), FLARE_LOWER[k], FLARE_UPPER[k]);
  FLARE_UNPACK
  vec2 range = FLARE_GHOST_RANGE[ghost];
  return theta >= range.x && theta <= range.y;
}

// The upper half of the outline (y ≤ My) relative to M: segment 0 (P_L → P_T) or 1 (P_T → P_R) in
// power form, B(t) = a0 + a1·t + a2·t² + a3·t³.
void flareSegment(FlareGhost g, int s, out vec2 a0, out vec2 a1, out vec2 a2, out vec2 a3) {
  vec2 p0, p1, p2, p3;
  if (s == 0) {
    p0 = vec2(-g.left, 0.0);
    p1 = vec2(-g.left, -g.curvature_left * g.height);
    p2 = vec2(-g.curvature_left * g.left, -g.height);
    p3 = vec2(0.0, -g.height);
  } else {
    p0 = vec2(0.0, -g.height);
    p1 = vec2(g.curvature_right * g.right, -g.height);
    p2 = vec2(g.right, -g.curvature_right * g.height);
    p3 = vec2(g.right, 0.0);
  }
  a0 = p0;
  a1 = 3.0 * (p1 - p0);
  a2 = 3.0 * (p2 - 2.0 * p1 + p0);
  a3 = p3 - 3.0 * p2 + 3.0 * p1 - p0;
}

// The squared distance from r to one segment: the nearest of even samples, refined by a
// safeguarded Newton on (B − r)·B′ = 0 within the neighbouring samples.
float flareSegmentDistance2(vec2 a0, vec2 a1, vec2 a2, vec2 a3, vec2 r) {
  float best = 3.4e38;
  int best_k = 0;
  for (int k = 0; k <= FLARE_SAMPLES; ++k) {
    float t = float(k) / float(FLARE_SAMPLES);
    vec2 b = ((a3 * t + a2) * t + a1) * t + a0 - r;
    float d2 = dot(b, b);
    if (d2 < best) {
      best = d2;
      best_k = k;
    }
  }
  float lo = float(max(best_k - 1, 0)) / float(FLARE_SAMPLES);
  float hi = float(min(best_k + 1, FLARE_SAMPLES)) / float(FLARE_SAMPLES);
  float t = float(best_k) / float(FLARE_SAMPLES);
  for (int i = 0; i < FLARE_NEWTON_STEPS; ++i) {
    vec2 b = ((a3 * t + a2) * t + a1) * t + a0 - r;
    vec2 d1 = (3.0 * a3 * t + 2.0 * a2) * t + a1;
    vec2 dd = 6.0 * a3 * t + 2.0 * a2;
    float f = dot(b, d1), fp = dot(d1, d1) + dot(b, dd);
    if (f > 0.0) hi = t; else lo = t;
    float next = fp > 0.0 ? t - f / fp : 0.5 * (lo + hi);
    t = (next >= lo && next <= hi) ? next : 0.5 * (lo + hi);
  }
  vec2 b = ((a3 * t + a2) * t + a1) * t + a0 - r;
  return min(best, dot(b, b));
}

// Whether r (relative to M, reflected into the upper half) lies inside the outline: below the
// outline's height at r.x, found on the segment over r.x (x(t) rises on both).
bool flareInside(FlareGhost g, vec2 r) {
  if (r.x < -g.left || r.x > g.right || r.y < -g.height) return false;
  vec2 a0, a1, a2, a3;
  flareSegment(g, r.x <= 0.0 ? 0 : 1, a0, a1, a2, a3);
  // Safeguarded Newton on x(t) = r.x from the straight-line guess, as model/ does.
  float lo = 0.0, hi = 1.0;
  float t = clamp(r.x <= 0.0 ? 1.0 + r.x / g.left : r.x / g.right, 0.0, 1.0);
  for (int i = 0; i < 8; ++i) {
    float f = ((a3.x * t + a2.x) * t + a1.x) * t + a0.x - r.x;
    if (f > 0.0) hi = t; else lo = t;
    float fp = (3.0 * a3.x * t + 2.0 * a2.x) * t + a1.x;
    float next = fp > 0.0 ? t - f / fp : 0.5 * (lo + hi);
    t = (next >= lo && next <= hi) ? next : 0.5 * (lo + hi);
  }
  return r.y >= ((a3.y * t + a2.y) * t + a1.y) * t + a0.y;
}

// The ghost's value at capture point q: the transfer function of the signed distance
// (model/intensity.h).
vec3 flareGhostValue(FlareGhost g, vec2 q) {
  vec2 r = vec2(q.x - g.center.x, -abs(q.y - g.center.y));
  float fo = g.outside_falloff;
  if (r.x < -g.left - fo || r.x > g.right + fo || r.y < -g.height - fo) return vec3(0.0);
  vec2 a0, a1, a2, a3;
  flareSegment(g, 0, a0, a1, a2, a3);
  float d2 = flareSegmentDistance2(a0, a1, a2, a3, r);
  flareSegment(g, 1, a0, a1, a2, a3);
  float d = sqrt(min(d2, flareSegmentDistance2(a0, a1, a2, a3, r)));
  if (flareInside(g, r)) {
    float tau = min(d / g.inside_falloff, 1.0);
    float w = tau > 0.0 ? pow(tau, g.inside_exponent) : 0.0;
    return g.border * (1.0 - w) + g.inside * w;
  }
  float tau = min(d / fo, 1.0);
  return tau >= 1.0 ? vec3(0.0) : g.border * (1.0 - pow(tau, g.outside_exponent));
}

// The pedestal at field angle θ (model/pedestal.h): c[k] multiplies term k of (1, u, v, u², uv, v²)
// per channel; false (and all 0) where the model has none or θ is outside its range.
bool flarePedestalAt(float theta, out vec3 c[6]) {
  for (int k = 0; k < 6; ++k) c[k] = vec3(0.0);
  if (!FLARE_HAS_PEDESTAL || theta < FLARE_PEDESTAL_RANGE.x || theta > FLARE_PEDESTAL_RANGE.y) return false;
  for (int ch = 0; ch < FLARE_CHANNELS; ++ch)
    for (int k = 0; k < 6; ++k) c[k][ch] = flarePedestalPolynomial((ch * 6 + k) * FLARE_TERMS, theta);
  if (FLARE_CHANNELS == 1)
    for (int k = 0; k < 6; ++k) c[k] = vec3(c[k].x);
  return true;
}

// The pedestal of coefficients c at capture point q, taken at the nearest point of the capture's
// frame: u = (x − W/2) / W, v = (y − H/2) / W.
vec3 flarePedestalValue(vec3 c[6], vec2 q) {
  vec2 p = clamp(q, vec2(0.0), FLARE_CAPTURE_SIZE);
  float u = (p.x - 0.5 * FLARE_CAPTURE_SIZE.x) / FLARE_CAPTURE_SIZE.x;
  float v = (p.y - 0.5 * FLARE_CAPTURE_SIZE.y) / FLARE_CAPTURE_SIZE.x;
  return c[0] + c[1] * u + c[2] * v + c[3] * (u * u) + c[4] * (u * v) + c[5] * (v * v);
}

vec3 flarePedestal(vec2 q, float theta) {
  vec3 c[6];
  return flarePedestalAt(theta, c) ? flarePedestalValue(c, q) : vec3(0.0);
}

// The capture point an image point shows: uv is the offset from the image's centre in image
// widths (y down); the roll φ (degrees) turns the flare about the optical axis, counter-clockwise
// as displayed (FlareModel::viewAt).
vec2 flareCapturePoint(vec2 uv, float phi) {
  float c = cos(radians(phi)), s = sin(radians(phi));
  vec2 d = uv * FLARE_CAPTURE_SIZE.x - (FLARE_OPTICAL_AXIS - 0.5 * FLARE_CAPTURE_SIZE);
  return FLARE_OPTICAL_AXIS + vec2(c * d.x - s * d.y, s * d.x + c * d.y);
}

// The inverse of flareCapturePoint: where capture point q appears, in image widths from the
// image's centre.
vec2 flareImagePoint(vec2 q, float phi) {
  float c = cos(radians(phi)), s = sin(radians(phi));
  vec2 x = q - FLARE_OPTICAL_AXIS;
  vec2 turned = vec2(c * x.x + s * x.y, -s * x.x + c * x.y);
  return (FLARE_OPTICAL_AXIS - 0.5 * FLARE_CAPTURE_SIZE + turned) / FLARE_CAPTURE_SIZE.x;
}

// The flare at image point uv for a light at field angle θ and roll φ (degrees): linear R, G, B.
vec3 flare(vec2 uv, float theta, float phi) {
  vec2 q = flareCapturePoint(uv, phi);
  vec3 sum = vec3(0.0);
  for (int i = 0; i < FLARE_GHOSTS; ++i) {
    FlareGhost g;
    if (flareGhostAt(i, theta, g)) sum += flareGhostValue(g, q);
  }
  return max(sum + flarePedestal(q, theta), 0.0);
}
)GLSL";

}  // namespace

bool FlareShaderOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* message) {
    if (error) *error = message;
    return false;
  };
  if (samples_per_segment < 4 || samples_per_segment > 256) return fail("samples_per_segment must be in [4, 256]");
  if (newton_steps < 1 || newton_steps > 64) return fail("newton_steps must be in [1, 64]");
  return true;
}

std::string flareShader(const model::FlareModel& m, const FlareShaderOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw std::invalid_argument("FlareShaderOptions: " + why);
  const ParameterLayout layout{m.channels};
  const int parameters = layout.count(), terms = termsOf(m);

  std::vector<double> coefficients, ranges, lower, upper, pedestal;
  for (const auto& g : m.ghosts) {
    for (const auto& p : g.parameters) appendPolynomial(coefficients, p, terms);
    ranges.push_back(g.angle_min_deg);
    ranges.push_back(g.angle_max_deg);
  }
  for (int k = 0; k < parameters; ++k) {
    const model::ParameterBounds b = model::parameterBounds(k, m.channels);
    lower.push_back(b.lower);
    upper.push_back(b.upper);
  }
  if (m.pedestal)
    for (const auto& p : m.pedestal->terms) appendPolynomial(pedestal, p, terms);

  std::ostringstream out;
  out << "// FlareKit flare shader (GLSL ES 3.00): " << commentText(m.capture.lens) << " on "
      << commentText(m.capture.camera);
  if (!options.source_name.empty()) out << ", from " << commentText(options.source_name);
  out << ".\n// vec3 flare(vec2 uv, float theta, float phi): the flare's linear R, G, B at image point uv\n"
         "// (offset from the image's centre in image widths, y down) for a light at field angle theta and\n"
         "// roll phi (degrees). Generated by flarekit; the model's coefficients are baked in.\n\n";
  out << "const int FLARE_GHOSTS = " << m.ghosts.size() << ";\n"
      << "const int FLARE_CHANNELS = " << m.channels << ";\n"
      << "const int FLARE_PARAMETERS = " << parameters << ";  // per ghost, model/ghost_shape.h order\n"
      << "const int FLARE_TERMS = " << terms << ";  // coefficients per polynomial in θ (degrees)\n"
      << "const int FLARE_SAMPLES = " << options.samples_per_segment << ";\n"
      << "const int FLARE_NEWTON_STEPS = " << options.newton_steps << ";\n"
      << "const vec2 FLARE_CAPTURE_SIZE = vec2(" << glslFloat(m.capture.image_size.width) << ", "
      << glslFloat(m.capture.image_size.height) << ");  // capture pixels\n";
  const cv::Point2d axis = m.capture.opticalAxis();
  out << "const vec2 FLARE_OPTICAL_AXIS = vec2(" << glslFloat(axis.x) << ", " << glslFloat(axis.y)
      << ");  // capture pixels\n";
  out << "const bool FLARE_HAS_PEDESTAL = " << (m.pedestal ? "true" : "false") << ";\n";
  out << "const vec2 FLARE_PEDESTAL_RANGE = vec2("
      << glslFloat(m.pedestal ? m.pedestal->angle_min_deg : 0) << ", "
      << glslFloat(m.pedestal ? m.pedestal->angle_max_deg : -1) << ");  // degrees\n";
  out << floatArray("FLARE_LOWER", lower) << floatArray("FLARE_UPPER", upper);
  out << "const vec2 FLARE_GHOST_RANGE[" << std::max<size_t>(m.ghosts.size(), 1) << "] = vec2[](";
  for (size_t i = 0; i < std::max<size_t>(m.ghosts.size(), 1); ++i)
    out << (i ? ", " : "") << "vec2("
        << (i < m.ghosts.size() ? glslFloat(ranges[2 * i]) + ", " + glslFloat(ranges[2 * i + 1]) : "0.0, -1.0")
        << ")";
  out << ");  // each ghost's θ range, degrees\n";
  out << "// Ghost i's parameter k has coefficient j at [(i·FLARE_PARAMETERS + k)·FLARE_TERMS + j].\n"
      << floatArray("FLARE_COEFFICIENTS", coefficients);
  out << "// The pedestal's term k of channel c: [(c·6 + k)·FLARE_TERMS + j].\n"
      << floatArray("FLARE_PEDESTAL_COEFFICIENTS", pedestal);

  // Parameter vector → FlareGhost, in the layout of ghost_shape.h for this channel count.
  std::ostringstream unpack;
  using namespace model::param;
  unpack << "g.center = vec2(p[" << kMx << "], p[" << kMy << "]);\n"
         << "  g.left = p[" << kL << "]; g.right = p[" << kR << "]; g.height = p[" << kH << "];\n"
         << "  g.curvature_left = p[" << kCl << "]; g.curvature_right = p[" << kCr << "];\n";
  if (m.channels == 1)
    unpack << "  g.border = vec3(p[" << layout.ib(0) << "]); g.inside = vec3(p[" << layout.ii(0) << "]);\n";
  else
    unpack << "  g.border = vec3(p[" << layout.ib(0) << "], p[" << layout.ib(1) << "], p[" << layout.ib(2)
           << "]);\n  g.inside = vec3(p[" << layout.ii(0) << "], p[" << layout.ii(1) << "], p["
           << layout.ii(2) << "]);\n";
  unpack << "  g.inside_falloff = p[" << layout.fi() << "]; g.inside_exponent = p[" << layout.ei()
         << "];\n  g.outside_falloff = p[" << layout.fo() << "]; g.outside_exponent = p[" << layout.eo() << "];";
  std::string functions = kFunctions;
  const std::string marker = "FLARE_UNPACK";
  functions.replace(functions.find(marker), marker.size(), unpack.str());
  out << functions;
  return out.str();
}

}  // namespace flarekit::view
