#include "fit/evaluation.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <map>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "common/progress.h"
#include "common/robust_statistics.h"
#include "fit/cost.h"
#include "fit/detail/truth.h"
#include "fit/group_solver.h"
#include "fit/pedestal.h"

namespace flarekit::fit {

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

namespace detail {

// Intensity-weighted centroid, peak and radius of a luminance image placed at `offset` in the
// frame. The radius is √2 × the intensity-weighted RMS distance from the centroid: exactly R for a
// uniform disc of radius R, and, unlike an area above a fraction of the peak, not shrunk to a few
// pixels by a caustic's bright spike on a large ghost, which would shrink its match gate to the
// smallest.
Blob describe(const cv::Mat& lum, cv::Point offset) {
  Blob b;
  double sum = 0, sx = 0, sy = 0, sxx = 0, syy = 0, peak = 0;
  for (int y = 0; y < lum.rows; ++y) {
    const float* p = lum.ptr<float>(y);
    for (int x = 0; x < lum.cols; ++x) {
      const double v = std::max(0.0f, p[x]);
      const double px = x + 0.5, py = y + 0.5;
      sum += v;
      sx += v * px;
      sy += v * py;
      sxx += v * px * px;
      syy += v * py * py;
      peak = std::max(peak, v);
    }
  }
  if (sum <= 0) return b;
  b.present = true;
  b.peak = peak;
  const double cx = sx / sum, cy = sy / sum;
  b.centroid = {offset.x + cx, offset.y + cy};
  b.sigma_x = std::sqrt(std::max(0.0, sxx / sum - cx * cx));
  b.sigma_y = std::sqrt(std::max(0.0, syy / sum - cy * cy));
  b.radius = std::sqrt(2 * (b.sigma_x * b.sigma_x + b.sigma_y * b.sigma_y));
  return b;
}

// The normal σ of `values` about their median, from their MAD (NaN when empty).
double robustSigma(std::vector<float>& v) {
  if (v.empty()) return kNaN;
  return madSigma(v, upperMedian(v));
}

// PSNR of `a` against `reference` over `mask`, the peak being the reference's maximum there.
double psnr(const cv::Mat& a, const cv::Mat& reference, const cv::Mat& mask) {
  if (cv::countNonZero(mask) == 0) return kNaN;
  double peak = 0;
  cv::minMaxLoc(reference, nullptr, &peak, nullptr, nullptr, mask);
  if (!(peak > 0)) return kNaN;
  cv::Mat d;
  cv::subtract(a, reference, d, cv::noArray(), CV_64F);
  cv::multiply(d, d, d);
  const double mse = cv::mean(d, mask)[0];
  if (mse <= 0) return 200;
  return 10 * std::log10(peak * peak / mse);
}


FrameTruth readFrameTruth(const Frame& f, const cv::Mat& frame_lum, int noise_block_px) {
  FrameTruth truth;
  cv::Mat radiance = readExrLayer(f.truth_file, "");
  cv::patchNaNs(radiance, 0);
  const cv::Mat radiance_lum = luminance(radiance);
  cv::Mat noise;
  cv::subtract(frame_lum, radiance_lum, noise, cv::noArray(), CV_32F);
  truth.noise_sigma = noiseFloor(noise, f.valid, noise_block_px);
  truth.pixel_noise_sigma = noiseFloor(noise, f.valid, 1);
  truth.ghosts = readGhostTruth(f.ghosts_file);
  truth.flare = cv::Mat::zeros(frame_lum.size(), CV_32F);
  for (const auto& g : truth.ghosts) truth.flare += luminance(g.image);
  cv::subtract(radiance_lum, truth.flare, truth.light, cv::noArray(), CV_32F);
  return truth;
}

}  // namespace detail

namespace {

using namespace detail;

// One frame's evaluation (evaluateGhosts).
FrameEvaluation evaluateFrame(const Frame& f, const FlareAtAngle& flare, int channels,
                              const FrameStack& stack, const EvaluationOptions& options) {
  const std::vector<model::GhostAtAngle>& ghosts = flare.ghosts;
  const cv::Rect image(0, 0, stack.size.width, stack.size.height);
  FrameEvaluation fe;
  fe.angle_deg = f.angle_deg;
  model::RenderOptions render;
  std::vector<model::GhostParameters> all;
  for (const auto& g : ghosts) all.push_back(g.parameters);
  cv::Mat model_image = model::renderGhosts(all, stack.size, channels, render);
  flare.pedestal.addTo(model_image, stack.size);
  const cv::Mat model_lum = luminance(model_image);
  const cv::Mat frame_lum = luminance(f.image);
  FrameTruth truth;
  if (stack.has_truth) {
    truth = readFrameTruth(f, frame_lum, options.noise_block_px);
    fe.noise_sigma = truth.noise_sigma;
    fe.pixel_noise_sigma = truth.pixel_noise_sigma;
  } else {
    fe.noise_sigma = estimatePixelNoiseSigma(f.image, f.valid);
  }
  // PSNR against the frame over the model's footprint.
  fe.capture_psnr_db = psnr(model_lum, frame_lum, (model_lum > fe.noise_sigma) & (f.valid > 0));
  // Model ghosts, one by one.
  std::vector<Blob> model_blobs;
  std::vector<cv::Mat> model_images;  // each blob's luminance over model_boxes
  std::vector<cv::Rect> model_boxes;
  for (const auto& g : ghosts) {
    const cv::Rect box = model::ghostPixelBounds(g.parameters) & image;
    if (box.empty()) continue;
    std::vector<model::GhostParameters> one = {g.parameters};
    cv::Mat lum = luminance(model::renderGhosts(one, box, channels, render));
    Blob b = describe(lum, box.tl());
    b.id = g.id;
    if (!b.present) continue;
    model_blobs.push_back(b);
    model_images.push_back(lum);
    model_boxes.push_back(box);
  }
  fe.model_ghosts = static_cast<int>(model_blobs.size());
  if (!stack.has_truth) {
    fe.psnr_db = kNaN;
    return fe;
  }
  fe.psnr_db = psnr(model_lum, truth.flare, (truth.flare > fe.noise_sigma) & (f.valid > 0));
  std::vector<Blob> true_blobs;
  std::vector<cv::Mat> true_images;  // each blob's luminance over the frame
  for (const auto& g : truth.ghosts) {
    cv::Mat lum = luminance(g.image);
    Blob b = describe(lum, {0, 0});
    b.id = g.id;
    if (!b.present) continue;
    true_blobs.push_back(b);
    true_images.push_back(lum);
  }
  // Greedy matching by distance within each true ghost's gate.
  struct Pair {
    double d;
    int t, mdl;
  };
  std::vector<Pair> pairs;
  for (size_t t = 0; t < true_blobs.size(); ++t)
    for (size_t k = 0; k < model_blobs.size(); ++k) {
      const double d = cv::norm(true_blobs[t].centroid - model_blobs[k].centroid);
      const double gate = std::max(options.min_match_px, options.match_fraction * true_blobs[t].radius);
      if (d <= gate) pairs.push_back({d, static_cast<int>(t), static_cast<int>(k)});
    }
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.d < b.d; });
  // Visible true ghosts take their matches first, so a faint true ghost beside a visible one
  // does not steal its model ghost.
  std::stable_sort(pairs.begin(), pairs.end(), [&](const Pair& a, const Pair& b) {
    const bool va = true_blobs[a.t].peak > options.visible_factor * fe.noise_sigma;
    const bool vb = true_blobs[b.t].peak > options.visible_factor * fe.noise_sigma;
    return va > vb;
  });
  std::vector<int> true_match(true_blobs.size(), -1), model_match(model_blobs.size(), -1);
  for (const auto& p : pairs) {
    if (true_match[p.t] >= 0 || model_match[p.mdl] >= 0) continue;
    true_match[p.t] = p.mdl;
    model_match[p.mdl] = p.t;
  }
  for (size_t t = 0; t < true_blobs.size(); ++t) {
    if (!(true_blobs[t].peak > options.visible_factor * fe.noise_sigma)) continue;
    ++fe.true_ghosts_visible;
    if (true_match[t] >= 0) {
      ++fe.true_ghosts_found;
      const size_t k = static_cast<size_t>(true_match[t]);
      FrameEvaluation::Matched m;
      m.true_id = true_blobs[t].id;
      m.model_id = model_blobs[k].id;
      m.radius_px = true_blobs[t].radius;
      m.centroid_error_px = cv::norm(true_blobs[t].centroid - model_blobs[k].centroid);
      m.centroid_error_pct = m.radius_px > 0 ? 100 * m.centroid_error_px / m.radius_px : kNaN;
      // Flux: the ghost's luminance summed over the image, as describe() counts it (light ≥ 0).
      const double true_flux = cv::sum(cv::max(true_images[t], 0.0f))[0];
      const double model_flux = cv::sum(cv::max(model_images[k], 0.0f))[0];
      m.flux_error = true_flux > 0 ? std::abs(model_flux - true_flux) / true_flux : kNaN;
      m.psnr_db = psnr(model_lum, truth.flare, (true_images[t] > fe.noise_sigma) & (f.valid > 0));
      fe.matched.push_back(m);
    } else {
      fe.missed_true_ids.push_back(true_blobs[t].id);
      FrameEvaluation::Missed miss;
      miss.id = true_blobs[t].id;
      miss.centroid = true_blobs[t].centroid;
      miss.radius_px = true_blobs[t].radius;
      miss.peak_sigma = fe.noise_sigma > 0 ? true_blobs[t].peak / fe.noise_sigma : kNaN;
      miss.nearest_distance_px = kNaN;
      for (const Blob& b : model_blobs)
        if (const double d = cv::norm(b.centroid - miss.centroid);
            miss.nearest_model_id < 0 || d < miss.nearest_distance_px) {
          miss.nearest_model_id = b.id;
          miss.nearest_distance_px = d;
        }
      fe.missed.push_back(miss);
    }
  }
  const cv::Mat light_region = truth.light > options.light_factor * fe.noise_sigma;
  for (size_t k = 0; k < model_blobs.size(); ++k) {
    if (model_match[k] >= 0) {
      ++fe.model_ghosts_matched;
      continue;
    }
    // Whose light it draws (FrameEvaluation::Unmatched).
    FrameEvaluation::Unmatched u;
    u.model_id = model_blobs[k].id;
    u.peak_sigma = fe.noise_sigma > 0 ? model_blobs[k].peak / fe.noise_sigma : kNaN;
    cv::Mat drawn = cv::max(model_images[k], 0.0f);
    const double total = cv::sum(drawn)[0];
    cv::Mat shared;
    for (size_t t = 0; t < true_blobs.size(); ++t) {
      cv::min(drawn, true_images[t](model_boxes[k]), shared);
      const double part = total > 0 ? cv::sum(cv::max(shared, 0.0f))[0] / total : 0;
      if (part > u.fraction_in_true) {
        u.fraction_in_true = part;
        u.true_id = true_blobs[t].id;
      }
    }
    // On the light's core or starburst (FrameEvaluation::Unmatched::onLight).
    const cv::Point2d c = model_blobs[k].centroid;
    const cv::Point pixel(static_cast<int>(std::floor(c.x)), static_cast<int>(std::floor(c.y)));
    u.centroid_on_light = image.contains(pixel) && light_region.at<uchar>(pixel) > 0;
    cv::Mat on_light = cv::Mat::zeros(drawn.size(), CV_32F);
    drawn.copyTo(on_light, light_region(model_boxes[k]));
    u.fraction_on_light = total > 0 ? cv::sum(on_light)[0] / total : 0;
    if (u.piece()) ++fe.model_ghosts_pieces;
    if (u.onLight()) ++fe.light_ghosts;
    fe.unmatched.push_back(u);
  }
  return fe;
}

}  // namespace

bool EvaluationOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(visible_factor > 0)) return fail("visible_factor must be > 0");
  if (!(match_fraction > 0)) return fail("match_fraction must be > 0");
  if (!(min_match_px > 0)) return fail("min_match_px must be > 0");
  if (!(light_factor > 0)) return fail("light_factor must be > 0");
  if (noise_block_px < 1) return fail("noise_block_px must be ≥ 1");
  return true;
}

double medianOf(std::vector<double> v) {
  v.erase(std::remove_if(v.begin(), v.end(), [](double x) { return !std::isfinite(x); }), v.end());
  if (v.empty()) return kNaN;
  // Selection, not a sort: linear in the number of values.
  const size_t n = v.size(), middle = n / 2;
  std::nth_element(v.begin(), v.begin() + middle, v.end());
  if (n % 2) return v[middle];
  return 0.5 * (*std::max_element(v.begin(), v.begin() + middle) + v[middle]);
}

double noiseFloor(const cv::Mat& noise, const cv::Mat& valid, int block_px) {
  CV_Assert(noise.type() == CV_32FC1 && valid.type() == CV_8UC1 && noise.size() == valid.size());
  CV_Assert(block_px >= 1);
  const int k = block_px;
  std::vector<float> means;
  means.reserve(noise.total() / (k * k));
  for (int y0 = 0; y0 + k <= noise.rows; y0 += k)
    for (int x0 = 0; x0 + k <= noise.cols; x0 += k) {
      double sum = 0;
      bool whole = true;
      for (int y = y0; y < y0 + k && whole; ++y) {
        const float* d = noise.ptr<float>(y);
        const uchar* ok = valid.ptr<uchar>(y);
        for (int x = x0; x < x0 + k; ++x) {
          if (!ok[x] || !std::isfinite(d[x])) {
            whole = false;
            break;
          }
          sum += d[x];
        }
      }
      if (whole) means.push_back(static_cast<float>(sum / (k * k)));
    }
  if (means.empty()) return 0;
  // The mean of k² independent values of σ has σ / k.
  return k * robustSigma(means);
}

namespace {
template <class Field>
double medianOver(const std::vector<FrameEvaluation::Matched>& matched, Field field) {
  std::vector<double> values;
  for (const auto& m : matched) values.push_back(m.*field);
  return medianOf(values);
}
}  // namespace

double FrameEvaluation::medianCentroidErrorPx() const {
  return medianOver(matched, &Matched::centroid_error_px);
}
double FrameEvaluation::medianCentroidErrorPct() const {
  return medianOver(matched, &Matched::centroid_error_pct);
}
double FrameEvaluation::medianFluxError() const { return medianOver(matched, &Matched::flux_error); }
double FrameEvaluation::medianGhostPsnrDb() const { return medianOver(matched, &Matched::psnr_db); }

Evaluation evaluateGhosts(const GhostsAtAngle& ghosts_at, int channels, const FrameStack& stack,
                          const EvaluationOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("EvaluationOptions: " + error);
  auto evaluated = measureFrames<FrameEvaluation>(stack, "fit-eval", [&](size_t i) -> std::optional<FrameEvaluation> {
    if (options.odd_frames_only && i % 2 == 0) return std::nullopt;
    const auto flare = ghosts_at(stack.frames[i].angle_deg);
    if (!flare) return std::nullopt;
    return evaluateFrame(stack.frames[i], *flare, channels, stack, options);
  });
  Evaluation ev;
  ev.has_truth = stack.has_truth;
  std::vector<double> psnrs, capture_psnrs, errors, errors_pct, flux_errors, ghost_psnrs;
  for (auto& fe : evaluated) {
    if (!fe) continue;
    capture_psnrs.push_back(fe->capture_psnr_db);
    if (stack.has_truth) psnrs.push_back(fe->psnr_db);
    for (const auto& m : fe->matched) {
      errors.push_back(m.centroid_error_px);
      errors_pct.push_back(m.centroid_error_pct);
      flux_errors.push_back(m.flux_error);
      ghost_psnrs.push_back(m.psnr_db);
    }
    ev.true_ghosts_visible += fe->true_ghosts_visible;
    ev.true_ghosts_found += fe->true_ghosts_found;
    ev.model_ghosts += fe->model_ghosts;
    ev.model_ghosts_matched += fe->model_ghosts_matched;
    ev.model_ghosts_pieces += fe->model_ghosts_pieces;
    ev.light_ghosts += fe->light_ghosts;
    ev.frames.push_back(std::move(*fe));
  }
  // Per true ghost, over the frames.
  struct Seen {
    TrueGhostSummary summary;
    std::vector<double> radii, missed_peaks;
    std::map<int, int> frames_by_model_id;  // the frames each model ghost matched it in
  };
  std::map<int, Seen> seen;
  for (const auto& fe : ev.frames) {
    for (const auto& m : fe.matched) {
      Seen& s = seen[m.true_id];
      ++s.summary.frames_visible;
      ++s.summary.frames_found;
      s.radii.push_back(m.radius_px);
      ++s.frames_by_model_id[m.model_id];
    }
    for (const auto& m : fe.missed) {
      Seen& s = seen[m.id];
      if (s.missed_peaks.empty()) s.summary.missed_min_deg = fe.angle_deg;
      s.summary.missed_max_deg = fe.angle_deg;
      ++s.summary.frames_visible;
      s.radii.push_back(m.radius_px);
      s.missed_peaks.push_back(m.peak_sigma);
    }
  }
  for (const auto& fe : ev.frames)
    for (const auto& u : fe.unmatched)
      if (auto it = seen.find(u.true_id); u.piece() && it != seen.end()) ++it->second.summary.unmatched_pieces;
  double continuity_sum = 0;
  for (auto& [id, s] : seen) {
    s.summary.id = id;
    s.summary.median_radius_px = medianOf(s.radii);
    s.summary.missed_median_peak_sigma = medianOf(s.missed_peaks);
    int most = 0;
    for (const auto& [model_id, n] : s.frames_by_model_id)
      if (n > most) {
        most = n;
        s.summary.continuity_model_id = model_id;
      }
    s.summary.continuity = double(most) / s.summary.frames_visible;
    continuity_sum += s.summary.continuity;
    ev.true_ghosts.push_back(s.summary);
  }
  ev.median_psnr_db = medianOf(psnrs);
  ev.median_capture_psnr_db = medianOf(capture_psnrs);
  ev.median_centroid_error_px = medianOf(errors);
  ev.median_centroid_error_pct = medianOf(errors_pct);
  ev.median_flux_error = medianOf(flux_errors);
  ev.median_ghost_psnr_db = medianOf(ghost_psnrs);
  ev.continuity = seen.empty() ? kNaN : continuity_sum / seen.size();
  ev.recall = ev.true_ghosts_visible ? double(ev.true_ghosts_found) / ev.true_ghosts_visible : kNaN;
  ev.precision = ev.model_ghosts ? double(ev.model_ghosts_matched) / ev.model_ghosts : kNaN;
  return ev;
}

Evaluation evaluateModel(const model::FlareModel& m, const FrameStack& stack,
                         const EvaluationOptions& options) {
  return evaluateGhosts(
      [&](double angle_deg) {
        const double field = m.capture.fieldAngle(angle_deg);  // frames are at rig angles
        return std::optional(FlareAtAngle{m.ghostsAt(field), m.pedestalAt(field)});
      },
      m.channels, stack, options);
}

Evaluation evaluateFrameFits(const FrameFits& fits, const FrameStack& stack, const EvaluationOptions& options) {
  return evaluateGhosts(
      [&](double angle_deg) -> std::optional<FlareAtAngle> {
        const FrameFits::FittedFrame* frame = fits.at(angle_deg);
        if (!frame) return std::nullopt;
        return FlareAtAngle{frame->ghosts, frame->pedestal};
      },
      fits.channels, stack, options);
}

namespace {

nlohmann::json missed(const FrameEvaluation& f) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& m : f.missed)
    a.push_back({{"id", m.id},
                 {"centroid_px", {m.centroid.x, m.centroid.y}},
                 {"radius_px", m.radius_px},
                 {"peak_sigma", number(m.peak_sigma)},
                 {"nearest_model_id", m.nearest_model_id},
                 {"nearest_distance_px", number(m.nearest_distance_px)}});
  return a;
}

nlohmann::json matched(const FrameEvaluation& f) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& m : f.matched)
    a.push_back({{"true_id", m.true_id},
                 {"model_id", m.model_id},
                 {"radius_px", m.radius_px},
                 {"centroid_error_px", m.centroid_error_px},
                 {"centroid_error_pct", number(m.centroid_error_pct)},
                 {"flux_error", number(m.flux_error)},
                 {"psnr_db", number(m.psnr_db)}});
  return a;
}

nlohmann::json unmatched(const FrameEvaluation& f) {
  nlohmann::json a = nlohmann::json::array();
  for (const auto& u : f.unmatched)
    a.push_back({{"model_id", u.model_id},
                 {"true_id", u.true_id},
                 {"fraction_in_true", u.fraction_in_true},
                 {"piece", u.piece()},
                 {"fraction_on_light", u.fraction_on_light},
                 {"peak_sigma", u.peak_sigma},
                 {"centroid_on_light", u.centroid_on_light},
                 {"on_light", u.onLight()}});
  return a;
}
}  // namespace

nlohmann::json Evaluation::toJson() const {
  nlohmann::json j;
  j["has_truth"] = has_truth;
  j["frames_evaluated"] = frames.size();
  j["median_psnr_db"] = number(median_psnr_db);
  j["median_capture_psnr_db"] = number(median_capture_psnr_db);
  j["median_centroid_error_px"] = number(median_centroid_error_px);
  j["median_centroid_error_pct"] = number(median_centroid_error_pct);
  j["median_flux_error"] = number(median_flux_error);
  j["median_ghost_psnr_db"] = number(median_ghost_psnr_db);
  j["continuity"] = number(continuity);
  j["recall"] = number(recall);
  j["precision"] = number(precision);
  j["true_ghosts_visible"] = true_ghosts_visible;
  j["true_ghosts_found"] = true_ghosts_found;
  j["model_ghosts"] = model_ghosts;
  j["model_ghosts_matched"] = model_ghosts_matched;
  j["model_ghosts_pieces"] = model_ghosts_pieces;
  j["light_ghosts"] = light_ghosts;
  nlohmann::json fs = nlohmann::json::array();
  for (const auto& f : frames) {
    fs.push_back({{"angle_deg", f.angle_deg},
                  {"noise_sigma", f.noise_sigma},
                  {"pixel_noise_sigma", number(has_truth ? f.pixel_noise_sigma : kNaN)},
                  {"psnr_db", number(f.psnr_db)},
                  {"capture_psnr_db", number(f.capture_psnr_db)},
                  {"true_ghosts_visible", f.true_ghosts_visible},
                  {"true_ghosts_found", f.true_ghosts_found},
                  {"model_ghosts", f.model_ghosts},
                  {"model_ghosts_matched", f.model_ghosts_matched},
                  {"median_centroid_error_px", number(f.medianCentroidErrorPx())},
                  {"median_centroid_error_pct", number(f.medianCentroidErrorPct())},
                  {"median_flux_error", number(f.medianFluxError())},
                  {"median_ghost_psnr_db", number(f.medianGhostPsnrDb())},
                  {"missed_true_ids", f.missed_true_ids},
                  {"matched", matched(f)},
                  {"missed", missed(f)},
                  {"model_ghosts_pieces", f.model_ghosts_pieces},
                  {"unmatched", unmatched(f)},
                  {"light_ghosts", f.light_ghosts},
                  {"ceiling_psnr_db", number(f.ceiling_psnr_db)}});
  }
  j["frames"] = fs;
  j["ceiling"] = ceiling.points.empty() ? nlohmann::json() : nlohmann::json(ceiling.name());
  j["ceiling_frames"] = ceiling_frames;
  j["median_ceiling_gap_db"] = number(median_ceiling_gap_db);
  nlohmann::json ghosts = nlohmann::json::array();
  for (const auto& g : true_ghosts) {
    nlohmann::json e = {{"id", g.id},
                        {"frames_visible", g.frames_visible},
                        {"frames_found", g.frames_found},
                        {"median_radius_px", number(g.median_radius_px)},
                        {"missed_median_peak_sigma", number(g.missed_median_peak_sigma)},
                        {"unmatched_pieces", g.unmatched_pieces},
                        {"continuity", g.continuity},
                        {"continuity_model_id", g.continuity_model_id}};
    e["missed_range_deg"] = g.frames_found < g.frames_visible
                                ? nlohmann::json::array({g.missed_min_deg, g.missed_max_deg})
                                : nlohmann::json(nullptr);
    ghosts.push_back(e);
  }
  j["true_ghosts"] = ghosts;
  return j;
}

std::string Evaluation::BriefReport() const {
  std::ostringstream s;
  s.precision(3);
  s << frames.size() << " frame(s): ";
  if (has_truth)
    s << "median PSNR vs noise-free flare " << median_psnr_db << " dB, median centroid error "
      << median_centroid_error_px << " px (" << median_centroid_error_pct
      << " % of the ghost's radius), median flux error " << 100 * median_flux_error
      << " %, median PSNR over each ghost's support " << median_ghost_psnr_db << " dB, recall "
      << 100 * recall << " % (" << true_ghosts_found << "/" << true_ghosts_visible
      << "), continuity " << continuity << ", precision " << 100 * precision << " % ("
      << model_ghosts_matched << "/" << model_ghosts << "); ";
  s << "median PSNR vs capture " << median_capture_psnr_db << " dB.";
  // The ghosts missed most, up to three.
  std::vector<TrueGhostSummary> missed;
  for (const auto& g : true_ghosts)
    if (g.frames_found < g.frames_visible) missed.push_back(g);
  std::stable_sort(missed.begin(), missed.end(), [](const TrueGhostSummary& a, const TrueGhostSummary& b) {
    return a.frames_visible - a.frames_found > b.frames_visible - b.frames_found;
  });
  if (missed.size() > 3) missed.resize(3);
  for (size_t i = 0; i < missed.size(); ++i) {
    const auto& g = missed[i];
    s << (i == 0 ? " Missed most: ghost " : "; ghost ") << g.id << " in " << g.frames_visible - g.frames_found
      << " of " << g.frames_visible << " frames (" << g.missed_min_deg << "–" << g.missed_max_deg
      << "°, median peak " << g.missed_median_peak_sigma << " σ, radius " << g.median_radius_px << " px)";
  }
  if (!missed.empty()) s << ".";
  // Of the unmatched model ghosts, the pieces of true ghosts, and the ghosts drawn in most pieces.
  if (has_truth && model_ghosts > model_ghosts_matched) {
    s << " Unmatched model ghosts: " << model_ghosts - model_ghosts_matched << "; "
      << model_ghosts_pieces << " of them draw a piece of a true ghost";
    std::vector<TrueGhostSummary> pieces;
    for (const auto& g : true_ghosts)
      if (g.unmatched_pieces > 0) pieces.push_back(g);
    std::stable_sort(pieces.begin(), pieces.end(), [](const TrueGhostSummary& a, const TrueGhostSummary& b) {
      return a.unmatched_pieces > b.unmatched_pieces;
    });
    if (pieces.size() > 3) pieces.resize(3);
    for (size_t i = 0; i < pieces.size(); ++i)
      s << (i == 0 ? " (ghost " : ", ghost ") << pieces[i].id << ": " << pieces[i].unmatched_pieces;
    s << (pieces.empty() ? "." : ").");
    s << " On the light's core or starburst: " << light_ghosts << ".";
  }
  // Against the ceiling: the median loss, and the frames that lost most, up to three.
  if (ceiling_frames > 0) {
    std::vector<const FrameEvaluation*> lost;
    for (const auto& f : frames)
      if (std::isfinite(f.ceiling_psnr_db) && std::isfinite(f.psnr_db)) lost.push_back(&f);
    std::stable_sort(lost.begin(), lost.end(),
                     [](const FrameEvaluation* a, const FrameEvaluation* b) {
                       return a->ceiling_psnr_db - a->psnr_db > b->ceiling_psnr_db - b->psnr_db;
                     });
    if (lost.size() > 3) lost.resize(3);
    s << " Against " << ceiling.name() << " in " << ceiling_frames << " frame(s): median "
      << median_ceiling_gap_db << " dB below it; most at";
    for (size_t i = 0; i < lost.size(); ++i)
      s << (i == 0 ? " " : ", ") << lost[i]->angle_deg << "° (" << lost[i]->psnr_db << " against "
        << lost[i]->ceiling_psnr_db << " dB)";
    s << ".";
  }
  return s.str();
}

void Evaluation::setCeiling(const CeilingCurve& curve) {
  ceiling = curve;
  std::vector<double> gaps;
  for (auto& f : frames) {
    f.ceiling_psnr_db = kNaN;
    for (const auto& c : ceiling.points)
      if (std::abs(c.angle_deg - f.angle_deg) <= kAngleToleranceDeg)
        f.ceiling_psnr_db = c.psnr_db;
    if (std::isfinite(f.ceiling_psnr_db) && std::isfinite(f.psnr_db))
      gaps.push_back(f.ceiling_psnr_db - f.psnr_db);
  }
  ceiling_frames = static_cast<int>(gaps.size());
  median_ceiling_gap_db = medianOf(gaps);
}

}  // namespace flarekit::fit
