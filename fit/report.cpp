#include "fit/report.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/image.h"
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

void writeCeilingSheets(const fs::path& dir, const ModelCeiling& ceiling) {
  fs::create_directories(dir);
  for (const auto& f : ceiling.frames) {
    std::ostringstream name;
    name << "ceiling_" << std::fixed << std::setprecision(2) << f.angle_deg << ".png";
    writeImage8(dir / name.str(), ceilingSheet(f));
  }
}

void writeFitReport(const fs::path& dir, const FitResult& result, const FrameStack& stack,
                    const ReportOptions& options) {
  fs::create_directories(dir);
  const auto names = model::parameterNames(stack.channels);
  nlohmann::json summary;
  const FitSummary& s = result.summary;
  summary["brief"] = s.BriefReport();
  summary["optimizer"] = s.optimizer;
  summary["frames_total"] = s.frames_total;
  summary["frames_fitted"] = s.frames_fitted;
  summary["ghosts"] = s.ghosts;
  summary["detections"] = s.detections;
  summary["detections_rejected"] = s.detections_rejected;
  summary["ghosts_dropped_short"] = s.ghosts_dropped_short;
  summary["seconds_total"] = s.seconds_total;
  summary["seconds_fitting"] = s.seconds_fitting;
  summary["seconds_detecting"] = s.seconds_detecting;
  summary["seconds_modelling"] = s.seconds_modelling;
  summary["evaluations"] = s.evaluations;
  summary["warnings"] = s.warnings;
  nlohmann::json ghosts = nlohmann::json::array();
  for (const auto& t : result.tracks) {
    int flagged = 0, carried = 0;
    for (bool b : t.unexplained) flagged += b;
    for (bool b : t.carried) carried += b;
    ghosts.push_back({{"id", t.id},
                      {"angle_min_deg", t.angles_deg.front()},
                      {"angle_max_deg", t.angles_deg.back()},
                      {"frames", t.angles_deg.size()},
                      {"key_frame_angle_deg", result.frames.empty() ? 0.0 : t.angles_deg.front()},
                      {"ends_low", t.end_low},
                      {"ends_high", t.end_high},
                      {"frames_not_described", flagged},
                      {"frames_carried_through_the_light", carried},
                      {"fraction_not_described", double(flagged) / t.angles_deg.size()}});
    std::ostringstream csv;
    csv << std::setprecision(9) << "angle_deg";
    for (const auto& n : names) csv << "," << n;
    csv << ",residual_rms,peak,not_described,carried\n";
    for (size_t i = 0; i < t.angles_deg.size(); ++i) {
      csv << t.angles_deg[i];
      for (double v : model::toParameterVector(t.fits[i])) csv << "," << v;
      csv << "," << t.residual_rms[i] << "," << t.peak[i] << "," << (t.unexplained[i] ? 1 : 0) << ","
          << (i < t.carried.size() && t.carried[i] ? 1 : 0) << "\n";
    }
    writeTextFileAtomically(dir / ("ghost_" + std::to_string(t.id) + ".csv"), csv.str());
  }
  summary["ghost_tracks"] = ghosts;
  writeJsonFile(dir / "summary.json", summary);
  FrameFits::fromResult(result, stack.size, stack.channels).save(dir / "frame_fits.json");

  if (options.contact_sheets > 0 && !result.frames.empty()) {
    const int n = static_cast<int>(result.frames.size());
    const int count = std::min(options.contact_sheets, n);
    for (int k = 0; k < count; ++k) {
      const int i = count == 1 ? 0 : k * (n - 1) / (count - 1);
      const FrameFit& ff = result.frames[i];
      const Frame& f = stack.frames[ff.frame];
      // The ghosts as this frame's fits drew them, and as the model file has them (polynomials):
      // what users get, and what of it the polynomials lost.
      const cv::Mat fits_image = model::renderGhosts(ff.ghosts, stack.size, stack.channels);
      const cv::Mat model_image = result.model.render(f.angle_deg, 0, stack.size);
      cv::Mat sheet = contactSheet(f.image, fits_image, model_image, ff.noise_sigma);
      std::ostringstream name;
      name << "contact_" << std::fixed << std::setprecision(2) << f.angle_deg << ".png";
      writeImage8(dir / name.str(), sheet);
    }
  }
}

}  // namespace flarekit::fit
