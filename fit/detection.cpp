#include "fit/detection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "common/image.h"
#include "fit/cost.h"

namespace flarekit::fit {

bool DetectionOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!(smoothing_px > 0)) return fail("smoothing_px must be > 0");
  if (levels_sigma.empty()) return fail("levels_sigma must not be empty");
  for (double l : levels_sigma)
    if (!(l > 0)) return fail("levels_sigma must be > 0");
  if (min_area_px < 1) return fail("min_area_px must be ≥ 1");
  if (!(max_axis_offset > 0)) return fail("max_axis_offset must be > 0");
  if (!(light_zone_sigma > 0)) return fail("light_zone_sigma must be > 0");
  if (!(zone_margin >= 1)) return fail("zone_margin must be ≥ 1");
  if (!(core_margin >= 1)) return fail("core_margin must be ≥ 1");
  if (!(light_smoothing_px >= 0)) return fail("light_smoothing_px must be ≥ 0");
  if (!(light_residue_fraction >= 0)) return fail("light_residue_fraction must be ≥ 0");
  if (max_new_per_frame < 1) return fail("max_new_per_frame must be ≥ 1");
  if (veil_band_px < 0 || veil_window_px < 1) return fail("veil_band_px must be ≥ 0, veil_window_px ≥ 1");
  if (!(veil_step_sigma > 0)) return fail("veil_step_sigma must be > 0");
  if (!(glare_sigma > 0)) return fail("glare_sigma must be > 0");
  return true;
}

namespace {

// The centre of point symmetry of the light's image near `light.center`: the saturated core's
// centroid is off by a fraction of a pixel (clipping is uneven where a ghost or the halo's slope
// crosses the core), and the starburst's fine lines make S(p) = min(R(p), R(2c − p)) leave
// speckle behind unless c is right to a tenth of a pixel. Minimises Σ |R(p) − R(2c − p)| over the
// brightest unsaturated pixels of the zone (where the light rules), coarse to fine.
cv::Point2d refineLightCenter(const cv::Mat& luminance, const cv::Mat& valid, const LightImage& light,
                              const DetectionOptions& options) {
  const double radius = std::max(light.core_radius_px * 3, light.zone_radius_px);
  const cv::Rect zone = cv::Rect(cvFloor(light.center.x - radius), cvFloor(light.center.y - radius),
                                 cvCeil(2 * radius), cvCeil(2 * radius)) &
                        cv::Rect(0, 0, luminance.cols, luminance.rows);
  if (zone.area() < 16) return light.center;
  cv::Mat smooth;
  cv::GaussianBlur(luminance, smooth, cv::Size(0, 0), std::max(0.5, options.light_smoothing_px));
  // The pixels that carry the light: the brightest quarter of the zone's unsaturated ones.
  std::vector<std::pair<float, cv::Point>> pixels;
  for (int y = zone.y; y < zone.y + zone.height; ++y)
    for (int x = zone.x; x < zone.x + zone.width; ++x)
      if (valid.at<uchar>(y, x)) pixels.push_back({smooth.at<float>(y, x), {x, y}});
  if (pixels.size() < 16) return light.center;
  const size_t keep = std::min<size_t>(pixels.size() / 4, 20000);
  std::nth_element(pixels.begin(), pixels.begin() + keep, pixels.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  pixels.resize(keep);
  auto asymmetry = [&](cv::Point2d c) {
    double sum = 0;
    int used = 0;
    for (const auto& [v, p] : pixels) {
      // Bilinear sample at the mirror of the pixel centre (p + ½ → 2c − p − ½).
      const double mx = 2 * c.x - p.x - 1, my = 2 * c.y - p.y - 1;
      const int x0 = cvFloor(mx), y0 = cvFloor(my);
      if (x0 < 0 || y0 < 0 || x0 + 1 >= luminance.cols || y0 + 1 >= luminance.rows) continue;
      if (!valid.at<uchar>(y0, x0) || !valid.at<uchar>(y0 + 1, x0 + 1) ||
          !valid.at<uchar>(y0, x0 + 1) || !valid.at<uchar>(y0 + 1, x0))
        continue;
      const double fx = mx - x0, fy = my - y0;
      const double m = (1 - fy) * ((1 - fx) * smooth.at<float>(y0, x0) + fx * smooth.at<float>(y0, x0 + 1)) +
                       fy * ((1 - fx) * smooth.at<float>(y0 + 1, x0) + fx * smooth.at<float>(y0 + 1, x0 + 1));
      sum += std::abs(v - m);
      ++used;
    }
    return used > 0 ? sum / used : std::numeric_limits<double>::infinity();
  };
  cv::Point2d best = light.center;
  double best_value = asymmetry(best);
  for (double step : {0.5, 0.125}) {
    const cv::Point2d start = best;
    for (int j = -4; j <= 4; ++j)
      for (int i = -4; i <= 4; ++i) {
        const cv::Point2d c = start + cv::Point2d(i * step, j * step);
        const double a = asymmetry(c);
        if (a < best_value) {
          best_value = a;
          best = c;
        }
      }
  }
  return best;
}

}  // namespace

LightImage findLight(const cv::Mat& luminance, const cv::Mat& valid, double noise_sigma,
                     const DetectionOptions& options) {
  LightImage light;
  cv::Mat saturated = valid == 0;
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(saturated, labels, stats, centroids, 8, CV_32S);
  int best = -1, best_area = 0;
  for (int i = 1; i < n; ++i)
    if (stats.at<int>(i, cv::CC_STAT_AREA) > best_area) {
      best_area = stats.at<int>(i, cv::CC_STAT_AREA);
      best = i;
    }
  if (best < 0) return light;  // no clipped core: the light is outside the frame
  light.found = true;
  light.center = {centroids.at<double>(best, 0) + 0.5, centroids.at<double>(best, 1) + 0.5};
  const double core = std::sqrt(best_area / std::numbers::pi);
  light.core_radius_px = core;
  // The zone: where the azimuthal median (robust to ghosts crossing a few directions) falls to
  // the frame's median plus light_zone_sigma noise σ. The halo and starburst are point-symmetric
  // about the light; ghosts are not, so the median follows the former.
  std::vector<float> all;
  for (int y = 0; y < luminance.rows; y += 4)
    for (int x = 0; x < luminance.cols; x += 4) all.push_back(luminance.at<float>(y, x));
  std::nth_element(all.begin(), all.begin() + all.size() / 2, all.end());
  const double floor_level = all[all.size() / 2] + options.light_zone_sigma * noise_sigma;
  const double max_r = std::hypot(luminance.cols, luminance.rows);
  double zone = core;
  std::vector<float> ring;
  for (double r = core + 1; r < max_r; r += 2) {
    ring.clear();
    const int samples = 72;
    for (int k = 0; k < samples; ++k) {
      const double a = 2 * std::numbers::pi * k / samples;
      const int x = static_cast<int>(light.center.x + r * std::cos(a));
      const int y = static_cast<int>(light.center.y + r * std::sin(a));
      if (x < 0 || y < 0 || x >= luminance.cols || y >= luminance.rows) continue;
      ring.push_back(valid.at<uchar>(y, x) ? luminance.at<float>(y, x) : 1e30f);
    }
    if (ring.size() < 8) break;
    std::nth_element(ring.begin(), ring.begin() + ring.size() / 2, ring.end());
    zone = r;
    if (ring[ring.size() / 2] < floor_level) break;
  }
  light.zone_radius_px = zone * options.zone_margin;
  light.center = refineLightCenter(luminance, valid, light, options);
  return light;
}

std::vector<LightImage> followLight(std::vector<LightImage> found, const std::vector<double>& angles_deg,
                                    cv::Size size) {
  const int n = static_cast<int>(found.size());
  if (static_cast<int>(angles_deg.size()) != n) throw std::invalid_argument("followLight: one angle per frame");
  std::vector<double> cores;
  for (const LightImage& l : found)
    if (l.found) cores.push_back(l.core_radius_px);
  if (cores.empty()) return found;
  std::nth_element(cores.begin(), cores.begin() + cores.size() / 2, cores.end());
  const double median_core = cores[cores.size() / 2];
  constexpr double kMarginPx = 2, kMaxGapDeg = 3;
  constexpr int kNeighbours = 8, kMinNeighbours = 4;
  auto clear = [&](const LightImage& l) {
    const double r = std::max(l.core_radius_px, median_core) + kMarginPx;
    return l.found && l.center.x > r && l.center.y > r && l.center.x + r < size.width && l.center.y + r < size.height;
  };
  std::vector<int> clear_frames;
  for (int i = 0; i < n; ++i)
    if (clear(found[i])) clear_frames.push_back(i);
  std::vector<LightImage> lights = found;
  for (int i = 0; i < n; ++i) {
    if (clear(found[i])) continue;
    std::vector<int> near = clear_frames;
    std::sort(near.begin(), near.end(), [&](int a, int b) {
      return std::abs(angles_deg[a] - angles_deg[i]) < std::abs(angles_deg[b] - angles_deg[i]);
    });
    if (static_cast<int>(near.size()) > kNeighbours) near.resize(kNeighbours);
    if (static_cast<int>(near.size()) < kMinNeighbours || std::abs(angles_deg[near[0]] - angles_deg[i]) > kMaxGapDeg)
      continue;
    // Least squares line through the centres, in θ − θ_i.
    double s1 = 0, st = 0, stt = 0, sx = 0, stx = 0, sy = 0, sty = 0, core = 0, zone = 0;
    for (int k : near) {
      const double t = angles_deg[k] - angles_deg[i];
      s1 += 1;
      st += t;
      stt += t * t;
      sx += found[k].center.x;
      stx += t * found[k].center.x;
      sy += found[k].center.y;
      sty += t * found[k].center.y;
      core += found[k].core_radius_px;
      zone += found[k].zone_radius_px;
    }
    const double det = s1 * stt - st * st;
    if (!(std::abs(det) > 1e-12)) continue;  // every neighbour at one angle
    LightImage l;
    l.found = true;
    l.predicted = true;
    l.center = {(stt * sx - st * stx) / det, (stt * sy - st * sty) / det};  // the lines at t = 0
    l.core_radius_px = core / s1;
    l.zone_radius_px = zone / s1;
    const double dx = std::max({0.0, -l.center.x, l.center.x - size.width});
    const double dy = std::max({0.0, -l.center.y, l.center.y - size.height});
    if (std::hypot(dx, dy) < l.zone_radius_px) lights[i] = l;
  }
  return lights;
}

cv::Mat validBesideLight(const cv::Mat& valid, const LightImage& light) {
  if (!light.found || !light.predicted) return valid;
  cv::Mat out = valid.clone();
  const cv::Point2d c = light.center;
  for (int y = 0; y < out.rows; ++y) {
    uchar* v = out.ptr<uchar>(y);
    for (int x = 0; x < out.cols; ++x) {
      const double px = x + 0.5, py = y + 0.5;
      if (std::hypot(px - c.x, py - c.y) > light.zone_radius_px) continue;
      const double mx = 2 * c.x - px, my = 2 * c.y - py;
      if (mx < 0 || my < 0 || mx >= out.cols || my >= out.rows) v[x] = 0;
    }
  }
  return out;
}

cv::Mat estimateLightImage(const cv::Mat& residual, const cv::Mat& valid, const LightImage& light,
                           double noise_sigma, const DetectionOptions& options) {
  cv::Mat light_image = cv::Mat::zeros(residual.size(), residual.type());
  if (!light.found) return light_image;
  // A new buffer: blurring into a header that shares `residual`'s data would blur the caller's
  // frame in place.
  cv::Mat smooth;
  if (options.light_smoothing_px > 0)
    cv::GaussianBlur(residual, smooth, cv::Size(0, 0), options.light_smoothing_px,
                     options.light_smoothing_px, cv::BORDER_REPLICATE);
  else
    smooth = residual.clone();
  // Pixel i has its centre at i + ½, so the reflection 2c − p maps index i to 2c − 1 − i.
  const cv::Matx23d reflect(-1, 0, 2 * light.center.x - 1, 0, -1, 2 * light.center.y - 1);
  const float unknown = std::numeric_limits<float>::quiet_NaN();
  cv::Mat mirrored, mirrored_valid;
  cv::warpAffine(smooth, mirrored, reflect, smooth.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_CONSTANT, cv::Scalar::all(unknown));
  cv::warpAffine(valid, mirrored_valid, reflect, valid.size(), cv::INTER_NEAREST | cv::WARP_INVERSE_MAP,
                 cv::BORDER_CONSTANT, cv::Scalar(255));
  const int channels = residual.channels();
  // The distance of a pixel's centre from the light, and the ring of whole pixels it lies in.
  auto distance = [&](int x, int y) { return std::hypot(x + 0.5 - light.center.x, y + 0.5 - light.center.y); };
  auto ring = [&](int x, int y) { return static_cast<int>(distance(x, y)); };
  const int rings = 2 + static_cast<int>(std::ceil(std::max(
                            {distance(0, 0), distance(residual.cols - 1, 0), distance(0, residual.rows - 1),
                             distance(residual.cols - 1, residual.rows - 1)})));
  // S where the mirror point is in the frame; per channel and ring, the largest of it and how many
  // pixels it is known at.
  std::vector<std::vector<float>> ring_max(channels, std::vector<float>(rings, 0.0f));
  std::vector<int> ring_known(rings, 0);
  std::vector<uchar> mirror_outside(residual.total(), 0);
  for (int y = 0; y < residual.rows; ++y) {
    const float* r = smooth.ptr<float>(y);
    const float* m = mirrored.ptr<float>(y);
    const uchar* mv = mirrored_valid.ptr<uchar>(y);
    float* s = light_image.ptr<float>(y);
    for (int x = 0; x < residual.cols; ++x) {
      if (std::isnan(m[x * channels])) {
        mirror_outside[static_cast<size_t>(y) * residual.cols + x] = 1;
        continue;
      }
      const int k = ring(x, y);
      if (mv[x]) ++ring_known[k];
      for (int c = 0; c < channels; ++c) {
        const int i = x * channels + c;
        s[i] = std::max(0.0f, mv[x] ? std::min(r[i], m[i]) : r[i]);  // beside the core the light rules
        if (mv[x]) ring_max[c][k] = std::max(ring_max[c][k], s[i]);
      }
    }
  }
  // Where the mirror point is outside the frame (the light near its border), the light is taken as
  // the same in every direction: S = min(R̃(p), P(|p − c|)), P the largest S over the ring's pixels
  // whose mirror is in the frame, made non-increasing outwards so that a ghost in a ring does not
  // raise it, and 0 from the first ring outside the core with too few such pixels to tell. The
  // halo is radial and the starburst's spikes (the aperture's diffraction) as long in every
  // direction, so P is the spikes' level, and between them S is the halo; S itself, not R̃, is
  // taken over the ring, the ghosts in it already left out by their mirror points. With S = 0
  // there, the halo and spikes beside a light 33–45 px from the border were fitted as ghosts 3–10×
  // brighter than the flare (Heliar 640×427 fit at λ = 1, 9.0–10.0°: PSNR 5.8–11.8 dB; with this,
  // 15.6 and 16.1 dB at 9.0 and 9.2°, where a veil is missing, and 24.9–25.4 dB at 9.4–10.0°).
  // The rings' median left the spikes, and they were fitted (13.1 dB at 9.2°).
  constexpr int kMinRingPixels = 8;
  std::vector<std::vector<float>> profile(channels, std::vector<float>(rings, 0.0f));
  for (int c = 0; c < channels; ++c) {
    float running = std::numeric_limits<float>::infinity();
    for (int k = 0; k < rings; ++k) {
      if (ring_known[k] < kMinRingPixels) {
        if (std::isfinite(running)) running = 0;  // past the core: nothing known from here outwards
        continue;
      }
      running = std::min(running, ring_max[c][k]);
      profile[c][k] = running;
    }
  }
  for (int y = 0; y < residual.rows; ++y) {
    const float* r = smooth.ptr<float>(y);
    float* s = light_image.ptr<float>(y);
    for (int x = 0; x < residual.cols; ++x) {
      if (!mirror_outside[static_cast<size_t>(y) * residual.cols + x]) continue;
      // Between the rings' middles (ring k holds distances k to k + 1): halos are steep near the
      // core, tens of σ per pixel.
      const double t = std::max(0.0, distance(x, y) - 0.5);
      const int k = std::min(static_cast<int>(t), rings - 2);
      const double f = t - k;
      for (int c = 0; c < channels; ++c) {
        const int i = x * channels + c;
        const double p = (1 - f) * profile[c][k] + f * profile[c][k + 1];
        s[i] = std::max(0.0f, std::min(r[i], static_cast<float>(p)));
      }
    }
  }
  // Only the light's own region: the part of {S > light_zone_sigma σ} connected to the core. Away
  // from the light, min(R(p), R(2c − p)) is not the light but whatever is smooth there (the
  // frame-filling veils, a ghost's symmetric part), and removing it took those ghosts away.
  cv::Mat strong = luminance(light_image) > options.light_zone_sigma * noise_sigma;
  cv::Mat labels;
  const int count = cv::connectedComponents(strong, labels, 8, CV_32S);
  std::vector<bool> keep(count, false);
  const double reach = std::max(2.0, 2 * light.core_radius_px);
  const cv::Rect near = cv::Rect(cvFloor(light.center.x - reach), cvFloor(light.center.y - reach),
                                 cvCeil(2 * reach) + 1, cvCeil(2 * reach) + 1) &
                        cv::Rect(0, 0, labels.cols, labels.rows);
  for (int y = near.y; y < near.y + near.height; ++y)
    for (int x = near.x; x < near.x + near.width; ++x) {
      const int l = labels.at<int>(y, x);
      if (l > 0) keep[l] = true;
    }
  cv::Mat region = cv::Mat::zeros(labels.size(), CV_8U);
  for (int y = 0; y < labels.rows; ++y)
    for (int x = 0; x < labels.cols; ++x)
      if (keep[labels.at<int>(y, x)]) region.at<uchar>(y, x) = 255;
  // The soft fringe just outside the threshold belongs to the light too.
  cv::dilate(region, region, cv::Mat(), cv::Point(-1, -1), 3);
  cv::Mat outside = region == 0;
  light_image.setTo(cv::Scalar::all(0), outside);
  return light_image;
}

namespace {

// The rest of a seed whose centre and size are set, the same for blobs and veils: an elliptic
// outline, border and inside values `border` and `inside`, an inside fall-off of 15 % of the
// smaller half-size, an outside fall-off of 2 px (the blob's margin), linear exponents.
void finishSeed(double border, double inside, model::GhostParameters* g) {
  g->curvature_left = g->curvature_right = model::kEllipseCurvature;
  g->border = {border, 0, 0};
  g->inside = {inside, 0, 0};
  g->inside_falloff = std::max(1.0, 0.15 * std::min(g->left + g->right, 2 * g->height) / 2);
  g->inside_exponent = 1;
  g->outside_falloff = 2;
  g->outside_exponent = 1;
}

// The flare axis's unit direction from the image centre (see flareAxisOffset).
cv::Point2d flareAxisDirection(const LightImage& light, cv::Size size) {
  const cv::Point2d center(size.width / 2.0, size.height / 2.0);
  cv::Point2d dir(1, 0);
  if (light.found && cv::norm(light.center - center) > 0.05 * size.width) {
    dir = light.center - center;
    dir /= cv::norm(dir);
  }
  return dir;
}

}  // namespace

double flareAxisOffset(cv::Point2d point, const LightImage& light, cv::Size size) {
  const cv::Point2d center(size.width / 2.0, size.height / 2.0);
  const cv::Point2d dir = flareAxisDirection(light, size);
  const cv::Point2d d = point - center;
  return std::abs(d.x * dir.y - d.y * dir.x);
}

std::vector<Detection> detectGhosts(const cv::Mat& residual, const cv::Mat& valid,
                                    double noise_sigma, const LightImage& light,
                                    const DetectionOptions& options, const cv::Mat& floor) {
  cv::Mat smooth;
  cv::GaussianBlur(residual, smooth, cv::Size(0, 0), options.smoothing_px, options.smoothing_px,
                   cv::BORDER_REPLICATE);
  const int W = residual.cols, H = residual.rows;
  // Keep out of the light's zone and of masked pixels.
  cv::Mat allowed = valid.clone();
  if (light.found)
    cv::circle(allowed, cv::Point(cvRound(light.center.x), cvRound(light.center.y)),
               cvRound(options.light_symmetry ? light.core_radius_px * options.core_margin
                                              : light.zone_radius_px),
               cv::Scalar(0), cv::FILLED);
  const cv::Point2d center(W / 2.0, H / 2.0);
  auto axisOffset = [&](cv::Point2d p) { return flareAxisOffset(p, light, residual.size()); };

  std::vector<Detection> found;
  cv::Mat claimed = cv::Mat::zeros(residual.size(), CV_8U);  // blobs already taken at a higher level
  std::vector<double> levels = options.levels_sigma;
  std::sort(levels.rbegin(), levels.rend());
  for (double level : levels) {
    cv::Mat mask = (smooth > level * noise_sigma) & (allowed > 0);
    if (!floor.empty()) mask &= smooth > floor;
    cv::Mat labels, stats, centroids;
    const int n = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
    for (int i = 1; i < n; ++i) {
      const int area = stats.at<int>(i, cv::CC_STAT_AREA);
      if (area < options.min_area_px) continue;
      const cv::Rect box(stats.at<int>(i, cv::CC_STAT_LEFT), stats.at<int>(i, cv::CC_STAT_TOP),
                         stats.at<int>(i, cv::CC_STAT_WIDTH), stats.at<int>(i, cv::CC_STAT_HEIGHT));
      cv::Mat blob = labels(box) == i;
      // Already claimed at a higher level: the same ghost (or its brighter neighbour).
      if (cv::countNonZero(claimed(box) & blob) > area / 4) continue;
      const cv::Point2d centroid(centroids.at<double>(i, 0) + 0.5, centroids.at<double>(i, 1) + 0.5);
      // Elongated thin blobs are starburst spikes or edges of the light's zone, not ghosts.
      const double aspect = double(std::max(box.width, box.height)) / std::max(1, std::min(box.width, box.height));
      if (aspect > 6) continue;
      // The box's centre on the axis: symmetric ghosts have their mirror axis there.
      const cv::Point2d box_center(box.x + box.width / 2.0, box.y + box.height / 2.0);
      if (axisOffset(box_center) > options.max_axis_offset * H &&
          axisOffset(centroid) > options.max_axis_offset * H)
        continue;
      Detection d;
      d.blob = box;
      d.mask = blob.clone();
      d.level_sigma = level;
      double peak = 0;
      cv::minMaxLoc(smooth(box), nullptr, &peak, nullptr, nullptr, blob);
      d.peak = peak;
      // Values over the blob: the border value from the bright end, the inside from the median.
      std::vector<float> values;
      for (int y = 0; y < box.height; ++y)
        for (int x = 0; x < box.width; ++x)
          if (blob.at<uchar>(y, x)) values.push_back(residual.at<float>(box.y + y, box.x + x));
      // Selections, not a sort: a frame-filling glare's blob holds 10⁵ values.
      const size_t middle = values.size() / 2, upper = static_cast<size_t>(0.9 * (values.size() - 1));
      std::nth_element(values.begin(), values.begin() + middle, values.end());
      const double median = values[middle];
      std::nth_element(values.begin(), values.begin() + upper, values.end());
      const double high = values[upper];
      model::GhostParameters& g = d.seed;
      g.channels = 1;
      // The mirror axis: the box is symmetric about it unless the image border cuts it.
      const bool cut_top = box.y <= 0, cut_bottom = box.y + box.height >= H;
      double my = box_center.y;
      if (cut_top != cut_bottom) my = center.y;
      g.center_y = my;
      g.height = std::max({2.0, my - box.y, box.y + box.height - my});
      g.center_x = box_center.x;
      g.left = g.right = std::max(2.0, box.width / 2.0);
      // Cut by the left or right border: the ghost reaches beyond it; keep its round shape.
      if (box.x <= 0 && box.x + box.width < W) {
        g.right = std::max(g.right, g.height * 0.5);
        g.center_x = box.x + box.width - g.right;
        g.left = std::max(g.right, g.height);
        g.right = g.left;
        g.center_x = box.x + box.width - g.right;
      } else if (box.x + box.width >= W && box.x > 0) {
        g.left = std::max(g.left, g.height);
        g.right = g.left;
        g.center_x = box.x + g.left;
      }
      // Beside the light, the part of a ghost that overlaps its own reflection about the light
      // went into the light's estimate (estimateLightImage), so the blob is cut on the light's
      // side: a blob narrower than tall there keeps its far edge and is seeded round (ghosts of
      // round apertures are round near the axis), reaching towards the light.
      if (light.found && options.light_symmetry && box.width < 0.8 * box.height &&
          g.left == g.right && box.x > 0 && box.x + box.width < W) {
        const double half = g.height;
        if (light.center.x > box_center.x) g.center_x = box.x + half;
        else g.center_x = box.x + box.width - half;
        g.left = g.right = half;
      }
      // The blob reaches over the outside fall-off (seeded at 2 px) and the smoothing: the outline
      // lies that much inside its box. A seed outline too large makes a ring of Ib ≈ 0 around the
      // ghost a local minimum when the ghost is brighter inside than at its border.
      const double shrink = 2 + options.smoothing_px;
      if (g.left > 2 * shrink) g.left -= shrink;
      if (g.right > 2 * shrink) g.right -= shrink;
      if (g.height > 2 * shrink) g.height -= shrink;
      finishSeed(std::max(high, 1e-12), std::max(median, 0.0), &g);
      found.push_back(d);
      claimed(box).setTo(255, blob);
    }
  }
  std::sort(found.begin(), found.end(),
            [](const Detection& a, const Detection& b) { return a.peak > b.peak; });
  if (static_cast<int>(found.size()) > options.max_new_per_frame)
    found.resize(options.max_new_per_frame);
  return found;
}

std::optional<Detection> detectGlare(const cv::Mat& residual, const cv::Mat& valid, double noise_sigma,
                                     const LightImage& light, const DetectionOptions& options) {
  if (!(noise_sigma > 0)) return std::nullopt;
  cv::Mat mask = valid.clone();
  if (light.found)
    cv::circle(mask, cv::Point(cvRound(light.center.x), cvRound(light.center.y)),
               cvCeil(light.core_radius_px * options.core_margin), cv::Scalar(0), cv::FILLED);
  std::vector<float> values;
  for (int y = 0; y < residual.rows; ++y)
    for (int x = 0; x < residual.cols; ++x)
      if (mask.at<uchar>(y, x) && std::isfinite(residual.at<float>(y, x))) values.push_back(residual.at<float>(y, x));
  if (values.empty()) return std::nullopt;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  const double median = values[values.size() / 2];
  if (!(median > options.glare_sigma * noise_sigma)) return std::nullopt;
  Detection det;
  det.level_sigma = options.glare_sigma;
  det.peak = median;
  model::GhostParameters& g = det.seed;
  g.channels = 1;
  finishSeed(median, median, &g);
  // An outline that holds the frame, flat over it, centred where the axis runs through the image
  // centre: the shape fitBounds keeps a glare within.
  shapeGlareSeed(residual.size(), &g);
  det.blob = cv::Rect(0, 0, residual.cols, residual.rows);
  det.mask = mask;
  return det;
}

std::vector<Detection> detectVeilEdges(const cv::Mat& residual, const cv::Mat& valid,
                                       double noise_sigma, const LightImage& light,
                                       const DetectionOptions& options) {
  std::vector<Detection> found;
  if (!(noise_sigma > 0)) return found;
  const int W = residual.cols, H = residual.rows;
  const cv::Point2d center(W / 2.0, H / 2.0);
  const cv::Point2d dir = flareAxisDirection(light, residual.size());
  const cv::Point2d across(-dir.y, dir.x);
  const double keep_out = light.found ? light.core_radius_px * options.core_margin : 0.0;
  // The point at axis position i (t = i − reach pixels from the centre), s pixels across, and
  // its pixel, when inside the frame and valid.
  const int reach = static_cast<int>(std::ceil(std::hypot(W, H) / 2));
  const int n = 2 * reach + 1;
  auto pointAt = [&](int i, int s) {
    return center + static_cast<double>(i - reach) * dir + static_cast<double>(s) * across;
  };
  auto usablePixel = [&](cv::Point2d p, cv::Point* px) {
    *px = cv::Point(static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y)));
    return px->x >= 0 && px->y >= 0 && px->x < W && px->y < H && valid.at<uchar>(*px) != 0;
  };
  // The band's mean at each position (NaN unless more than half its pixels are usable).
  std::vector<double> profile(static_cast<size_t>(n), std::numeric_limits<double>::quiet_NaN());
  const int band = options.veil_band_px;
  for (int i = 0; i < n; ++i) {
    double sum = 0;
    int count = 0;
    for (int s = -band; s <= band; ++s) {
      const cv::Point2d p = pointAt(i, s);
      cv::Point px;
      if (!usablePixel(p, &px)) continue;
      if (light.found && cv::norm(p - light.center) < keep_out) continue;
      sum += residual.at<float>(px);
      ++count;
    }
    if (count > band) profile[static_cast<size_t>(i)] = sum / count;
  }
  // Steps: mean over (t, t + w] minus mean over [t − w, t), each side needing w usable means.
  const int w = options.veil_window_px;
  auto sideMean = [&](int from, int to) {  // inclusive, may run off the profile
    double sum = 0;
    int k = 0;
    for (int j = std::max(0, from); j <= std::min(n - 1, to); ++j)
      if (!std::isnan(profile[static_cast<size_t>(j)])) {
        sum += profile[static_cast<size_t>(j)];
        ++k;
      }
    return k == to - from + 1 ? sum / k : std::numeric_limits<double>::quiet_NaN();
  };
  std::vector<double> step(static_cast<size_t>(n), 0.0);
  for (int i = 0; i < n; ++i) {
    const double d = sideMean(i + 1, i + w) - sideMean(i - w, i - 1);
    if (!std::isnan(d)) step[static_cast<size_t>(i)] = d;
  }
  const double threshold = options.veil_step_sigma * noise_sigma;
  // The usable stretch of the axis, for "stays up to the border".
  int first = 0, last = n - 1;
  while (first < n && std::isnan(profile[static_cast<size_t>(first)])) ++first;
  while (last >= 0 && std::isnan(profile[static_cast<size_t>(last)])) --last;
  for (int i = 0; i < n; ++i) {
    const double d = step[static_cast<size_t>(i)];
    if (!(std::abs(d) >= threshold)) continue;
    bool peak = true;  // the strongest within ±w (the first of equals)
    for (int j = std::max(0, i - w); j <= std::min(n - 1, i + w) && peak; ++j)
      if (std::abs(step[static_cast<size_t>(j)]) > std::abs(d) ||
          (j < i && std::abs(step[static_cast<size_t>(j)]) == std::abs(d)))
        peak = false;
    if (!peak) continue;
    const int sign = d > 0 ? 1 : -1;  // the bright side: +t or −t
    // The bright side stays up to the border: the last window before the usable end is still at
    // least half the step above the dark side.
    const double dark = sign > 0 ? sideMean(i - w, i - 1) : sideMean(i + 1, i + w);
    const double edge = sign > 0 ? sideMean(last - w + 1, last) : sideMean(first, first + w - 1);
    if (std::isnan(dark) || std::isnan(edge) || !(edge - dark >= 0.5 * std::abs(d))) continue;
    Detection det;
    det.level_sigma = options.veil_step_sigma;
    det.peak = std::abs(d);
    const double radius = H;
    const cv::Point2d crossing = pointAt(i, 0);
    const cv::Point2d c = crossing + static_cast<double>(sign) * radius * dir;
    model::GhostParameters& g = det.seed;
    g.channels = 1;
    g.center_x = c.x;
    g.center_y = c.y;
    g.left = g.right = g.height = radius;
    finishSeed(std::abs(d), std::abs(d), &g);
    // The blob: the band on the bright side, from the step to the border.
    cv::Mat mask = cv::Mat::zeros(residual.size(), CV_8U);
    const int to = sign > 0 ? last : first;
    for (int j = i; j != to + sign; j += sign)
      for (int s = -band; s <= band; ++s) {
        cv::Point px;
        if (usablePixel(pointAt(j, s), &px)) mask.at<uchar>(px) = 255;
      }
    det.blob = cv::boundingRect(mask);
    if (det.blob.empty()) continue;
    det.mask = mask(det.blob).clone();
    found.push_back(std::move(det));
  }
  std::sort(found.begin(), found.end(), [](const Detection& a, const Detection& b) { return a.peak > b.peak; });
  return found;
}

}  // namespace flarekit::fit
