#include "metrics/report.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <iomanip>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/image.h"
#include "common/plot.h"

namespace flarekit::metrics {

namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace {

std::string num(double v, int precision = 4) {
  if (!std::isfinite(v)) return "";
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

Json jnum(double v) { return std::isfinite(v) ? Json(v) : Json(); }

// For people: "–" where there is no number.
std::string show(double v, int precision = 4) { return std::isfinite(v) ? num(v, precision) : "–"; }

std::string levelName(size_t l) {
  static const char* names[] = {"1e-3", "1e-4", "1e-5"};
  return names[l];
}

const Series* seriesOf(const Metrics& m, const std::string& source) {
  if (source == "capture") return &m.capture;
  if (source == "truth") return &m.truth;
  return &m.model;
}

Json frameJson(const FrameFigures& f) {
  Json j = {{"index", f.index},
            {"angle_deg", f.angle_deg},
            {"light_known", f.light_known},
            {"light_in_frame", f.light_in_frame},
            {"light_px", f.light_known ? Json{f.light_px.x, f.light_px.y} : Json()},
            {"flare_flux_ratio", jnum(f.flare_flux_ratio)},
            {"ghost_flux_ratio", jnum(f.ghost_flux_ratio)},
            {"ghost_peak_ratio", jnum(f.ghost_peak_ratio)},
            {"ghost_peak_stops", jnum(f.ghost_peak_stops)},
            {"ghost_layers_peak_stops", jnum(f.ghost_layers_peak_stops)},
            {"visible_ghosts", f.visible_ghosts >= 0 ? Json(f.visible_ghosts) : Json()},
            {"light_flux_ratio", jnum(f.light_flux_ratio)}};
  Json shares;
  for (size_t l = 0; l < kShareLevels.size(); ++l) shares[levelName(l)] = jnum(f.share_above[l]);
  j["share_above"] = shares;
  if (!f.ghost_flux.empty()) {
    Json g = Json::object();
    for (const auto& [id, v] : f.ghost_flux) g[std::to_string(id)] = jnum(v);
    j["ghost_flux"] = g;
  }
  if (f.unknown_pixels) j["clipped_unmeasured_pixels"] = f.unknown_pixels;
  return j;
}

Json lightJson(const LightReference& r) {
  return {{"method", r.method},       {"description", r.description}, {"frame_index", r.frame_index},
          {"angle_deg", jnum(r.angle_deg)}, {"flux", jnum(r.flux)},   {"peak", jnum(r.peak)},
          {"exposures_s", r.exposures_s}, {"nd_factor", r.nd_factor}, {"lower_bound", r.lower_bound}};
}

Json worstJson(const Series& s) {
  const FrameFigures* w = s.worst();
  if (!w) return Json();
  return {{"angle_deg", w->angle_deg},
          {"flare_flux_ratio", jnum(w->flare_flux_ratio)},
          {"ghost_flux_ratio", jnum(w->ghost_flux_ratio)},
          {"ghost_peak_stops", jnum(w->ghost_peak_stops)}};
}

// ── Plots ────────────────────────────────────────────────────────────────────────────────────

const cv::Scalar kWhite(255, 255, 255), kInk(60, 60, 60);

void text(cv::Mat& image, const std::string& s, cv::Point at, double scale = 0.45, const cv::Scalar& c = kInk) {
  cv::putText(image, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, c, 1, cv::LINE_AA);
}

// Marker of a series style at p.
void marker(cv::Mat& image, const std::string& source, cv::Point p, const cv::Scalar& c) {
  if (source == "capture") {
    cv::circle(image, p, 3, c, cv::FILLED, cv::LINE_AA);
  } else if (source == "truth") {
    cv::rectangle(image, p - cv::Point(3, 3), p + cv::Point(3, 3), c, 1);
  } else {
    cv::line(image, p - cv::Point(3, 3), p + cv::Point(3, 3), c, 1, cv::LINE_AA);
    cv::line(image, p + cv::Point(-3, 3), p + cv::Point(3, -3), c, 1, cv::LINE_AA);
  }
}

int thickness(const std::string& source) { return source == "capture" ? 2 : 1; }

// A figure of a frame, already on the panel's y scale (log10 for log panels); NaN: none.
using Value = std::function<double(const FrameFigures&)>;

struct Curve {
  std::string source;
  int input = 0;
  bool faint = false;  // drawn paler: a second figure on the same axes
  std::vector<std::pair<double, double>> points;  // (θ, y), NaN y breaks the line
};

std::vector<Curve> curves(const std::vector<Metrics>& inputs, const Value& value,
                          const std::vector<std::string>& sources) {
  std::vector<Curve> out;
  for (size_t k = 0; k < inputs.size(); ++k)
    for (const auto& source : sources) {
      const Series* s = seriesOf(inputs[k], source);
      Curve c{source, static_cast<int>(k), false, {}};
      bool any = false;
      for (const auto& f : s->frames) {
        const double y = value(f);
        c.points.emplace_back(f.angle_deg, y);
        any = any || std::isfinite(y);
      }
      if (any) out.push_back(std::move(c));
    }
  return out;
}

struct Range {
  double x0 = kNaN, x1 = kNaN, y0 = kNaN, y1 = kNaN;
  void add(double x, double y) {
    if (!std::isfinite(y)) return;
    x0 = std::isfinite(x0) ? std::min(x0, x) : x;
    x1 = std::isfinite(x1) ? std::max(x1, x) : x;
    y0 = std::isfinite(y0) ? std::min(y0, y) : y;
    y1 = std::isfinite(y1) ? std::max(y1, y) : y;
  }
};

void xRangeOf(const std::vector<Metrics>& inputs, Range& r) {
  for (const auto& m : inputs)
    for (const Series* s : {&m.capture, &m.truth, &m.model})
      for (const auto& f : s->frames) {
        r.x0 = std::isfinite(r.x0) ? std::min(r.x0, f.angle_deg) : f.angle_deg;
        r.x1 = std::isfinite(r.x1) ? std::max(r.x1, f.angle_deg) : f.angle_deg;
      }
}

void drawCurves(cv::Mat& image, const PlotPanel& panel, const std::vector<Curve>& cs) {
  for (const auto& c : cs) {
    cv::Scalar colour = plotSeriesColour(c.input);
    if (c.faint) colour = 0.45 * colour + 0.55 * cv::Scalar(255, 255, 255);
    std::vector<cv::Point> run;
    auto flush = [&] {
      if (run.size() > 1) cv::polylines(image, run, false, colour, thickness(c.source), cv::LINE_AA);
      run.clear();
    };
    for (const auto& [x, y] : c.points) {
      if (!std::isfinite(y)) {
        flush();
        continue;
      }
      const cv::Point p(panel.px(x), panel.py(std::clamp(y, panel.y0, panel.y1)));
      run.push_back(p);
      marker(image, c.source, p, colour);
    }
    flush();
  }
}

// Each input's worst angle (largest value of its capture curve, else its first curve), ringed and
// named above the panel's title line, right-aligned (inside the panel it would hide points).
void markWorst(cv::Mat& image, const PlotPanel& panel, const std::vector<Curve>& cs,
               const std::vector<Metrics>& inputs, bool largest = true) {
  int right = panel.area.x + panel.area.width;
  for (size_t k = inputs.size(); k-- > 0;) {
    const Curve* best = nullptr;
    for (const auto& c : cs)
      if (c.input == static_cast<int>(k) && (!best || (best->source != "capture" && c.source == "capture"))) best = &c;
    if (!best) continue;
    double bx = kNaN, by = kNaN;
    for (const auto& [x, y] : best->points)
      if (std::isfinite(y) && (!std::isfinite(by) || (largest ? y > by : y < by))) {
        bx = x;
        by = y;
      }
    if (!std::isfinite(by)) continue;
    const cv::Scalar colour = plotSeriesColour(static_cast<int>(k));
    const cv::Point p(panel.px(bx), panel.py(std::clamp(by, panel.y0, panel.y1)));
    cv::circle(image, p, 8, colour, 2, cv::LINE_AA);
    std::ostringstream s;
    s << inputs[k].name << ": worst at " << std::setprecision(3) << bx << " deg";
    int baseline = 0;
    const int width = cv::getTextSize(s.str(), cv::FONT_HERSHEY_SIMPLEX, 0.42, 1, &baseline).width;
    right -= width;
    text(image, s.str(), {right, panel.area.y - 24}, 0.42, colour);
    right -= 18;
  }
}

void legend(cv::Mat& image, const std::vector<Metrics>& inputs, const std::vector<Curve>& cs, int y) {
  int x = 70;
  for (size_t k = 0; k < inputs.size(); ++k) {
    const cv::Scalar colour = plotSeriesColour(static_cast<int>(k));
    cv::line(image, {x, y - 4}, {x + 22, y - 4}, colour, 2, cv::LINE_AA);
    text(image, inputs[k].name, {x + 28, y});
    int baseline = 0;
    x += 28 + cv::getTextSize(inputs[k].name, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &baseline).width + 20;
  }
  std::set<std::string> sources;
  for (const auto& c : cs) sources.insert(c.source);
  for (const std::string s : {"capture", "truth", "model"}) {
    if (!sources.count(s)) continue;
    marker(image, s, {x + 6, y - 4}, kInk);
    text(image, s, {x + 16, y});
    x += 90;
  }
}

struct PlotSpec {
  std::string y_label;
  Value value;
  bool log10 = false;
  std::vector<std::string> sources{"capture", "truth", "model"};
  bool mark_worst = true;
  bool integer = false;
};

// One panel of a plot over θ; false when there is nothing to draw. `extra` (may be null): more
// curves on the same axes, in its sources' styles (the ghosts alone beside the flux outside the
// core).
bool drawPanel(cv::Mat& image, cv::Rect area, const std::vector<Metrics>& inputs, const PlotSpec& spec,
               bool x_labels, std::vector<Curve>* drawn = nullptr, const PlotSpec* extra = nullptr) {
  auto scaled = [&](const PlotSpec& p) -> Value {
    if (!p.log10) return p.value;
    return [f = p.value](const FrameFigures& fr) {
      const double y = f(fr);
      return y > 0 ? std::log10(y) : kNaN;
    };
  };
  std::vector<Curve> cs = curves(inputs, scaled(spec), spec.sources);
  if (cs.empty()) return false;
  std::vector<Curve> more;
  if (extra) more = curves(inputs, scaled(*extra), extra->sources);
  for (auto& c : more) c.faint = true;
  Range r;
  xRangeOf(inputs, r);
  for (const auto* set : {&cs, &more})
    for (const auto& c : *set)
      for (const auto& [x, y] : c.points) r.add(x, y);
  if (!(r.x1 > r.x0)) {
    r.x0 -= 0.5;
    r.x1 += 0.5;
  }
  if (spec.log10) {
    r.y0 = std::floor(r.y0);
    r.y1 = std::max(std::ceil(r.y1), r.y0 + 1);
  } else if (spec.integer) {
    r.y0 = std::min(0.0, r.y0);
    r.y1 = std::max(r.y1 + 1, r.y0 + 1);
  } else {
    const double pad = std::max(0.08 * (r.y1 - r.y0), 1e-6 + 1e-3 * std::abs(r.y1));
    r.y0 -= pad;
    r.y1 += pad;
  }
  const PlotPanel panel{area, r.x0, r.x1, r.y0, r.y1};
  panel.drawAxes(image, spec.y_label, x_labels, spec.log10);
  drawCurves(image, panel, more);
  drawCurves(image, panel, cs);
  if (spec.mark_worst) markWorst(image, panel, cs, inputs);
  if (drawn) {
    drawn->insert(drawn->end(), cs.begin(), cs.end());
    drawn->insert(drawn->end(), more.begin(), more.end());
  }
  return true;
}

cv::Mat singlePlot(const std::vector<Metrics>& inputs, const PlotSpec& spec) {
  cv::Mat image(460, 960, CV_8UC3, kWhite);
  std::vector<Curve> cs;
  if (!drawPanel(image, cv::Rect(70, 40, 860, 340), inputs, spec, true, &cs)) return {};
  text(image, "rig angle, deg", {860, 412});
  legend(image, inputs, cs, 445);
  return image;
}

cv::Mat sharePlot(const std::vector<Metrics>& inputs) {
  cv::Mat image(760, 960, CV_8UC3, kWhite);
  std::vector<Curve> cs;
  bool any = false;
  for (size_t l = 0; l < kShareLevels.size(); ++l) {
    PlotSpec spec;
    spec.y_label = "share of the frame outside the core above " + levelName(l) + " of the light's peak, %";
    spec.value = [l](const FrameFigures& f) { return 100 * f.share_above[l]; };
    spec.mark_worst = l == 0;
    any = drawPanel(image, cv::Rect(70, 40 + static_cast<int>(l) * 225, 860, 180), inputs, spec, l + 1 == kShareLevels.size(), &cs) || any;
  }
  if (!any) return {};
  text(image, "rig angle, deg", {860, 712});
  legend(image, inputs, cs, 745);
  return image;
}

cv::Mat ghostFluxPlot(const std::vector<Metrics>& inputs) {
  std::vector<std::pair<const Metrics*, const Series*>> panels;
  for (const auto& m : inputs) {
    const Series* s = !m.model.empty() ? &m.model : !m.truth.empty() ? &m.truth : nullptr;
    if (!s) continue;
    bool any = false;
    for (const auto& f : s->frames) any = any || !f.ghost_flux.empty();
    if (any) panels.emplace_back(&m, s);
  }
  if (panels.empty()) return {};
  if (panels.size() > 4) panels.resize(4);
  const int h = 250;
  cv::Mat image(60 + h * static_cast<int>(panels.size()), 960, CV_8UC3, kWhite);
  Range xr;
  xRangeOf(inputs, xr);
  if (!(xr.x1 > xr.x0)) {
    xr.x0 -= 0.5;
    xr.x1 += 0.5;
  }
  for (size_t p = 0; p < panels.size(); ++p) {
    const auto& [m, s] = panels[p];
    // The brightest ghosts (by their largest flux over θ): a lens has hundreds, most faint.
    constexpr size_t kShown = 10;
    std::map<int, double> brightest;
    for (const auto& f : s->frames)
      for (const auto& [id, v] : f.ghost_flux) brightest[id] = std::max(brightest[id], v);
    std::vector<std::pair<double, int>> order;
    for (const auto& [id, v] : brightest) order.emplace_back(-v, id);
    std::sort(order.begin(), order.end());
    std::set<int> shown;
    for (size_t k = 0; k < std::min(kShown, order.size()); ++k) shown.insert(order[k].second);
    std::map<int, std::vector<std::pair<double, double>>> by_id;
    double y0 = kNaN, y1 = kNaN;
    for (const auto& f : s->frames)
      for (const auto& [id, v] : f.ghost_flux) {
        if (!shown.count(id)) continue;
        const double y = v > 0 ? std::log10(v) : kNaN;
        by_id[id].emplace_back(f.angle_deg, y);
        if (std::isfinite(y)) {
          y0 = std::isfinite(y0) ? std::min(y0, y) : y;
          y1 = std::isfinite(y1) ? std::max(y1, y) : y;
        }
      }
    if (!std::isfinite(y0)) continue;
    // Up to five decades below the brightest: where a ghost leaves, its flux dives.
    y0 = std::max(std::floor(y0), std::ceil(y1) - 5);
    const PlotPanel panel{cv::Rect(70, 40 + static_cast<int>(p) * h, 860, h - 60), xr.x0, xr.x1, y0,
                          std::max(std::ceil(y1), y0 + 1)};
    const bool relative = m->kind == "capture";
    panel.drawAxes(image,
                   m->name + " (" + s->source + "): each ghost's flux" +
                       (relative ? " / the light's flux" : ", the model's units") +
                       (order.size() > kShown ? " (the " + std::to_string(kShown) + " brightest of " +
                                                    std::to_string(order.size()) + ")"
                                              : std::string()),
                   p + 1 == panels.size(), true);
    int k = 0;
    for (const auto& [id, pts] : by_id) {
      const cv::Scalar colour = plotSeriesColour(k++);
      std::vector<cv::Point> run;
      cv::Point last(-1, -1);
      auto flush = [&] {
        if (run.size() > 1) cv::polylines(image, run, false, colour, 1, cv::LINE_AA);
        run.clear();
      };
      for (const auto& [x, y] : pts) {
        if (!std::isfinite(y) || y < panel.y0) {
          flush();
          continue;
        }
        run.emplace_back(panel.px(x), panel.py(y));
        last = run.back();
      }
      flush();
      if (last.x >= 0) text(image, std::to_string(id), last + cv::Point(3, -3), 0.35, colour);
    }
  }
  text(image, "rig angle, deg", {860, image.rows - 8});
  return image;
}

cv::Mat lightPlot(const std::vector<Metrics>& inputs) {
  PlotSpec spec;
  spec.y_label = "the light's own flux (its light exposure) / the reference frame's";
  spec.value = [](const FrameFigures& f) { return f.light_flux_ratio; };
  spec.mark_worst = false;
  spec.sources = {"capture", "truth"};
  cv::Mat image = singlePlot(inputs, spec);
  if (image.empty()) return image;
  // The stability figures under the legend.
  std::vector<std::pair<std::string, int>> lines;
  for (size_t k = 0; k < inputs.size(); ++k) {
    const LightStability& st = inputs[k].trust.light;
    if (!st.recorded) continue;
    std::ostringstream s;
    s << inputs[k].name << ": the light's drift over the capture "
      << (std::isfinite(st.drift_pct) ? num(st.drift_pct, 3) + " %" : "not measured") << " (light check at frame "
      << st.reference_frame_index << "), scatter from frame to frame "
      << (std::isfinite(st.scatter_pct) ? num(st.scatter_pct, 3) + " %" : "not measured");
    lines.emplace_back(s.str(), static_cast<int>(k));
  }
  cv::Mat taller(image.rows + 20 * static_cast<int>(lines.size()) + 6, image.cols, CV_8UC3, kWhite);
  image.copyTo(taller(cv::Rect(0, 0, image.cols, image.rows)));
  for (size_t k = 0; k < lines.size(); ++k)
    text(taller, lines[k].first, {70, image.rows + 14 + 20 * static_cast<int>(k)}, 0.45, plotSeriesColour(lines[k].second));
  image = taller;
  return image;
}

std::string html(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else if (c == '"') o += "&quot;";
    else o += c;
  }
  return o;
}

std::string metricsHtml(const std::vector<Metrics>& inputs, const std::vector<std::string>& plots) {
  std::ostringstream o;
  o << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>FlareKit metrics</title>\n"
       "<style>body{font-family:sans-serif;max-width:1000px;margin:1em auto;color:#333}"
       "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left;"
       "vertical-align:top}th{background:#f3f3f3}.warn{color:#a40}.note{color:#666;font-size:90%}"
       "img{max-width:100%;border:1px solid #ddd;margin:.5em 0}</style></head><body>\n"
       "<h1>Flare metrics</h1>\n<p class=\"note\">Definitions, the standards they follow and where FlareKit "
       "differs: docs/metrics.md. Flux ratios: the frame's light outside the light's core over the light's flux "
       "(ISO 9358's glare spread function, integrated); peaks in stops (log2) below the light's peak; shares: "
       "pixels outside the core at or above 1e-3, 1e-4, 1e-5 of the light's peak (Imatest's counts).</p>\n";
  for (size_t k = 0; k < inputs.size(); ++k) {
    const Metrics& m = inputs[k];
    o << "<h2>" << html(m.name) << " <span class=\"note\">(" << html(m.kind) << ": " << html(m.input.string())
      << (m.model_file.empty() || m.kind == "model" ? "" : ", model " + html(m.model_file.string())) << ")</span></h2>\n";
    o << "<table>\n<tr><th>lens</th><td>" << html(m.lens) << ", f/" << num(m.f_number, 3) << ", " << m.size.width
      << "×" << m.size.height << " px</td></tr>\n";
    if (m.kind == "capture") {
      o << "<tr><th>the light (normaliser)</th><td>" << html(m.light.description.empty() ? m.light.method : m.light.description)
        << "; flux " << num(m.light.flux) << ", peak " << num(m.light.peak) << " (" << html(m.units) << ")"
        << (m.light.lower_bound ? " <span class=\"warn\">lower bounds</span>" : "") << "</td></tr>\n";
      if (!m.truth.empty())
        o << "<tr><th>the light in the truth</th><td>flux " << num(m.truth_light.flux) << ", peak "
          << num(m.truth_light.peak) << "</td></tr>\n";
      o << "<tr><th>core</th><td>radius " << num(m.core_radius_px, 3) << " px; light flux disc radius "
        << num(m.flux_radius_px, 3) << " px</td></tr>\n";
      const CaptureTrust& t = m.trust;
      o << "<tr><th>light stability</th><td>";
      if (t.light.recorded)
        o << "drift " << (std::isfinite(t.light.drift_pct) ? num(t.light.drift_pct, 3) + " %" : "not measured")
          << " (the light check at frame " << t.light.reference_frame_index << ", measured after it and again after the "
             "last frame), scatter "
          << (std::isfinite(t.light.scatter_pct) ? num(t.light.scatter_pct, 3) + " %" : "not measured") << " over "
          << t.light.frames << " frames"
          << (t.light.warning.empty() ? "" : " <span class=\"warn\">" + html(t.light.warning) + "</span>");
      else
        o << "not recorded (no light exposure)";
      o << "</td></tr>\n<tr><th>optical zero</th><td>"
        << (t.optical_zero_measured
                ? "θ0 = " + num(t.angle_zero_deg, 4) + "°, axis x = " + num(t.axis_x_px, 4) +
                      " px (light's centres within " + num(t.light_rms_px, 3) + " px RMS, " +
                      std::to_string(t.optical_zero_ghosts) + " ghosts)"
                : "<span class=\"warn\">θ0 not measured</span> (0 assumed); axis x = " + show(t.axis_x_px) +
                      " px from the light's curve (" + show(t.light_rms_px, 3) + " px RMS)")
        << "</td></tr>\n<tr><th>horizon</th><td>y = " << num(t.horizon_y_px, 4) << " px (mirror symmetry RMS "
        << num(t.symmetry_rms, 3) << "); the light in " << t.light_frames << " frames</td></tr>\n"
        << "<tr><th>settle</th><td>"
        << (std::isfinite(t.settle_s) ? num(t.settle_s, 3) + " s after each move" : std::string("none recorded"))
        << "</td></tr>\n";
      const TruthAgreement a = compareWithTruth(m);
      if (a.frames > 0)
        o << "<tr><th>capture against truth</th><td>flare flux ratio within " << num(100 * a.flare_flux_rel_max, 3)
          << " % (median " << num(100 * a.flare_flux_rel_median, 3) << " %), ghost peak within "
          << num(a.ghost_peak_stops_max, 3) << " stops (median " << num(a.ghost_peak_stops_median, 3) << "), light flux "
          << num(100 * a.light_flux_rel, 3) << " %, light peak " << num(a.light_peak_stops, 3) << " stops; "
          << a.frames << " frames</td></tr>\n";
    }
    for (const Series* s : {&m.capture, &m.truth, &m.model}) {
      if (s->empty()) continue;
      const FrameFigures* w = s->worst();
      if (w)
        o << "<tr><th>worst angle (" << s->source << ")</th><td>" << show(w->angle_deg) << "°: flux outside the core "
          << show(w->flare_flux_ratio, 3) << ", the ghosts alone " << show(w->ghost_flux_ratio, 3)
          << ", brightest ghost " << show(w->ghost_peak_stops, 3) << " stops</td></tr>\n";
    }
    o << "</table>\n";
    for (const auto& w : m.trust.warnings) o << "<p class=\"warn\">" << html(w) << "</p>\n";
    for (const auto& n : m.notes) o << "<p class=\"note\">" << html(n) << "</p>\n";
    for (const Series* s : {&m.capture, &m.truth, &m.model})
      for (const auto& n : s->notes) o << "<p class=\"note\">" << html(s->source) << ": " << html(n) << "</p>\n";
  }
  o << "<h2>Over the light angle</h2>\n";
  for (const auto& p : plots) o << "<p><img src=\"" << html(p) << "\" alt=\"" << html(p) << "\"></p>\n";
  o << "<p class=\"note\">Numbers: metrics.csv, ghost_flux.csv, metrics.json.</p>\n</body></html>\n";
  return o.str();
}

}  // namespace

Json metricsJson(const std::vector<Metrics>& inputs) {
  Json doc = {{"format", "flarekit.metrics"}, {"version", 1}};
  doc["share_levels"] = {kShareLevels[0], kShareLevels[1], kShareLevels[2]};
  doc["inputs"] = Json::array();
  for (const auto& m : inputs) {
    Json j = {{"name", m.name},
              {"input", m.input.string()},
              {"kind", m.kind},
              {"model", m.model_file.empty() ? Json() : Json(m.model_file.string())},
              {"lens", m.lens},
              {"f_number", m.f_number},
              {"image", {{"width", m.size.width}, {"height", m.size.height}, {"units", m.units}}},
              {"core_radius_px", jnum(m.core_radius_px)},
              {"flux_radius_px", jnum(m.flux_radius_px)},
              {"light", lightJson(m.light)},
              {"notes", m.notes}};
    if (!m.truth.empty()) j["truth_light"] = lightJson(m.truth_light);
    if (m.kind == "capture") {
      const CaptureTrust& t = m.trust;
      j["trust"] = {{"light_stability",
                     t.light.recorded ? Json{{"frames", t.light.frames},
                                             {"reference_frame_index", t.light.reference_frame_index},
                                             {"drift_pct", jnum(t.light.drift_pct)},
                                             {"scatter_pct", jnum(t.light.scatter_pct)},
                                             {"warning", t.light.warning}}
                                      : Json()},
                    {"settle_s", jnum(t.settle_s)},
                    {"horizon_y_px", jnum(t.horizon_y_px)},
                    {"symmetry_rms", jnum(t.symmetry_rms)},
                    {"optical_zero", {{"measured", t.optical_zero_measured},
                                      {"angle_zero_deg", jnum(t.angle_zero_deg)},
                                      {"axis_x_px", jnum(t.axis_x_px)},
                                      {"light_rms_px", jnum(t.light_rms_px)},
                                      {"ghosts_used", t.optical_zero_ghosts}}},
                    {"light_frames", t.light_frames},
                    {"clipped_outside_core", t.clipped_outside_core},
                    {"warnings", t.warnings}};
      const TruthAgreement a = compareWithTruth(m);
      if (a.frames > 0)
        j["truth_agreement"] = {{"frames", a.frames},
                                {"light_flux_rel", jnum(a.light_flux_rel)},
                                {"light_peak_stops", jnum(a.light_peak_stops)},
                                {"flare_flux_rel_max", jnum(a.flare_flux_rel_max)},
                                {"flare_flux_rel_median", jnum(a.flare_flux_rel_median)},
                                {"ghost_peak_stops_max", jnum(a.ghost_peak_stops_max)},
                                {"ghost_peak_stops_median", jnum(a.ghost_peak_stops_median)},
                                {"light_flux_ratio_rel_max", jnum(a.light_flux_ratio_rel_max)},
                                {"share_abs_max", {jnum(a.share_abs_max[0]), jnum(a.share_abs_max[1]), jnum(a.share_abs_max[2])}},
                                {"worst_flux_angle_deg", jnum(a.worst_flux_angle_deg)},
                                {"worst_peak_angle_deg", jnum(a.worst_peak_angle_deg)}};
    }
    Json series = Json::object();
    for (const Series* s : {&m.capture, &m.truth, &m.model}) {
      if (s->empty()) continue;
      Json frames = Json::array();
      for (const auto& f : s->frames) frames.push_back(frameJson(f));
      series[s->source] = {{"notes", s->notes}, {"worst", worstJson(*s)}, {"frames", frames}};
    }
    j["series"] = series;
    doc["inputs"].push_back(j);
  }
  return doc;
}

std::string metricsCsv(const std::vector<Metrics>& inputs) {
  std::ostringstream o;
  o << "input,source,index,angle_deg,light_in_frame,light_x_px,light_y_px,flare_flux_ratio,ghost_flux_ratio,"
       "ghost_peak_ratio,ghost_peak_stops,share_above_1e-3,share_above_1e-4,share_above_1e-5,visible_ghosts,"
       "light_flux_ratio,light_method\n";
  for (const auto& m : inputs)
    for (const Series* s : {&m.capture, &m.truth, &m.model}) {
      const std::string method = s->source == "truth" ? m.truth_light.method : m.kind == "model" ? "none" : m.light.method;
      for (const auto& f : s->frames) {
        o << '"' << m.name << "\"," << s->source << ',' << f.index << ',' << num(f.angle_deg, 8) << ','
          << (f.light_in_frame ? 1 : 0) << ',' << (f.light_known ? num(f.light_px.x, 6) : "") << ','
          << (f.light_known ? num(f.light_px.y, 6) : "") << ',' << num(f.flare_flux_ratio, 6) << ','
          << num(f.ghost_flux_ratio, 6) << ',' << num(f.ghost_peak_ratio, 6) << ',' << num(f.ghost_peak_stops, 5)
          << ',' << num(f.share_above[0], 6) << ',' << num(f.share_above[1], 6) << ',' << num(f.share_above[2], 6)
          << ',' << (f.visible_ghosts >= 0 ? std::to_string(f.visible_ghosts) : "") << ','
          << num(f.light_flux_ratio, 6) << ",\"" << method << "\"\n";
      }
    }
  return o.str();
}

std::string ghostFluxCsv(const std::vector<Metrics>& inputs) {
  std::ostringstream o;
  o << "input,source,angle_deg,ghost_id,flux,relative_to_light\n";
  for (const auto& m : inputs)
    for (const Series* s : {&m.truth, &m.model})
      for (const auto& f : s->frames)
        for (const auto& [id, v] : f.ghost_flux)
          o << '"' << m.name << "\"," << s->source << ',' << num(f.angle_deg, 8) << ',' << id << ',' << num(v, 6)
            << ',' << (m.kind == "capture" ? 1 : 0) << '\n';
  return o.str();
}

std::vector<std::pair<std::string, cv::Mat>> metricsPlots(const std::vector<Metrics>& inputs) {
  std::vector<std::pair<std::string, cv::Mat>> out;
  auto add = [&](const std::string& name, cv::Mat image) {
    if (!image.empty()) out.emplace_back(name, std::move(image));
  };
  {
    // The flux outside the core (capture, truth) and, thinner, the ghosts alone (the truth's
    // layers, the model's ghosts) on the same axes.
    PlotSpec flux;
    flux.y_label = "flux outside the light's core / the light's flux; pale: the ghosts alone (truth layers, model)";
    flux.value = [](const FrameFigures& f) { return f.flare_flux_ratio; };
    flux.log10 = true;
    flux.sources = {"capture", "truth"};
    PlotSpec ghosts = flux;
    ghosts.value = [](const FrameFigures& f) { return f.ghost_flux_ratio; };
    ghosts.sources = {"truth", "model"};
    cv::Mat image(460, 960, CV_8UC3, kWhite);
    std::vector<Curve> cs;
    if (drawPanel(image, cv::Rect(70, 40, 860, 340), inputs, flux, true, &cs, &ghosts)) {
      text(image, "rig angle, deg", {860, 412});
      legend(image, inputs, cs, 445);
      add("flare_flux.png", image);
    } else {
      // No light-relative flux (models alone): the ghosts' flux in their own units.
      PlotSpec g;
      g.y_label = "the ghosts' flux (the model's units)";
      g.value = [](const FrameFigures& f) {
        double s = 0;
        for (const auto& [id, v] : f.ghost_flux) s += v;
        return f.ghost_flux.empty() ? kNaN : s;
      };
      g.log10 = true;
      g.sources = {"model"};
      add("flare_flux.png", singlePlot(inputs, g));
    }
  }
  PlotSpec peak;
  peak.y_label = "the brightest ghost's peak / the light's peak, stops";
  peak.value = [](const FrameFigures& f) { return f.ghost_peak_stops; };
  add("ghost_peak.png", singlePlot(inputs, peak));
  add("share_above.png", sharePlot(inputs));
  PlotSpec visible;
  visible.y_label = "visible ghosts (capture: found by the fitter; truth, model: peak above 10 noise sigma)";
  visible.value = [](const FrameFigures& f) { return f.visible_ghosts >= 0 ? double(f.visible_ghosts) : kNaN; };
  visible.integer = true;
  visible.mark_worst = true;
  add("visible_ghosts.png", singlePlot(inputs, visible));
  add("ghost_flux.png", ghostFluxPlot(inputs));
  add("light.png", lightPlot(inputs));
  return out;
}

std::vector<fs::path> writeMetricsReport(const fs::path& dir, const std::vector<Metrics>& inputs) {
  createFolder(dir);
  std::vector<fs::path> written;
  auto textFile = [&](const std::string& name, const std::string& content) {
    writeTextFileAtomically(dir / name, content);
    written.push_back(dir / name);
  };
  textFile("metrics.csv", metricsCsv(inputs));
  textFile("ghost_flux.csv", ghostFluxCsv(inputs));
  writeJsonFile(dir / "metrics.json", metricsJson(inputs));
  written.push_back(dir / "metrics.json");
  std::vector<std::string> names;
  for (const auto& [name, image] : metricsPlots(inputs)) {
    writeImage8(dir / name, image);
    written.push_back(dir / name);
    names.push_back(name);
  }
  textFile("metrics.html", metricsHtml(inputs, names));
  return written;
}

std::vector<std::string> briefReport(const std::vector<Metrics>& inputs) {
  std::vector<std::string> lines;
  for (const auto& m : inputs) {
    std::ostringstream s;
    s << m.name << ": ";
    if (m.kind == "capture") {
      s << "the light by " << m.light.method;
      const FrameFigures* w = m.capture.worst();
      if (w)
        s << "; worst at " << num(w->angle_deg, 4) << "°: flare flux " << num(w->flare_flux_ratio, 3) << " of the light's, "
          << "brightest ghost " << num(w->ghost_peak_stops, 3) << " stops";
      if (m.trust.light.recorded)
        s << "; light drift " << (std::isfinite(m.trust.light.drift_pct) ? num(m.trust.light.drift_pct, 3) + " %" : "not measured")
          << ", scatter " << (std::isfinite(m.trust.light.scatter_pct) ? num(m.trust.light.scatter_pct, 3) + " %" : "not measured");
      if (m.trust.optical_zero_measured)
        s << "; optical zero " << num(m.trust.angle_zero_deg, 4) << "°, axis x " << num(m.trust.axis_x_px, 4) << " px";
      const TruthAgreement a = compareWithTruth(m);
      if (a.frames > 0)
        s << "; against the truth: flux within " << num(100 * a.flare_flux_rel_max, 3) << " %, ghost peak within "
          << num(a.ghost_peak_stops_max, 3) << " stops";
    } else {
      const FrameFigures* w = m.model.worst();
      s << "model of " << m.model.frames.size() << " angles";
      if (w) s << "; most ghost flux at " << num(w->angle_deg, 4) << "°";
    }
    lines.push_back(s.str());
  }
  return lines;
}

}  // namespace flarekit::metrics
