#include "metrics/capture_metrics.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "common/light_spot.h"
#include "fit/cost.h"
#include "fit/flare_fitter.h"
#include "fit/frames.h"
#include "model/flare_model.h"
#include "model/model_renderer.h"
#include "metrics/light_pattern.h"

namespace flarekit::metrics {

namespace fs = std::filesystem;

bool MetricsOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(core_factor > 0) || !(min_core_radius_px > 0))
    return fail("metrics: core_factor and min_core_radius_px must be > 0");
  if (!(visible_factor > 0)) return fail("metrics: visible_factor must be > 0");
  if (peak_box_px < 1 || peak_box_px % 2 == 0) return fail("metrics: peak_box_px must be odd and ≥ 1");
  if (!(light_dominance > 0 && light_dominance <= 1)) return fail("metrics: light_dominance must be in (0, 1]");
  return true;
}

const FrameFigures* Series::worst() const {
  const FrameFigures* w = nullptr;
  for (const auto& f : frames)
    if (std::isfinite(f.flare_flux_ratio) && (!w || f.flare_flux_ratio > w->flare_flux_ratio)) w = &f;
  if (w) return w;
  for (const auto& f : frames)
    if (std::isfinite(f.ghost_peak_ratio) && (!w || f.ghost_peak_ratio > w->ghost_peak_ratio)) w = &f;
  if (w) return w;
  for (const auto& f : frames)
    if (std::isfinite(f.ghost_flux_ratio) && (!w || f.ghost_flux_ratio > w->ghost_flux_ratio)) w = &f;
  return w;
}

bool isCaptureFolder(const fs::path& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    if (fs::exists(path / "manifest.json", ec)) return true;
    throw InputError(path.string(), "not a capture folder (no manifest.json) and not a model file");
  }
  if (!fs::exists(fs::symlink_status(path, ec)))
    throw InputError(path.string(), "no such file or folder (give a capture folder or a model .json)");
  return false;
}

namespace {

std::string fmt(double v, int precision = 3) {
  std::ostringstream s;
  s.precision(precision);
  s << v;
  return s.str();
}

// What the manifest says beyond fit/frames.h's reading: the light exposures and the trust figures.
struct ManifestExtras {
  std::map<int, fs::path> light_files;  // plan index → light exposure file
  std::vector<double> light_exposures_s;
  double nd_factor = 1;
  std::string cfa = "mono";  // camera.cfa
  double settle_s = kNaN;
  LightStability stability;
  std::string units;
};

ManifestExtras readExtras(const fs::path& folder) {
  ManifestExtras x;
  const ConfigNode root = loadJsonFile(folder / "manifest.json");
  if (auto plan = root.find("plan")) {
    if (auto s = plan->find("settle_s"); s && !s->isNull()) x.settle_s = s->number();
    if (auto t = plan->find("light_exposures_s"); t && t->isArray()) x.light_exposures_s = t->numbers();
    if (auto k = plan->find("light_nd_factor"); k && !k->isNull()) x.nd_factor = k->number();
    if (!(x.nd_factor >= 1) || !std::isfinite(x.nd_factor)) (*plan)["light_nd_factor"].fail("must be ≥ 1");
  }
  if (auto image = root.find("image")) x.units = image->string("units", "");
  if (auto camera = root.find("camera")) {
    x.cfa = camera->string("cfa", "mono");
    const bool known = x.cfa == "mono" || x.cfa == "RGGB" || x.cfa == "BGGR" || x.cfa == "GRBG" || x.cfa == "GBRG";
    if (!known) (*camera)["cfa"].fail("must be \"mono\", \"RGGB\", \"BGGR\", \"GRBG\" or \"GBRG\"");
  }
  const ConfigNode frames = root["frames"];
  for (size_t i = 0; i < frames.size(); ++i) {
    const ConfigNode f = frames[i];
    if (auto l = f.find("light"); l && l->isObject()) {
      const fs::path file = folder / (*l)["file"].string();
      if (!fs::exists(file)) (*l)["file"].fail("light exposure " + file.string() + " is missing");
      x.light_files[static_cast<int>(f["index"].integer())] = file;
    }
  }
  if (auto st = root.find("light_stability"); st && st->isObject()) {
    LightStability& s = x.stability;
    s.recorded = true;
    s.frames = static_cast<int>(st->integer("frames", 0));
    if (auto r = st->find("reference_frame_index"); r && !r->isNull()) s.reference_frame_index = static_cast<int>(r->integer());
    if (auto d = st->find("drift_pct"); d && !d->isNull()) s.drift_pct = d->number();
    if (auto d = st->find("scatter_pct"); d && !d->isNull()) s.scatter_pct = d->number();
    s.warning = st->string("warning", "");
  }
  return x;
}

// A disc mask (CV_8U, 255 inside) of `radius` about `c`; empty image when c is not finite.
cv::Mat discMask(cv::Size size, cv::Point2d c, double radius) {
  cv::Mat m = cv::Mat::zeros(size, CV_8U);
  if (!std::isfinite(c.x) || !std::isfinite(c.y)) return m;
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y - radius)));
  const int y1 = std::min(size.height - 1, static_cast<int>(std::ceil(c.y + radius)));
  const int x0 = std::max(0, static_cast<int>(std::floor(c.x - radius)));
  const int x1 = std::min(size.width - 1, static_cast<int>(std::ceil(c.x + radius)));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x)
      if (std::hypot(x + 0.5 - c.x, y + 0.5 - c.y) <= radius) m.at<uchar>(y, x) = 255;
  return m;
}

// The largest mean over peak_box² boxes wholly inside `valid` (-1 without any).
double boxPeak(const cv::Mat& image, const cv::Mat& valid, int peak_box) {
  cv::Mat box;
  cv::blur(image, box, cv::Size(peak_box, peak_box), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  cv::Mat valid_f, valid_box;
  valid.convertTo(valid_f, CV_32F, 1.0 / 255);
  cv::blur(valid_f, valid_box, cv::Size(peak_box, peak_box), cv::Point(-1, -1), cv::BORDER_CONSTANT);
  double peak = -1;
  for (int y = 0; y < image.rows; ++y) {
    const float* b = box.ptr<float>(y);
    const float* v = valid_box.ptr<float>(y);
    for (int x = 0; x < image.cols; ++x)
      if (v[x] > 0.999f && b[x] > peak) peak = b[x];
  }
  return peak;
}

// A noise-free R,G,B image as a colour sensor's frames show it: sampled through the colour filter
// array `cfa` ("RGGB", "BGGR", "GRBG" or "GBRG": the top-left 2×2 block row by row) and
// demosaiced bilinearly, as acquisition/hdr_merge.h's demosaicBilinear does the frames (metrics/
// does not depend on acquisition/).
cv::Mat throughCfa(const cv::Mat& rgb, const std::string& cfa) {
  auto colour = [&](int row, int col) {
    const char c = cfa[static_cast<size_t>((row & 1) * 2 + (col & 1))];
    return c == 'R' ? 0 : c == 'G' ? 1 : 2;
  };
  const int rows = rgb.rows, cols = rgb.cols;
  cv::Mat mosaic(rows, cols, CV_32F);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) mosaic.at<float>(y, x) = rgb.at<cv::Vec3f>(y, x)[colour(y, x)];
  cv::Mat out(rows, cols, CV_32FC3);
  tbb::parallel_for(0, rows, [&](int y) {
    for (int x = 0; x < cols; ++x) {
      float sum[3] = {0, 0, 0};
      int count[3] = {0, 0, 0};
      const int own = colour(y, x);
      for (int dy = -1; dy <= 1; ++dy) {
        const int yy = y + dy;
        if (yy < 0 || yy >= rows) continue;
        for (int dx = -1; dx <= 1; ++dx) {
          const int xx = x + dx;
          if (xx < 0 || xx >= cols) continue;
          const int c = colour(yy, xx);
          if (c == own && (dx != 0 || dy != 0)) continue;  // a site's own colour: its own value
          sum[c] += mosaic.at<float>(yy, xx);
          ++count[c];
        }
      }
      for (int c = 0; c < 3; ++c) out.at<cv::Vec3f>(y, x)[c] = count[c] ? sum[c] / count[c] : 0.0f;
    }
  });
  return out;
}

// The geometry both the capture's and the truth's figures use.
struct Geometry {
  std::vector<fit::LightImage> lights;  // per stack frame: the light's centre (found: known)
  // How far each centre may be off, pixels: measured on the light exposure, on the merged
  // frame's clipped core, or placed by the optical zero's curve beyond the frame's edge.
  std::vector<double> centre_error_px;
  double core_radius_px = 0;
};

// The figures of one frame image `lum` (luminance) given the light reference; `valid` marks the
// pixels whose value is measured (else a lower bound).
struct FrameInput {
  cv::Mat lum;
  cv::Mat known;  // CV_8U, 255 where lum is a measurement
  // CV_8U, 255 where the capture's merged frame measured the pixel itself (not clipped): where the
  // ghost peak is looked for. The light exposure stands in for clipped pixels only in sums, where
  // its noise averages out; a maximum would pick that noise. The truth takes the capture's.
  cv::Mat direct;
};

void frameFigures(const FrameInput& in, const fit::LightImage& light, double core_radius,
                  const LightReference& ref, const SubpixelPattern& pattern, int peak_box,
                  double light_dominance, double centre_error_px, FrameFigures& out) {
  const cv::Size size = in.lum.size();
  out.light_known = light.found;
  if (light.found) {
    out.light_px = light.center;
    out.light_in_frame = light.center.x >= 0 && light.center.y >= 0 && light.center.x < size.width &&
                         light.center.y < size.height;
  }
  const cv::Mat core = discMask(size, light.found ? light.center : cv::Point2d(kNaN, kNaN), core_radius);
  double flux = 0;
  long long outside = 0, unknown = 0;
  std::array<long long, 3> above{0, 0, 0};
  for (int y = 0; y < size.height; ++y) {
    const float* p = in.lum.ptr<float>(y);
    const uchar* c = core.ptr<uchar>(y);
    const uchar* k = in.known.ptr<uchar>(y);
    for (int x = 0; x < size.width; ++x) {
      if (c[x]) continue;
      ++outside;
      flux += p[x];
      if (!k[x]) ++unknown;
      for (size_t l = 0; l < kShareLevels.size(); ++l)
        if (p[x] >= kShareLevels[l] * ref.peak) ++above[l];
    }
  }
  out.unknown_pixels = unknown;
  if (ref.flux > 0) out.flare_flux_ratio = flux / ref.flux;
  if (ref.peak > 0 && outside > 0)
    for (size_t l = 0; l < kShareLevels.size(); ++l) out.share_above[l] = double(above[l]) / outside;
  // The brightest point outside the light's own image: the light's pattern taken out where it
  // does not outshine what lies under it, the core and unmeasured pixels left out.
  cv::Mat residual = in.lum.clone(), valid = in.known & in.direct;
  valid.setTo(0, core);
  // Where the light's pattern is not far below what remains, what remains may be the pattern's
  // own error: its likeness to this frame's light (∝ the pattern) and the error of the light's
  // centre (the pattern's gradient × that error). Left out, as is where it outshines the rest.
  if (light.found) {
    const cv::Mat p = pattern.at(size, light.center);
    cv::Mat gx, gy, grad;
    cv::Sobel(p, gx, CV_32F, 1, 0, 3, 0.125);
    cv::Sobel(p, gy, CV_32F, 0, 1, 3, 0.125);
    cv::magnitude(gx, gy, grad);
    residual -= p;
    for (int y = 0; y < size.height; ++y) {
      const float* pp = p.ptr<float>(y);
      const float* gg = grad.ptr<float>(y);
      const float* rr = residual.ptr<float>(y);
      uchar* vv = valid.ptr<uchar>(y);
      for (int x = 0; x < size.width; ++x) {
        const double doubt = pp[x] + centre_error_px * gg[x];
        if (doubt > 0 && doubt > light_dominance * rr[x]) vv[x] = 0;
      }
    }
  }
  const double peak = boxPeak(residual, valid, peak_box);
  if (peak > 0 && ref.peak > 0) {
    out.ghost_peak_ratio = peak / ref.peak;
    out.ghost_peak_stops = std::log2(out.ghost_peak_ratio);
  }
}

// The light reference from a light spot.
LightReference referenceFrom(const LightSpot& s, const std::string& method, int index, double angle) {
  LightReference r;
  r.method = method;
  r.frame_index = index;
  r.angle_deg = angle;
  r.flux = s.flux;
  r.peak = s.peak;
  r.lower_bound = s.saturated > 0;
  return r;
}

model::FlareModel loadModelFile(const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(file, ec)) throw InputError(file.string(), "no such model file");
  if (fs::is_directory(file, ec)) throw InputError(file.string(), "is a folder, not a model file");
  return model::FlareModel::load(file);
}

// A model's ghosts at rig angle θ, each rendered alone: (id, image).
std::vector<std::pair<int, cv::Mat>> modelGhosts(const model::FlareModel& m, double angle_deg) {
  std::vector<std::pair<int, cv::Mat>> out;
  for (const auto& g : m.ghostsAt(m.capture.fieldAngle(angle_deg))) {
    const model::GhostParameters p = g.parameters;
    cv::Mat img = model::renderGhosts(std::span<const model::GhostParameters>(&p, 1), m.capture.image_size,
                                      m.channels);
    out.emplace_back(g.id, luminance(img));
  }
  return out;
}

// InputError unless the model is of the capture's image size and some ghost's angle range meets
// the capture's angles [a0, a1] (rig angles).
void checkModelRange(const model::FlareModel& model, const fs::path& model_file, const fs::path& folder,
                     cv::Size size, double a0, double a1) {
  if (model.capture.image_size != size)
    throw InputError(model_file.string(), "the model is of " + std::to_string(model.capture.image_size.width) + "x" +
                                              std::to_string(model.capture.image_size.height) + " images, the capture " +
                                              folder.string() + " of " + std::to_string(size.width) + "x" +
                                              std::to_string(size.height));
  double g0 = kNaN, g1 = kNaN;
  bool overlap = false;
  for (const auto& g : model.ghosts) {
    const double lo = g.angle_min_deg + model.capture.angle_zero_deg, hi = g.angle_max_deg + model.capture.angle_zero_deg;
    g0 = std::isfinite(g0) ? std::min(g0, lo) : lo;
    g1 = std::isfinite(g1) ? std::max(g1, hi) : hi;
    overlap = overlap || (hi >= a0 && lo <= a1);
  }
  if (!overlap)
    throw InputError(model_file.string(),
                     model.ghosts.empty()
                         ? std::string("the model has no ghosts: nothing to measure")
                         : "its ghosts cover rig angles " + fmt(g0) + "° to " + fmt(g1) + "°, outside the capture " +
                               folder.string() + "'s " + fmt(a0) + "° to " + fmt(a1) + "°");
}

}  // namespace

void checkModelForCapture(const fs::path& folder, const fs::path& model_file) {
  if (!isCaptureFolder(folder)) throw InputError(folder.string(), "is not a capture folder (no manifest.json)");
  const model::FlareModel model = loadModelFile(model_file);
  const ConfigNode root = loadJsonFile(folder / "manifest.json");
  checkFormat(root, "flarekit.capture", 1);
  const ConfigNode image = root["image"];
  const cv::Size size(static_cast<int>(image["width"].integer()), static_cast<int>(image["height"].integer()));
  const ConfigNode frames = root["frames"];
  if (frames.size() == 0) frames.fail("lists no frames");
  double a0 = kNaN, a1 = kNaN;
  for (size_t i = 0; i < frames.size(); ++i) {
    const double a = frames[i]["angle_deg"].number();
    a0 = std::isfinite(a0) ? std::min(a0, a) : a;
    a1 = std::isfinite(a1) ? std::max(a1, a) : a;
  }
  checkModelRange(model, model_file, folder, size, a0, a1);
}

namespace {

}  // namespace

Metrics measureCapture(const fs::path& folder, const fs::path& model_file, const MetricsOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (!isCaptureFolder(folder)) throw InputError(folder.string(), "is not a capture folder (no manifest.json)");
  Metrics m;
  m.input = folder;
  m.kind = "capture";
  m.name = fs::path(folder).lexically_normal().filename().string();
  if (m.name.empty() || m.name == ".") m.name = fs::absolute(folder).lexically_normal().parent_path().filename().string();
  std::optional<model::FlareModel> model;
  if (!model_file.empty()) {
    model = loadModelFile(model_file);  // a bad model fails before the capture is read
    m.model_file = model_file;
  }

  fit::FrameStack stack = fit::loadCapture(folder);
  const ManifestExtras extras = readExtras(folder);
  m.lens = stack.info.lens;
  m.f_number = stack.info.f_number;
  m.size = stack.size;
  m.units = extras.units;
  m.flux_radius_px = lightFluxRadiusPx(stack.size);
  const size_t n = stack.frames.size();

  if (model) checkModelRange(*model, model_file, folder, stack.size, stack.frames.front().angle_deg,
                             stack.frames.back().angle_deg);

  // The capture's geometry (the fitter's stages 2–4).
  const fit::FitResult geom = fit::measureCaptureGeometry(stack);
  const fit::FitSummary& gs = geom.summary;
  CaptureTrust& trust = m.trust;
  trust.light = extras.stability;
  trust.settle_s = extras.settle_s;
  trust.horizon_y_px = geom.horizon.y_px;
  trust.symmetry_rms = geom.horizon.symmetry_rms;
  trust.optical_zero_measured = gs.optical_zero.measured;
  trust.angle_zero_deg = gs.optical_zero.angle_zero_deg;
  trust.axis_x_px = gs.optical_zero.axis_x_px;
  trust.light_rms_px = gs.optical_zero.light_rms_px;
  trust.optical_zero_ghosts = gs.optical_zero.ghosts_used;
  trust.light_frames = geom.horizon.lights_found;
  if (!gs.optical_zero.measured)
    trust.warnings.push_back(
        gs.optical_zero.light_coefficients.empty()
            ? "the optical zero could not be measured (the light in fewer than four frames): θ0 = 0 and the image's "
              "middle column are assumed"
            : "θ0 could not be told from the axis's x (no ghost seen in enough frames to follow its centre): θ0 = 0 "
              "is assumed, the axis's x is where the light's curve puts it then");
  if (!trust.light.warning.empty()) trust.warnings.push_back("light: " + trust.light.warning);

  // The light exposures, per stack frame.
  std::vector<cv::Mat> light_lum(n), light_known(n);
  std::vector<LightSpot> spots(n);
  const bool has_light = !extras.light_files.empty();
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    auto it = extras.light_files.find(stack.frames[i].index);
    if (it == extras.light_files.end()) return;
    cv::Mat image, valid;
    fit::readFrameImage(it->second, "", image, valid);
    if (image.size() != stack.size)
      throw InputError(it->second.string(), "the light exposure's size differs from the frames'");
    light_lum[i] = luminance(image);
    light_known[i] = valid;
    cv::Mat clipped = valid == 0;
    spots[i] = measureLightSpot(light_lum[i], clipped);
  });

  // Where the light is: the light exposure's spot, else the fitter's.
  Geometry g;
  g.lights = geom.horizon.lights;
  g.centre_error_px.assign(n, 1.0);
  for (size_t i = 0; i < n; ++i) {
    const cv::Point2d c = g.lights[i].center;
    if (spots[i].found && !spots[i].cut) {
      g.lights[i] = {true, spots[i].center, spots[i].half_max_radius_px};
      g.centre_error_px[i] = 0.1;
    } else if (spots[i].found) {
      // The frame's edge cuts the light's image; where it cuts the core too, the centroid is
      // pulled in (or is a starburst's spike): the optical zero's curve places it, as the fitter
      // does.
      const LightSpot& s = spots[i];
      const double margin = 2 * s.half_max_radius_px + 1;
      const bool core_cut = s.center.x < margin || s.center.y < margin || s.center.x > stack.size.width - margin ||
                            s.center.y > stack.size.height - margin;
      if (!(core_cut && g.lights[i].found)) g.lights[i] = {true, s.center, s.half_max_radius_px};
      g.centre_error_px[i] = core_cut ? 1.0 : 0.5;
    } else if (g.lights[i].found && c.x >= 0 && c.y >= 0 && c.x < stack.size.width && c.y < stack.size.height) {
      g.centre_error_px[i] = 0.3;
    }
  }

  // The reference frame: the whole light nearest the optical zero; a clipped light exposure
  // (lower bounds) only when none is whole.
  const double zero = gs.optical_zero.angle_zero_deg;
  int ref = -1;
  for (const bool whole : {true, false}) {
    for (size_t i = 0; i < n; ++i)
      if (spots[i].found && !spots[i].cut && (!whole || spots[i].whole()) &&
          (ref < 0 || std::abs(stack.frames[i].angle_deg - zero) < std::abs(stack.frames[ref].angle_deg - zero)))
        ref = static_cast<int>(i);
    if (ref >= 0) break;
  }
  if (ref >= 0) {
    const bool nd = extras.nd_factor != 1;
    m.light = referenceFrom(spots[ref], nd ? "light exposure through ND" : "light exposure", stack.frames[ref].index,
                            stack.frames[ref].angle_deg);
    m.light.exposures_s = extras.light_exposures_s;
    m.light.nd_factor = extras.nd_factor;
    std::string times;
    for (double t : extras.light_exposures_s) times += (times.empty() ? "" : " + ") + fmt(t);
    m.light.description = std::string(extras.light_exposures_s.size() > 1 ? "light exposures of " : "light exposure of ") +
                          times + " s" +
                          (nd ? " through a declared ND ×" + fmt(extras.nd_factor) : std::string()) +
                          " at θ = " + fmt(m.light.angle_deg) + "° (frame " + std::to_string(m.light.frame_index) + ")" +
                          (m.light.lower_bound ? ", clipped in " + std::to_string(spots[ref].saturated) +
                                                     " pixels: flux and peak are lower bounds, the figures upper bounds"
                                               : std::string());
    m.core_radius_px = std::max(options.min_core_radius_px, options.core_factor * spots[ref].half_max_radius_px);
  } else {
    // No light exposure holds the whole light: the merged frame's light, clipped.
    int best = -1;
    for (size_t i = 0; i < n; ++i) {
      if (!g.lights[i].found) continue;
      const LightSpot s = measureLightSpot(luminance(stack.frames[i].image), stack.frames[i].valid == 0);
      if (!s.found || s.cut) continue;
      if (best < 0 || std::abs(stack.frames[i].angle_deg - zero) < std::abs(stack.frames[best].angle_deg - zero))
        best = static_cast<int>(i);
    }
    if (best >= 0) {
      const LightSpot s = measureLightSpot(luminance(stack.frames[best].image), stack.frames[best].valid == 0);
      m.light = referenceFrom(s, "merged frame (clipped: lower bound)", stack.frames[best].index,
                              stack.frames[best].angle_deg);
      m.light.lower_bound = m.light.lower_bound || s.saturated > 0;
      m.light.description = "the merged frame at θ = " + fmt(m.light.angle_deg) + "° (frame " +
                            std::to_string(m.light.frame_index) + "), " +
                            (s.saturated > 0 ? "its core clipped (" + std::to_string(s.saturated) +
                                                   " pixels): flux and peak are lower bounds, the figures upper bounds"
                                             : std::string("not clipped"));
    }
    m.notes.push_back(has_light ? "no light exposure holds the whole, unclipped light: the light is measured on the "
                                  "merged frames (rig key light_exposure_s shorter, or light_nd_factor)"
                                : "the capture has no light exposures (rig key light_exposure_s): the light is measured "
                                  "on the merged frames, whose core clips");
  }
  // Without a light exposure the core is the clipped area about the light (nothing else measures it).
  if (!std::isfinite(m.core_radius_px)) {
    double r = options.min_core_radius_px;
    for (size_t i = 0; i < n; ++i) {
      if (!g.lights[i].found) continue;
      const cv::Mat& v = stack.frames[i].valid;
      for (int y = 0; y < v.rows; ++y)
        for (int x = 0; x < v.cols; ++x)
          if (!v.at<uchar>(y, x)) {
            const double d = std::hypot(x + 0.5 - g.lights[i].center.x, y + 0.5 - g.lights[i].center.y);
            if (d <= m.flux_radius_px) r = std::max(r, d + 1.0);
          }
    }
    m.core_radius_px = r;
  }
  g.core_radius_px = m.core_radius_px;
  if (m.light.method == "none")
    m.notes.push_back("no frame shows the whole light: nothing is relative to it (light-relative figures left out)");

  // The capture's images: the merged frame where measured, the light exposure where the frame clipped.
  std::vector<FrameInput> inputs(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    const fit::Frame& f = stack.frames[i];
    FrameInput& in = inputs[i];
    in.lum = luminance(f.image).clone();
    in.known = f.valid.clone();
    in.direct = f.valid.clone();
    if (!light_lum[i].empty()) {
      const cv::Mat fill = (f.valid == 0) & light_known[i];
      light_lum[i].copyTo(in.lum, fill);
      in.known.setTo(255, fill);
    }
  });
  // The light's pattern on these images, at the lights' centres (those measured).
  auto patternOf = [&](const std::vector<FrameInput>& images) {
    std::vector<const cv::Mat*> lums;
    std::vector<cv::Point2d> centres;
    for (size_t i = 0; i < n; ++i)
      if (g.lights[i].found && g.centre_error_px[i] <= 0.3) {
        lums.push_back(&images[i].lum);
        centres.push_back(g.lights[i].center);
      }
    const fit::LightPatternOptions o = fit::FlareFitterOptions().light_pattern;
    return measurePattern(lums, centres, o.radius_px, o.percentile, o.min_frames);
  };

  // The lights nothing measured, placed by the pattern.
  if (m.light.peak > 0) {
    const SubpixelPattern pattern = patternOf(inputs);
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      if (!g.lights[i].found || g.centre_error_px[i] <= 0.3) return;
      g.lights[i].center = registerLight(pattern, inputs[i].lum, inputs[i].known, g.lights[i].center,
                                         1e-7 * m.light.peak);
      g.centre_error_px[i] = 0.3;
    });
  }

  auto fillSeries = [&](Series& series, const std::vector<FrameInput>& images, const LightReference& reference) {
    const SubpixelPattern pattern = patternOf(images);
    series.frames.resize(n);
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      FrameFigures& f = series.frames[i];
      f.index = stack.frames[i].index;
      f.angle_deg = stack.frames[i].angle_deg;
      frameFigures(images[i], g.lights[i], g.core_radius_px, reference, pattern, options.peak_box_px,
                   options.light_dominance, g.centre_error_px[i], f);
    });
  };

  // Per-frame noise σ (fit-eval's), for what counts as visible.
  std::vector<double> sigma(n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    sigma[i] = fit::estimatePixelNoiseSigma(stack.frames[i].image, stack.frames[i].valid, fit::kNoiseBlockPx);
  });

  m.capture.source = "capture";
  fillSeries(m.capture, inputs, m.light);
  for (size_t i = 0; i < n; ++i) {
    FrameFigures& f = m.capture.frames[i];
    int visible = 0;
    for (const auto& c : geom.candidates)
      if (c.present(static_cast<int>(i))) ++visible;
    f.visible_ghosts = visible;
    if (spots[i].whole() && m.light.flux > 0 && m.light.method.rfind("light exposure", 0) == 0)
      f.light_flux_ratio = spots[i].flux / m.light.flux;
    trust.clipped_outside_core += f.unknown_pixels;
  }
  m.capture.notes.push_back("visible ghosts: those the fitter finds in the frame (fit/ghost_candidates.h)");
  if (trust.clipped_outside_core > 0)
    trust.warnings.push_back(std::to_string(trust.clipped_outside_core) +
                             " clipped pixels outside the light's core that no light exposure measured (over all "
                             "frames): the flux there is a lower bound");

  // The truth: the same figures on the noise-free images, and the ghosts alone.
  const bool colour_sensor = extras.cfa != "mono";
  if (stack.has_truth) {
    std::vector<FrameInput> truth(n);
    std::vector<std::vector<fit::GhostTruth>> ghosts(n);
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      cv::Mat image, valid;
      fit::readFrameImage(stack.frames[i].truth_file, "", image, valid);
      // A colour sensor's frames are its mosaic demosaiced: the truth is seen alike.
      if (colour_sensor && image.channels() == 3) image = throughCfa(image, extras.cfa);
      truth[i].lum = luminance(image).clone();
      truth[i].known = cv::Mat(stack.size, CV_8U, cv::Scalar(255));
      truth[i].direct = stack.frames[i].valid.clone();
      ghosts[i] = fit::readGhostTruth(stack.frames[i].ghosts_file);
    });
    int tref = -1;
    for (size_t i = 0; i < n; ++i)
      if (stack.frames[i].index == m.light.frame_index) tref = static_cast<int>(i);
    if (tref >= 0) {
      const LightSpot s = measureLightSpot(truth[tref].lum);
      m.truth_light = referenceFrom(s, "truth", m.light.frame_index, m.light.angle_deg);
      m.truth_light.description = "the noise-free truth at θ = " + fmt(m.light.angle_deg) + "° (frame " +
                                  std::to_string(m.light.frame_index) + ")";
    }
    m.truth.source = "truth";
    fillSeries(m.truth, truth, m.truth_light);
    for (size_t i = 0; i < n; ++i) {
      FrameFigures& f = m.truth.frames[i];
      cv::Mat sum = cv::Mat::zeros(stack.size, CV_32F);
      int visible = 0;
      for (const auto& gt : ghosts[i]) {
        const cv::Mat lum = luminance(gt.image);
        sum += lum;
        double peak = 0;
        cv::minMaxLoc(lum, nullptr, &peak);
        if (peak > options.visible_factor * sigma[i]) ++visible;
        if (m.truth_light.flux > 0) f.ghost_flux[gt.id] = cv::sum(lum)[0] / m.truth_light.flux;
      }
      f.visible_ghosts = visible;
      if (m.truth_light.flux > 0) f.ghost_flux_ratio = cv::sum(sum)[0] / m.truth_light.flux;
      // The ghosts' own brightest box, where the ghost peak is looked for.
      {
        cv::Mat valid = stack.frames[i].valid.clone();
        valid.setTo(0, discMask(stack.size, g.lights[i].found ? g.lights[i].center : cv::Point2d(kNaN, kNaN),
                                g.core_radius_px));
        const double p = boxPeak(sum, valid, options.peak_box_px);
        if (p > 0 && m.truth_light.peak > 0) f.ghost_layers_peak_stops = std::log2(p / m.truth_light.peak);
      }
      // The light's own flux where the capture measured it whole (a noise-free truth would take a
      // ghost for a light beyond the frame).
      if (spots[i].whole() && m.truth_light.flux > 0) {
        const LightSpot s = measureLightSpot(truth[i].lum);
        if (s.whole()) f.light_flux_ratio = s.flux / m.truth_light.flux;
      }
    }
    if (colour_sensor)
      m.truth.notes.push_back("a " + extras.cfa + " sensor: the truth seen through its colour filter array and the "
                              "frames' bilinear demosaic, as the frames are (the ghosts alone: their own layers)");
    m.truth.notes.push_back("the same figures on truth/'s noise-free images, with the capture's geometry; ghost flux "
                            "from the per-ghost truth layers; visible: a true ghost's peak above " +
                            fmt(options.visible_factor) + " × the frame's noise σ");
  } else {
    m.notes.push_back("the capture has no truth/ (not simulated, or captured with --no-truth): the truth figures "
                      "(noise-free flare, ghosts alone, true ghosts visible) are skipped");
  }

  // The model: each ghost's flux, relative to the capture's light.
  if (model) {
    m.model.source = "model";
    m.model.frames.resize(n);
    tbb::parallel_for(size_t{0}, n, [&](size_t i) {
      FrameFigures& f = m.model.frames[i];
      f.index = stack.frames[i].index;
      f.angle_deg = stack.frames[i].angle_deg;
      cv::Mat sum = cv::Mat::zeros(stack.size, CV_32F);
      int visible = 0;
      for (const auto& [id, lum] : modelGhosts(*model, f.angle_deg)) {
        sum += lum;
        double peak = 0;
        cv::minMaxLoc(lum, nullptr, &peak);
        if (peak > options.visible_factor * sigma[i]) ++visible;
        if (m.light.flux > 0) f.ghost_flux[id] = cv::sum(lum)[0] / m.light.flux;
      }
      f.visible_ghosts = visible;
      if (m.light.flux > 0) f.ghost_flux_ratio = cv::sum(sum)[0] / m.light.flux;
      double peak = 0;
      cv::minMaxLoc(sum, nullptr, &peak);
      if (peak > 0 && m.light.peak > 0) {
        f.ghost_peak_ratio = peak / m.light.peak;
        f.ghost_peak_stops = std::log2(f.ghost_peak_ratio);
      }
    });
    m.model.notes.push_back("each ghost of " + model_file.string() + " rendered alone at the frame's angle (field "
                            "angle = rig angle − the model's optical zero " + fmt(model->capture.angle_zero_deg) +
                            "°), relative to the capture's light; visible: peak above " + fmt(options.visible_factor) +
                            " × the frame's noise σ");
  }
  return m;
}

TruthAgreement compareWithTruth(const Metrics& m) {
  TruthAgreement a;
  // A capture normalised by a lower bound (its light clipped) is not compared: its figures are
  // bounds by design, orders of magnitude off.
  if (m.truth.empty() || m.capture.frames.size() != m.truth.frames.size() || m.light.lower_bound) return a;
  if (m.light.flux > 0 && m.truth_light.flux > 0) a.light_flux_rel = std::abs(m.light.flux / m.truth_light.flux - 1);
  if (m.light.peak > 0 && m.truth_light.peak > 0) a.light_peak_stops = std::abs(std::log2(m.light.peak / m.truth_light.peak));
  std::vector<double> flux, peak;
  double light_max = kNaN;
  for (size_t i = 0; i < m.capture.frames.size(); ++i) {
    const FrameFigures &c = m.capture.frames[i], &t = m.truth.frames[i];
    bool any = false;
    if (std::isfinite(c.flare_flux_ratio) && std::isfinite(t.flare_flux_ratio) && t.flare_flux_ratio > 0) {
      const double d = std::abs(c.flare_flux_ratio / t.flare_flux_ratio - 1);
      if (flux.empty() || d > *std::max_element(flux.begin(), flux.end())) a.worst_flux_angle_deg = c.angle_deg;
      flux.push_back(d);
      any = true;
    }
    if (std::isfinite(c.ghost_peak_stops) && std::isfinite(t.ghost_peak_stops)) {
      const double d = std::abs(c.ghost_peak_stops - t.ghost_peak_stops);
      if (peak.empty() || d > *std::max_element(peak.begin(), peak.end())) a.worst_peak_angle_deg = c.angle_deg;
      peak.push_back(d);
      any = true;
    }
    if (std::isfinite(c.light_flux_ratio) && std::isfinite(t.light_flux_ratio) && t.light_flux_ratio > 0) {
      const double d = std::abs(c.light_flux_ratio / t.light_flux_ratio - 1);
      light_max = std::isfinite(light_max) ? std::max(light_max, d) : d;
    }
    for (size_t l = 0; l < kShareLevels.size(); ++l)
      if (std::isfinite(c.share_above[l]) && std::isfinite(t.share_above[l])) {
        const double d = std::abs(c.share_above[l] - t.share_above[l]);
        a.share_abs_max[l] = std::isfinite(a.share_abs_max[l]) ? std::max(a.share_abs_max[l], d) : d;
      }
    if (any) ++a.frames;
  }
  auto median = [](std::vector<double> v) {
    if (v.empty()) return kNaN;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  if (!flux.empty()) {
    a.flare_flux_rel_max = *std::max_element(flux.begin(), flux.end());
    a.flare_flux_rel_median = median(flux);
  }
  if (!peak.empty()) {
    a.ghost_peak_stops_max = *std::max_element(peak.begin(), peak.end());
    a.ghost_peak_stops_median = median(peak);
  }
  a.light_flux_ratio_rel_max = light_max;
  return a;
}

Metrics measureModel(const fs::path& model_file, const MetricsOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const model::FlareModel model = loadModelFile(model_file);
  if (model.ghosts.empty()) throw InputError(model_file.string(), "the model has no ghosts: nothing to measure");
  Metrics m;
  m.input = model_file;
  m.model_file = model_file;
  m.kind = "model";
  m.name = model_file.stem().string();
  m.lens = model.capture.lens;
  m.f_number = model.capture.f_number;
  m.size = model.capture.image_size;
  m.units = "the model's (its capture's) units";
  double lo = kNaN, hi = kNaN;
  for (const auto& gt : model.ghosts) {
    lo = std::isfinite(lo) ? std::min(lo, gt.angle_min_deg) : gt.angle_min_deg;
    hi = std::isfinite(hi) ? std::max(hi, gt.angle_max_deg) : gt.angle_max_deg;
  }
  const double step = model.capture.angle_step_deg > 0 ? model.capture.angle_step_deg : 0.5;
  const int count = std::min(2001, static_cast<int>(std::floor((hi - lo) / step + 1e-9)) + 1);
  m.model.source = "model";
  m.model.frames.resize(count);
  tbb::parallel_for(0, count, [&](int k) {
    FrameFigures& f = m.model.frames[k];
    f.index = k;
    f.angle_deg = lo + k * step + model.capture.angle_zero_deg;
    cv::Mat sum = cv::Mat::zeros(m.size, CV_32F);
    int present = 0;
    for (const auto& [id, lum] : modelGhosts(model, f.angle_deg)) {
      sum += lum;
      ++present;
      f.ghost_flux[id] = cv::sum(lum)[0];
    }
    f.visible_ghosts = present;
    f.ghost_flux_ratio = kNaN;
  });
  m.model.notes.push_back("a model alone: its ghosts rendered over its angle range; a model file holds no measurement "
                          "of the light, so its figures are not relative to it (give its capture with --model for "
                          "that); ghost fluxes in the model's units; visible ghosts: the ghosts present");
  m.notes.push_back("model input: the light-relative figures and capture trust need the capture (flarekit metrics "
                    "CAPTURE --model " + model_file.string() + ")");
  return m;
}

}  // namespace flarekit::metrics
