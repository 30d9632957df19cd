#include "fit/report.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/image.h"
#include "common/plot.h"
#include "fit/frame_fits.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace fs = std::filesystem;

bool ReportOptions::IsValid(std::string* error) const {
  if (contact_sheets < 0) {
    if (error) *error = "contact_sheets must be ≥ 0";
    return false;
  }
  return true;
}

namespace {

// Log scale from lo to hi (decades) onto 0..255.
cv::Mat logView(const cv::Mat& lum, double lo, double hi) {
  cv::Mat l;
  cv::max(lum, lo, l);
  cv::log(l, l);
  l = (l - std::log(lo)) * (255.0 / (std::log(hi) - std::log(lo)));
  cv::Mat u;
  l.convertTo(u, CV_8U);
  cv::Mat bgr;
  cv::cvtColor(u, bgr, cv::COLOR_GRAY2BGR);
  return bgr;
}

// Panels side by side on one logarithmic scale from lo to hi, each labelled, red lines between.
cv::Mat panelSheet(const std::vector<std::pair<const char*, cv::Mat>>& panels, double lo, double hi) {
  std::vector<cv::Mat> views;
  for (const auto& [label, lum] : panels) views.push_back(logView(lum, lo, hi));
  cv::Mat sheet;
  cv::hconcat(views, sheet);
  const int w = panels[0].second.cols;
  for (size_t k = 0; k < panels.size(); ++k) {
    if (k > 0) cv::line(sheet, {int(k) * w, 0}, {int(k) * w, sheet.rows - 1}, cv::Scalar(0, 0, 255));
    cv::putText(sheet, panels[k].first, {int(k) * w + 6, 18}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 255, 255), 1);
  }
  return sheet;
}

double peakOf(const cv::Mat& lum) {
  double peak = 0;
  cv::minMaxLoc(lum, nullptr, &peak);
  return peak;
}

}  // namespace

cv::Mat contactSheet(const cv::Mat& capture, const cv::Mat& fits_image, const cv::Mat& model_image,
                     double noise_sigma) {
  const cv::Mat c = luminance(capture), f = luminance(fits_image), m = luminance(model_image);
  // From a fraction of the noise floor to the brightest ghost (the light itself clips).
  const double lo = std::max(0.3 * noise_sigma, 1e-12);
  const double hi = std::max(2 * std::max(peakOf(m), peakOf(f)), lo * 100);
  return panelSheet({{"capture", c}, {"frame's fits", f}, {"model", m}, {"|capture - model|", cv::abs(c - m)}}, lo, hi);
}

namespace {

// Noise-free flare | ceiling | |flare − ceiling|, scaled as the contact sheets.
cv::Mat ceilingSheet(const CeilingFrame& frame) {
  const double lo = std::max(0.3 * frame.noise_sigma, 1e-12);
  const double hi = std::max(2 * peakOf(frame.flare), lo * 100);
  return panelSheet({{"noise-free flare", frame.flare},
                     {"ceiling", frame.described},
                     {"|flare - ceiling|", cv::abs(frame.flare - frame.described)}},
                    lo, hi);
}

}  // namespace

cv::Mat evaluationPlot(const Evaluation& ev) {
  const cv::Scalar white(255, 255, 255), ink(60, 60, 60), fit_colour(180, 90, 20),
      ceiling_colour(0, 130, 255), visible_colour(185, 185, 185), found_colour(60, 160, 50),
      unmatched_colour(50, 50, 210), pieces_colour(160, 60, 160);
  cv::Mat image(600, 960, CV_8UC3, white);
  if (ev.frames.empty()) return image;
  double a0 = std::numeric_limits<double>::infinity(), a1 = -a0, p0 = a0, p1 = -a0;
  int count_max = 1, unmatched_max = 0;
  auto psnrOf = [&](const FrameEvaluation& f) {
    return ev.has_truth ? f.psnr_db : f.capture_psnr_db;
  };
  for (const auto& f : ev.frames) {
    a0 = std::min(a0, f.angle_deg);
    a1 = std::max(a1, f.angle_deg);
    for (double p : {psnrOf(f), f.ceiling_psnr_db})
      if (std::isfinite(p)) {
        p0 = std::min(p0, p);
        p1 = std::max(p1, p);
      }
    count_max = std::max({count_max, f.true_ghosts_visible, ev.has_truth ? 0 : f.model_ghosts});
    if (ev.has_truth)
      unmatched_max = std::max(unmatched_max, f.model_ghosts - f.model_ghosts_matched);
  }
  if (!(a1 > a0)) {
    a0 -= 0.5;
    a1 += 0.5;
  }
  if (!std::isfinite(p0)) p0 = p1 = 0;
  p0 = std::floor(p0 / 5) * 5;
  p1 = std::max(std::ceil(p1 / 5) * 5, p0 + 5);
  const PlotPanel top{cv::Rect(60, 40, 870, 300), a0, a1, p0, p1};
  const PlotPanel bottom{cv::Rect(60, 380, 870, 180), a0, a1, -double(unmatched_max),
                         double(count_max)};
  top.drawAxes(
      image,
      ev.has_truth ? "PSNR against the noise-free flare, dB" : "PSNR against the capture, dB",
      false);
  bottom.drawAxes(
      image,
      ev.has_truth
          ? "true ghosts visible (grey) and found (green); model ghosts matched to none (red; purple: pieces of a true ghost)"
          : "model ghosts",
      true);
  cv::putText(image, "angle, deg", {bottom.area.x + bottom.area.width - 80, 596},
              cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1, cv::LINE_AA);

  // Bars a little narrower than the frames' spacing.
  const int half =
      std::max(1, static_cast<int>(0.4 * top.area.width / std::max<size_t>(ev.frames.size(), 1)));
  auto bar = [&](double a, double from, double to, const cv::Scalar& colour) {
    if (from == to) return;
    cv::rectangle(image, cv::Point(bottom.px(a) - half, bottom.py(from)),
                  cv::Point(bottom.px(a) + half, bottom.py(to)), colour, cv::FILLED);
  };
  for (const auto& f : ev.frames) {
    if (ev.has_truth) {
      bar(f.angle_deg, 0, f.true_ghosts_visible, visible_colour);
      bar(f.angle_deg, 0, f.true_ghosts_found, found_colour);
      bar(f.angle_deg, 0, -(f.model_ghosts - f.model_ghosts_matched), unmatched_colour);
      bar(f.angle_deg, 0, -f.model_ghosts_pieces, pieces_colour);
    } else {
      bar(f.angle_deg, 0, f.model_ghosts, visible_colour);
    }
  }
  cv::line(image, {bottom.area.x, bottom.py(0)}, {bottom.area.x + bottom.area.width, bottom.py(0)},
           ink);

  // The PSNR curve (broken where a frame has none) and the ceiling's points.
  std::vector<cv::Point> run;
  auto flush = [&] {
    if (run.size() > 1) cv::polylines(image, run, false, fit_colour, 1, cv::LINE_AA);
    run.clear();
  };
  for (const auto& f : ev.frames) {
    const double p = psnrOf(f);
    if (!std::isfinite(p)) {
      flush();
      continue;
    }
    run.emplace_back(top.px(f.angle_deg), top.py(p));
    cv::circle(image, run.back(), 2, fit_colour, cv::FILLED, cv::LINE_AA);
  }
  flush();
  auto ceilingMarker = [&](cv::Point c) {
    cv::rectangle(image, c - cv::Point(4, 4), c + cv::Point(4, 4), ceiling_colour, 2);
  };
  bool has_ceiling = false;
  for (const auto& f : ev.frames)
    if (std::isfinite(f.ceiling_psnr_db)) {
      ceilingMarker({top.px(f.angle_deg), top.py(f.ceiling_psnr_db)});
      has_ceiling = true;
    }
  // The legend, on the panel's title line (inside the panel it would hide points), moved left as
  // far as the ceiling's label needs.
  constexpr int kCeilingEntryPx = 142;  // the ceiling's entry, right of the frames' one
  const std::string ceiling_label = has_ceiling ? ev.ceiling.label() : "";
  const int width =
      has_ceiling
          ? kCeilingEntryPx + cv::getTextSize(ceiling_label, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, nullptr).width
          : 0;
  const cv::Point legend(top.area.x + top.area.width - std::max(400, width + 20), top.area.y - 10);
  cv::line(image, legend, legend + cv::Point(24, 0), fit_colour, 2);
  cv::putText(image, "each frame", legend + cv::Point(30, 4), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink,
              1, cv::LINE_AA);
  if (has_ceiling) {
    const cv::Point c = legend + cv::Point(kCeilingEntryPx, 0);
    ceilingMarker(c);
    cv::putText(image, ceiling_label, c + cv::Point(12, 4), cv::FONT_HERSHEY_SIMPLEX, 0.45, ink, 1,
                cv::LINE_AA);
  }
  return image;
}

void writeCeilingSheets(const fs::path& dir, const ModelCeiling& ceiling) {
  fs::create_directories(dir);
  for (const auto& f : ceiling.frames) {
    std::ostringstream name;
    name << "ceiling_" << std::fixed << std::setprecision(2) << f.angle_deg << ".png";
    writeImage8(dir / name.str(), ceilingSheet(f));
  }
}

cv::Mat sweepRows(const model::FlareModel& m, const SweepImage& sweep, cv::Size size, int channels) {
  cv::Mat rows = cv::Mat::zeros(sweep.rows(), sweep.width(), CV_32F);
  const int band = 3;
  tbb::parallel_for(0, sweep.rows(), [&](int i) {
    const cv::Mat lum = luminance(m.render(m.capture.fieldAngle(sweep.angles_deg[i]), 0, size));
    (void)channels;
    const int centre = static_cast<int>(std::floor(sweep.horizon_y_px));
    for (int x = 0; x < sweep.width(); ++x) {
      double sum = 0;
      int n = 0;
      for (int d = -band; d <= band; ++d)
        if (const int y = centre + d; y >= 0 && y < lum.rows) {
          sum += lum.at<float>(y, x);
          ++n;
        }
      rows.at<float>(i, x) = static_cast<float>(n ? sum / n : 0);
    }
  });
  return rows;
}

cv::Mat sweepPicture(const SweepImage& sweep, const std::vector<BorderTrace>& traces,
                     const std::vector<GhostCandidate>& candidates, const cv::Mat& model_rows) {
  constexpr int kRowPx = 3;  // picture rows per frame
  // One log scale for both panels: from the noise to the brightest ghost (the light clips).
  std::vector<float> values;
  for (int i = 0; i < sweep.rows(); ++i)
    for (int x = 0; x < sweep.width(); x += 2) values.push_back(sweep.radiance.at<float>(i, x));
  std::sort(values.begin(), values.end());
  cv::Scalar noise = cv::mean(sweep.noise);
  const double lo = std::max(0.5 * noise[0], 1e-12);
  const double hi = std::max(values[std::min(values.size() - 1, values.size() * 995 / 1000)] * 2.0, lo * 100);
  auto panel = [&](const cv::Mat& rows) {
    cv::Mat tall;
    cv::resize(rows, tall, cv::Size(rows.cols, rows.rows * kRowPx), 0, 0, cv::INTER_NEAREST);
    return logView(tall, lo, hi);
  };
  cv::Mat left = panel(sweep.radiance);
  const cv::Scalar rising(0, 165, 255), falling(255, 200, 0), peak(80, 220, 80), light(0, 255, 255);
  for (const auto& t : traces) {
    const cv::Scalar colour = t.side == BorderSide::kLeft ? rising : t.side == BorderSide::kRight ? falling : peak;
    for (size_t k = 1; k < t.points.size(); ++k)
      cv::line(left, {int(t.points[k - 1].x_px), t.points[k - 1].row * kRowPx + 1},
               {int(t.points[k].x_px), t.points[k].row * kRowPx + 1}, colour, 1, cv::LINE_AA);
  }
  for (int i = 0; i < sweep.rows(); ++i)
    if (std::isfinite(sweep.light_x_px[i]))
      cv::circle(left, {int(sweep.light_x_px[i]), i * kRowPx + 1}, 1, light, cv::FILLED);
  for (const auto& c : candidates) {
    const int id = c.left_trace >= 0 ? c.left_trace : c.right_trace >= 0 ? c.right_trace : c.peak_trace;
    const BorderTrace& t = traces[id];
    const BorderPoint& p = t.points[t.points.size() / 2];
    cv::putText(left, std::to_string(c.id), {int(p.x_px) + 3, p.row * kRowPx + 4}, cv::FONT_HERSHEY_SIMPLEX,
                0.4, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  }
  cv::putText(left, "capture, traces and ghost ids", {6, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.45, light, 1);
  if (model_rows.empty()) return left;
  cv::Mat right = panel(model_rows);
  cv::putText(right, "model", {6, 14}, cv::FONT_HERSHEY_SIMPLEX, 0.45, light, 1);
  cv::Mat both;
  cv::hconcat(std::vector<cv::Mat>{left, cv::Mat(left.rows, 4, CV_8UC3, cv::Scalar(0, 0, 255)), right}, both);
  return both;
}

void writeFitReport(const fs::path& dir, const FitResult& result, const FrameStack& stack,
                    const ReportOptions& options) {
  fs::create_directories(dir);
  const auto names = model::parameterNames(stack.channels);
  nlohmann::json summary = result.summary.toJson();
  summary["brief"] = result.summary.BriefReport();
  // Each ghost: its borders and range, and its fit in every frame (ghost_<id>.csv).
  nlohmann::json ghosts = nlohmann::json::array();
  for (const auto& c : result.candidates) {
    std::ostringstream csv;
    csv << std::setprecision(9) << "angle_deg";
    for (const auto& n : names) csv << "," << n;
    csv << "\n";
    int frames = 0;
    for (const auto& f : result.frame_fits)
      for (size_t k = 0; k < f.ghost_ids.size(); ++k)
        if (f.ghost_ids[k] == c.id) {
          csv << f.angle_deg;
          for (double v : model::toParameterVector(f.ghosts[k])) csv << "," << v;
          csv << "\n";
          ++frames;
        }
    ghosts.push_back({{"id", c.id},
                      {"left_trace", c.left_trace},
                      {"right_trace", c.right_trace},
                      {"peak_trace", c.peak_trace},
                      {"angle_min_deg", stack.frames[result.frames_used[c.first_row]].angle_deg},
                      {"angle_max_deg", stack.frames[result.frames_used[c.last_row]].angle_deg},
                      {"frames_fitted", frames}});
    writeTextFileAtomically(dir / ("ghost_" + std::to_string(c.id) + ".csv"), csv.str());
  }
  summary["ghosts_found"] = ghosts;
  writeJsonFile(dir / "summary.json", summary);
  FrameFits::fromResult(result, stack.size, stack.channels).save(dir / "frame_fits.json");
  writeImage8(dir / "sweep.png",
              sweepPicture(result.sweep, result.traces, result.candidates,
                           sweepRows(result.model, result.sweep, stack.size, stack.channels)));

  if (options.contact_sheets > 0 && !result.frame_fits.empty()) {
    const int n = static_cast<int>(result.frame_fits.size());
    const int count = std::min(options.contact_sheets, n);
    for (int k = 0; k < count; ++k) {
      const int i = count == 1 ? 0 : k * (n - 1) / (count - 1);
      const FrameFit& ff = result.frame_fits[i];
      const Frame& f = stack.frames[ff.frame];
      // The flare as this frame's fits drew it, and as the model file has it (polynomials): what
      // users get, and what of it the polynomials lost.
      cv::Mat fits_image = model::renderGhosts(ff.ghosts, stack.size, stack.channels);
      ff.pedestal.addTo(fits_image, stack.size);
      const cv::Mat model_image = result.model.render(result.model.capture.fieldAngle(f.angle_deg), 0, stack.size);
      cv::Mat sheet = contactSheet(f.image, fits_image, model_image, ff.noise_sigma);
      std::ostringstream name;
      name << "contact_" << std::fixed << std::setprecision(2) << f.angle_deg << ".png";
      writeImage8(dir / name.str(), sheet);
    }
  }
}

}  // namespace flarekit::fit
