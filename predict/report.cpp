#include "predict/report.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/image.h"

namespace flarekit::predict {
namespace {

std::string escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string fmt(double v, const char* f = "%.4g") {
  if (!std::isfinite(v)) return "–";
  return cv::format(f, v);
}

}  // namespace

cv::Vec3b severityRampColor(double t) {
  static const std::array<cv::Vec3b, 9> stops = {
      cv::Vec3b{0, 0, 4},     cv::Vec3b{31, 12, 72},  cv::Vec3b{85, 15, 109}, cv::Vec3b{136, 34, 106},
      cv::Vec3b{186, 54, 85}, cv::Vec3b{227, 89, 51}, cv::Vec3b{249, 140, 10}, cv::Vec3b{249, 201, 50},
      cv::Vec3b{252, 255, 164}};
  t = std::clamp(std::isfinite(t) ? t : 0.0, 0.0, 1.0) * (stops.size() - 1);
  const size_t i = std::min(static_cast<size_t>(t), stops.size() - 2);
  const double f = t - i;
  cv::Vec3b c;
  for (int k = 0; k < 3; ++k) c[k] = static_cast<uchar>(std::lround(stops[i][k] * (1 - f) + stops[i + 1][k] * f));
  return c;
}

namespace {

cv::Vec3b ramp(double t) { return severityRampColor(t); }

// Names on the map are cut to keep labels on the page (the tooltip has the whole name).
std::string shortName(const std::string& name) {
  if (name.size() <= 16) return name;
  size_t cut = 15;
  while (cut > 0 && (static_cast<unsigned char>(name[cut]) & 0xC0) == 0x80) --cut;  // UTF-8 boundary
  return name.substr(0, cut) + "…";
}

// Characters (UTF-8 code points) of a string.
size_t codePoints(const std::string& s) {
  return static_cast<size_t>(std::count_if(s.begin(), s.end(), [](char c) {
    return (static_cast<unsigned char>(c) & 0xC0) != 0x80;
  }));
}

std::string rgb(const cv::Vec3b& c) { return cv::format("rgb(%d,%d,%d)", c[0], c[1], c[2]); }

std::string pngDataUri(const cv::Mat& linear) {
  const cv::Mat bgr8 = tonemapForDisplay(linear);
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", bgr8, png)) throw RuntimeError("cannot encode a PNG for the report");
  return "data:image/png;base64," + base64(png);
}

// Map position of (θ, φ) in the SVG (y down): the light's place as seen through the camera.
cv::Point2d polar(double cx, double cy, double rho, double roll_deg) {
  const double p = roll_deg * std::numbers::pi / 180.0;
  return {cx - rho * std::cos(p), cy + rho * std::sin(p)};
}

// Colour position of a map value: linear from no flare (0, or the best value when smaller is
// worse) to the map's worst value.
struct MapScale {
  bool larger_worse = true;
  double lo = 0, hi = 0;  // finite value range of the map
  double t(double v) const {
    if (!std::isfinite(v)) return 0;
    if (larger_worse) return hi > 0 ? v / hi : 0;
    return hi > lo ? (hi - v) / (hi - lo) : 0;
  }
  double valueAt(double t) const { return larger_worse ? t * hi : hi - t * (hi - lo); }
};

}  // namespace

std::string base64(const std::vector<unsigned char>& bytes) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (bytes[i] << 16) | (bytes[i + 1] << 8) | bytes[i + 2];
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += table[v & 63];
  }
  if (i + 1 == bytes.size()) {
    const unsigned v = bytes[i] << 16;
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == bytes.size()) {
    const unsigned v = (bytes[i] << 16) | (bytes[i + 1] << 8);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += table[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string polarMapSvg(const SeverityMap& map, const std::vector<LightPrediction>& lights, int width_px) {
  // Room beside the disc for the labels of lights beyond the model's range (drawn on the rim).
  const double w = width_px, legend_h = 86;
  const double radius = 0.5 * w - 130, cx = 0.5 * w, cy = radius + 30;
  const double h = cy + radius + 30 + legend_h;
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" id=\"severity-map\" width=\"" << w << "\" height=\"" << h
    << "\" viewBox=\"0 0 " << w << ' ' << h << "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  o << "<title>Flare severity (" << toString(map.estimator) << ") over light directions</title>\n";
  o << "<circle cx=\"" << cx << "\" cy=\"" << cy << "\" r=\"" << radius << "\" fill=\"#111\"/>\n";
  MapScale scale;
  scale.larger_worse = largerIsWorse(map.estimator);
  scale.lo = std::numeric_limits<double>::infinity();
  scale.hi = -std::numeric_limits<double>::infinity();
  for (const auto& row : map.values)
    for (double v : row)
      if (std::isfinite(v)) {
        scale.lo = std::min(scale.lo, v);
        scale.hi = std::max(scale.hi, v);
      }
  const size_t n_a = map.angles_deg.size(), n_r = map.rolls_deg.size();
  const double da = n_a ? map.max_angle_deg / n_a : 0, dr = n_r ? 360.0 / n_r : 0;
  for (size_t i = 0; i < n_a; ++i) {
    const double r0 = radius * (map.angles_deg[i] - 0.5 * da) / map.max_angle_deg;
    const double r1 = radius * (map.angles_deg[i] + 0.5 * da) / map.max_angle_deg;
    for (size_t j = 0; j < n_r; ++j) {
      const double t = scale.t(map.values[i][j]);
      const double a = map.rolls_deg[j] - 0.5 * dr, b = map.rolls_deg[j] + 0.5 * dr;
      const cv::Point2d p1 = polar(cx, cy, r1, a), p2 = polar(cx, cy, r1, b), p3 = polar(cx, cy, r0, b),
                        p4 = polar(cx, cy, r0, a);
      // Increasing φ turns counter-clockwise on screen: SVG sweep-flag 0 outward, 1 back inside.
      o << cv::format("<path d=\"M%.2f %.2f A%.2f %.2f 0 0 0 %.2f %.2f L%.2f %.2f A%.2f %.2f 0 0 1 %.2f %.2f Z\" ",
                      p1.x, p1.y, r1, r1, p2.x, p2.y, p3.x, p3.y, r0, r0, p4.x, p4.y)
        << "fill=\"" << rgb(ramp(t)) << "\"><title>θ " << fmt(map.angles_deg[i], "%.1f") << "°, φ "
        << fmt(map.rolls_deg[j], "%.0f") << "°: " << fmt(map.values[i][j]) << "</title></path>\n";
    }
  }
  // θ rings and φ spokes.
  const double step = map.max_angle_deg > 40 ? 10 : (map.max_angle_deg > 15 ? 5 : 2);
  for (double a = step; a <= map.max_angle_deg + 1e-9; a += step) {
    const double r = radius * a / map.max_angle_deg;
    o << "<circle cx=\"" << cx << "\" cy=\"" << cy << "\" r=\"" << r
      << "\" fill=\"none\" stroke=\"#888\" stroke-width=\"0.6\" stroke-dasharray=\"3 3\"/>\n";
    o << "<text x=\"" << cx + 3 << "\" y=\"" << cy - r - 2 << "\" fill=\"#ccc\">" << fmt(a, "%.0f") << "°</text>\n";
  }
  for (int k = 0; k < 12; ++k) {
    const double phi = 30.0 * k;
    const cv::Point2d e = polar(cx, cy, radius, phi), l = polar(cx, cy, radius + 16, phi);
    o << cv::format("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#666\" stroke-width=\"0.5\"/>\n",
                    cx, cy, e.x, e.y);
    o << cv::format("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\" dominant-baseline=\"middle\" fill=\"#333\">φ %.0f°</text>\n",
                    l.x, l.y, phi);
  }
  // The scene's lights. Labels are placed one after the other (most severe first); one that would
  // overlap a label already placed moves down a line, and one that would leave the page turns to
  // the other side of its mark. Label sizes are estimated from the font (bold 11 px: ≤ 7 px a
  // character), which is all an SVG writer knows without a renderer.
  std::vector<cv::Rect2d> placed;
  for (const auto& p : lights) {
    if (p.geometry.status == LightStatus::kBehindCamera) continue;
    const bool inside = p.geometry.angle_deg <= map.max_angle_deg;
    const double rho = radius * std::min(p.geometry.angle_deg, map.max_angle_deg * 1.04) / map.max_angle_deg;
    const cv::Point2d q = polar(cx, cy, rho, p.geometry.roll_deg);
    const std::string label = std::to_string(p.rank) + ". " + shortName(p.name);
    const double label_w = 7.0 * static_cast<double>(codePoints(label)), line_h = 13;
    // Inside the disc labels point inwards, on the rim outwards, so they stay on the page.
    bool to_left = (q.x > cx) == inside;
    if (!to_left && q.x + 8 + label_w > w - 2) to_left = true;
    if (to_left && q.x - 8 - label_w < 2) to_left = false;
    const double x = to_left ? q.x - 8 : q.x + 8;
    double y = q.y - 8;
    auto box = [&](double at_y) { return cv::Rect2d(to_left ? x - label_w : x, at_y - 11, label_w, line_h); };
    for (int tries = 0; tries < 6; ++tries) {
      const cv::Rect2d b = box(y);
      if (std::none_of(placed.begin(), placed.end(), [&](const cv::Rect2d& o) { return (o & b).area() > 0; })) break;
      y += line_h;
    }
    placed.push_back(box(y));
    o << cv::format("<g class=\"light-marker\"><circle cx=\"%.1f\" cy=\"%.1f\" r=\"6\" fill=\"%s\" stroke=\"#0cf\" stroke-width=\"2\"/>",
                    q.x, q.y, p.ghost_count > 0 ? "#fff" : "none")
      << cv::format("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"%s\" fill=\"#0cf\" stroke=\"#000\" "
                    "stroke-width=\"3\" paint-order=\"stroke\" font-weight=\"bold\">",
                    x, y, to_left ? "end" : "start")
      << p.rank << ". " << escape(shortName(p.name)) << "<title>" << escape(p.name) << ": θ "
      << fmt(p.geometry.angle_deg, "%.1f") << "°, φ " << fmt(p.geometry.roll_deg, "%.0f") << "°, "
      << toString(p.geometry.status) << "</title></text></g>\n";
  }
  // Legend.
  const double ly = cy + radius + 40, lx = 40, lw = w - 80;
  o << "<defs><linearGradient id=\"severity-ramp\">";
  for (int k = 0; k <= 8; ++k) o << "<stop offset=\"" << k / 8.0 << "\" stop-color=\"" << rgb(ramp(k / 8.0)) << "\"/>";
  o << "</linearGradient></defs>\n";
  o << "<rect x=\"" << lx << "\" y=\"" << ly << "\" width=\"" << lw << "\" height=\"12\" fill=\"url(#severity-ramp)\"/>\n";
  for (int k = 0; k <= 4; ++k)
    o << "<text x=\"" << lx + lw * k / 4.0 << "\" y=\"" << ly + 26 << "\" text-anchor=\"middle\">"
      << fmt(scale.valueAt(k / 4.0), "%.3g") << "</text>\n";
  o << "<text x=\"" << lx << "\" y=\"" << ly + 44 << "\">" << escape(toString(map.estimator))
    << " of one light (B = " << fmt(map.brightness, "%.3g")
    << ") placed at each direction; darkest: least flare</text>\n"
    << "<text x=\"" << lx << "\" y=\"" << ly + 60 << "\">numbered marks: the scene's lights by rank (hollow: no ghosts)</text>\n";
  o << "</svg>\n";
  return o.str();
}

std::string timelineSvg(const std::vector<TimelinePoint>& timeline, Estimator estimator, int width_px) {
  if (timeline.empty()) return "";
  const double w = width_px, h = 220, left = 70, right = 20, top = 20, bottom = 40;
  double t0 = timeline.front().time_s, t1 = timeline.back().time_s, vmax = 0;
  for (const auto& p : timeline) vmax = std::max(vmax, std::isfinite(p.severity) ? p.severity : 0.0);
  if (!(t1 > t0)) t1 = t0 + 1;
  if (!(vmax > 0)) vmax = 1;
  auto x = [&](double t) { return left + (w - left - right) * (t - t0) / (t1 - t0); };
  auto y = [&](double v) { return top + (h - top - bottom) * (1 - (std::isfinite(v) ? v : 0) / vmax); };
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" id=\"severity-timeline\" width=\"" << w << "\" height=\"" << h
    << "\" viewBox=\"0 0 " << w << ' ' << h << "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  o << "<title>Flare severity (" << toString(estimator) << ") along the camera path</title>\n";
  o << cv::format("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#333\"/>", left, h - bottom, w - right, h - bottom);
  o << cv::format("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#333\"/>\n", left, top, left, h - bottom);
  for (int k = 0; k <= 4; ++k) {
    const double v = vmax * k / 4.0;
    o << cv::format("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\" dominant-baseline=\"middle\">%.3g</text>", left - 5, y(v), v);
    const double t = t0 + (t1 - t0) * k / 4.0;
    o << cv::format("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.3g s</text>\n", x(t), h - bottom + 16, t);
  }
  o << "<polyline fill=\"none\" stroke=\"#d4491c\" stroke-width=\"2\" points=\"";
  for (const auto& p : timeline) o << cv::format("%.1f,%.1f ", x(p.time_s), y(p.severity));
  o << "\"/>\n";
  for (const auto& p : timeline)
    o << cv::format("<circle cx=\"%.1f\" cy=\"%.1f\" r=\"3\" fill=\"#d4491c\"><title>t = %.3g s: %.4g (%d lights in range)</title></circle>",
                    x(p.time_s), y(p.severity), p.time_s, p.severity, p.lights_in_range);
  o << cv::format("\n<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">time (s)</text>", 0.5 * (left + w - right), h - 6);
  o << "<text x=\"12\" y=\"" << top + 0.5 * (h - top - bottom) << "\" transform=\"rotate(-90 12 "
    << top + 0.5 * (h - top - bottom) << ")\" text-anchor=\"middle\">" << escape(toString(estimator)) << "</text>\n";
  o << "</svg>\n";
  return o.str();
}

std::string reportHtml(const PredictionSummary& s, const model::FlareModel& m, const Scene& scene,
                       const cv::Mat& composite, const cv::Mat& overlay) {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>Flare prediction: "
    << escape(s.scene_name) << "</title>\n<style>\n"
    << "body{font-family:sans-serif;margin:24px;color:#222;max-width:1400px}h1{font-size:22px}"
       "h2{font-size:17px;margin-top:28px;border-bottom:1px solid #ccc}"
       "table{border-collapse:collapse;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
       "th{background:#f2f2f2}td.l,th.l{text-align:left}.row{display:flex;flex-wrap:wrap;gap:24px;align-items:flex-start}"
       "figure{margin:0}figcaption{font-size:12px;color:#555;max-width:640px}.note{font-size:12px;color:#555;max-width:900px}"
       "tr.none td{color:#888}.warning{background:#fff3cd;border:1px solid #e0b000;padding:6px 10px;max-width:900px}"
       "\n</style></head><body>\n";
  o << "<h1>Flare prediction: " << escape(s.scene_name) << "</h1>\n";
  for (const auto& w : s.warnings) o << "<p class=\"warning\">Warning: " << escape(w) << "</p>\n";
  o << "<p id=\"brief\">" << escape(s.BriefReport()) << "</p>\n";

  // Images: the composite with the lights marked, and the overlay alone.
  const double disp_w = 640, disp_h = disp_w * s.image_size.height / s.image_size.width;
  const double k = disp_w / s.image_size.width;
  o << "<div class=\"row\">\n<figure><svg xmlns=\"http://www.w3.org/2000/svg\" id=\"composite\" width=\"" << disp_w
    << "\" height=\"" << disp_h << "\" viewBox=\"0 0 " << disp_w << ' ' << disp_h << "\">"
    << "<image width=\"" << disp_w << "\" height=\"" << disp_h << "\" href=\"" << pngDataUri(composite) << "\"/>";
  for (const auto& p : s.lights) {
    if (!p.geometry.in_frame) continue;
    o << cv::format("<circle cx=\"%.1f\" cy=\"%.1f\" r=\"9\" fill=\"none\" stroke=\"#0cf\" stroke-width=\"1.5\"/>",
                    p.geometry.image_px.x * k, p.geometry.image_px.y * k)
      << cv::format("<text x=\"%.1f\" y=\"%.1f\" fill=\"#0cf\" font-family=\"sans-serif\" font-size=\"12\">",
                    p.geometry.image_px.x * k + 11, p.geometry.image_px.y * k - 8)
      << escape(p.name) << "</text>";
  }
  o << "</svg><figcaption>Composite: the scene's background with the predicted flare of every light added "
       "(Walch 2018 Eq. 2 brightness). Circles: lights inside the frame.</figcaption></figure>\n";
  o << "<figure><img id=\"overlay\" width=\"" << disp_w << "\" height=\"" << disp_h << "\" alt=\"flare overlay\" src=\""
    << pngDataUri(overlay) << "\"><figcaption>Flare overlay alone (own automatic exposure).</figcaption></figure>\n</div>\n";

  // Ranking.
  o << "<h2>Lights, most severe first</h2>\n<table id=\"lights\"><tr><th>rank</th><th class=\"l\">light</th>"
       "<th class=\"l\">status</th><th>θ (°)</th><th>φ (°)</th><th>in frame</th><th>l·α (lx)</th><th>B</th>"
       "<th>log2 B</th><th>ghosts</th><th>"
    << escape(toString(s.map.estimator))
    << "</th><th>percentile</th><th>max</th><th>contrast ratio</th><th>viewer</th></tr>\n";
  std::vector<const LightPrediction*> ranked;
  for (const auto& p : s.lights) ranked.push_back(&p);
  std::sort(ranked.begin(), ranked.end(), [](auto* a, auto* b) { return a->rank < b->rank; });
  for (const auto* p : ranked) {
    const bool lit = p->illuminance_lux > 0;
    o << "<tr" << (p->ghost_count > 0 ? "" : " class=\"none\"") << "><td>" << p->rank << "</td><td class=\"l\">"
      << escape(p->name) << "</td><td class=\"l\">" << toString(p->geometry.status) << "</td><td>"
      << fmt(p->geometry.angle_deg, "%.1f") << "</td><td>" << fmt(p->geometry.roll_deg, "%.0f") << "</td><td>"
      << (p->geometry.in_frame ? "yes" : "no") << "</td><td>" << fmt(p->illuminance_lux, "%.3g") << "</td><td>"
      << (lit ? fmt(p->brightness.scale, "%.3g") : "0") << "</td><td>"
      << (lit ? fmt(p->brightness.log2_scale, "%+.2f") : "–") << "</td><td>" << p->ghost_count << "</td><td>"
      << fmt(p->severity) << "</td><td>" << fmt(p->severity_percentile, "%.0f") << "</td><td>"
      << fmt(p->estimators.max) << "</td><td>" << fmt(p->estimators.contrast_ratio, "%.3f") << "</td><td>";
    // The real-time viewer beside the report (view/viewer_page.h) at this light's θ and φ.
    if (p->geometry.status == LightStatus::kInRange)
      o << cv::format("<a class=\"view\" href=\"view.html#theta=%.3f&amp;phi=%.2f&amp;ev=0\">open</a>",
                      p->geometry.model_angle_deg, p->geometry.model_roll_deg);
    o << "</td></tr>\n";
  }
  o << "</table>\n<p class=\"note\">θ: angle between the optical axis and the light; φ: roll of the flare about the "
       "image centre (0° = light left of centre, counter-clockwise). B: brightness scale of the paper's Eq. 2 against the "
       "capture; log2 B = (EV100 capture − EV100 scene) + log2(l·α scene / l·α capture). Percentile: where this light's "
    << escape(toString(s.map.estimator))
    << " falls among the same light moved over the model's sampled range (Walch 2018 §3.5).</p>\n";

  // Map and estimators.
  o << "<div class=\"row\"><div><h2>Severity over light directions</h2>\n" << polarMapSvg(s.map, s.lights)
    << "<p class=\"note\">Seen through the camera: the centre is the optical axis, the radius is θ up to the model's "
       "range, and a point's position is where a light there would appear. Ring colour: the "
    << escape(toString(s.map.estimator)) << " of its flare over this scene.</p></div>\n";
  o << "<div><h2>Occurrence estimators of the whole overlay</h2>\n<table id=\"estimators\"><tr><th class=\"l\">estimator"
       "</th><th>value</th><th>percentile</th><th>range min</th><th>median</th><th>range max</th></tr>\n";
  for (const auto& r : s.ratings) {
    std::vector<double> d = r.distribution;
    std::sort(d.begin(), d.end());
    const double lo = d.empty() ? NAN : d.front(), hi = d.empty() ? NAN : d.back(),
                 med = d.empty() ? NAN : d[d.size() / 2];
    o << "<tr><td class=\"l\">" << escape(toString(r.estimator)) << (largerIsWorse(r.estimator) ? "" : " (lower = worse)")
      << "</td><td>" << fmt(r.value) << "</td><td>" << fmt(r.percentile, "%.0f") << "</td><td>" << fmt(lo)
      << "</td><td>" << fmt(med) << "</td><td>" << fmt(hi) << "</td></tr>\n";
  }
  o << "</table>\n<p class=\"note\">Contrast without flare " << fmt(s.estimators.contrast_without_flare, "%.4g")
    << ", with flare " << fmt(s.estimators.contrast_with_flare, "%.4g")
    << ". Distributions: one light as bright as the scene's brightest flaring light swept over the model's sampled "
       "angles at roll 0.</p></div></div>\n";

  if (!s.timeline.empty()) {
    o << "<h2>Severity along the camera path</h2>\n" << timelineSvg(s.timeline, s.map.estimator);
  }

  // Provenance.
  const AngleRange range = sampledRange(m);
  const auto& c = m.capture;
  o << "<h2>Where this came from</h2>\n<table id=\"provenance\">"
    << "<tr><th class=\"l\">model file</th><td class=\"l\">" << escape(s.model_file.string()) << "</td></tr>"
    << "<tr><th class=\"l\">capture</th><td class=\"l\">" << escape(c.camera) << ", " << escape(c.lens)
    << (c.focal_length_mm > 0 ? " (" + fmt(c.focal_length_mm, "%.4g") + " mm)" : std::string()) << ", f/"
    << fmt(c.f_number, "%.3g") << ", ISO " << fmt(c.iso, "%.0f") << ", " << fmt(c.exposure_s, "%.4g") << " s, light "
    << escape(c.light) << ", " << c.image_size.width << " x " << c.image_size.height << " px, pitch "
    << fmt(c.pixel_pitch_um, "%.3g") << " µm, step " << fmt(c.angle_step_deg, "%.3g") << "°; capture light l·α = "
    << fmt(s.capture_illuminance_lux, "%.3g") << " lx ("
    << (s.capture_illuminance_source == "model"    ? "measured on the rig, from the model"
        : s.capture_illuminance_source == "option" ? "prediction option"
                                                   : "ASSUMED: the model does not record it; absolute brightness is uncalibrated")
    << "); flare in "
    << (s.overlay_in_white_units ? "fractions of the scene camera's white level"
                                 : "the capture's units (the model does not record its clip level)")
    << "</td></tr>"
    << "<tr><th class=\"l\">model</th><td class=\"l\">" << m.ghosts.size() << " ghosts, " << m.channels
    << (m.channels == 1 ? " channel" : " channels") << ", sampled θ " << fmt(range.min_deg, "%.1f") << "° to "
    << fmt(range.max_deg, "%.1f") << "°</td></tr>"
    << "<tr><th class=\"l\">scene file</th><td class=\"l\">" << escape(scene.file.string()) << "</td></tr>"
    << "<tr><th class=\"l\">scene camera</th><td class=\"l\">" << fmt(scene.camera.focal_length_mm, "%.3g") << " mm on "
    << fmt(scene.camera.sensor_width_mm, "%.3g") << " x " << fmt(scene.camera.sensor_height_mm, "%.3g") << " mm, f/"
    << fmt(scene.camera.f_number, "%.3g") << ", ISO " << fmt(scene.camera.iso, "%.0f") << ", "
    << fmt(scene.camera.exposure_s, "%.4g") << " s</td></tr>"
    << "<tr><th class=\"l\">background</th><td class=\"l\">"
    << (scene.background.empty() ? "uniform level " + fmt(scene.background_level, "%.3g")
                                 : escape(scene.background_file.string()))
    << "</td></tr>"
    << "<tr><th class=\"l\">image</th><td class=\"l\">" << s.image_size.width << " x " << s.image_size.height
    << " px; " << fmt(s.seconds, "%.2f") << " s</td></tr></table>\n";
  o << "<p class=\"note\">After Walch et al. 2018, Lens flare prediction based on measurements with real-time "
       "visualization, §3.4–3.5. The scene's camera should match the captured lens (the paper fixes the focal length); "
       "l·α of the capture light is an assumption of the prediction options when the model does not record it.</p>\n";
  o << "</body></html>\n";
  return o.str();
}

}  // namespace flarekit::predict
