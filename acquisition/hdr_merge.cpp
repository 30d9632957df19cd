#include "acquisition/hdr_merge.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

#include <atomic>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace flarekit::acquisition {

bool MergeOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(gain_e_per_dn > 0) || !std::isfinite(gain_e_per_dn))
    return fail("gain_e_per_dn must be positive");
  if (!(read_noise_e >= 0) || !std::isfinite(read_noise_e))
    return fail("read_noise_e must be ≥ 0");
  if (!(saturation_fraction > 0 && saturation_fraction <= 1))
    return fail("saturation_fraction must be in (0, 1]");
  if (!(output_scale > 0) || !std::isfinite(output_scale)) return fail("output_scale must be positive");
  if (!(ratio_tolerance > 0)) return fail("ratio_tolerance must be positive");
  if (ratio_min_samples < 1) return fail("ratio_min_samples must be ≥ 1");
  return true;
}

namespace {

constexpr int kMaxFrames = 16;

void checkInputs(const std::vector<RawFrame>& frames, const std::vector<cv::Mat>& darks) {
  if (frames.empty()) throw InputError("merge: no frames given");
  if (frames.size() > kMaxFrames)
    throw InputError("merge: at most " + std::to_string(kMaxFrames) + " exposures, got " +
                     std::to_string(frames.size()));
  const RawFrame& f0 = frames[0];
  for (size_t i = 0; i < frames.size(); ++i) {
    const RawFrame& f = frames[i];
    std::string which = "merge: frame " + std::to_string(i + 1);
    if (f.data.empty() || f.data.type() != CV_16UC1)
      throw InputError(which + ": RAW data must be 16-bit single-channel");
    if (f.data.size() != f0.data.size())
      throw InputError(which + ": size " + std::to_string(f.data.cols) + "x" +
                       std::to_string(f.data.rows) + " differs from frame 1 (" +
                       std::to_string(f0.data.cols) + "x" + std::to_string(f0.data.rows) + ")");
    if (f.cfa != f0.cfa) throw InputError(which + ": colour filter layout differs from frame 1");
    if (!(f.exposure_s > 0) || !std::isfinite(f.exposure_s))
      throw InputError(which + ": exposure time must be positive (got " +
                       std::to_string(f.exposure_s) + " s)");
    if (!(f.white_level > f.black_level))
      throw InputError(which + ": white level must be above the black level");
    if (f.black_level != f0.black_level || f.white_level != f0.white_level)
      throw InputError(which + ": black/white levels differ from frame 1");
    for (size_t j = 0; j < i; ++j)
      if (std::abs(frames[j].exposure_s - f.exposure_s) <= 1e-9 * f.exposure_s)
        throw InputError(which + ": same exposure time as frame " + std::to_string(j + 1) + " (" +
                         std::to_string(f.exposure_s) + " s); a bracket needs different times");
  }
  if (!darks.empty()) {
    if (darks.size() != frames.size())
      throw InputError("merge: need one dark frame per exposure or none");
    for (const auto& d : darks)
      if (d.type() != CV_32FC1 || d.size() != f0.data.size())
        throw InputError("merge: dark frames must be float images of the frames' size");
  }
}

}  // namespace

MergeResult mergeBracket(const std::vector<RawFrame>& frames, const MergeOptions& options,
                         const std::vector<cv::Mat>& darks) {
  std::string error;
  if (!options.IsValid(&error)) throw InputError("merge options: " + error);
  checkInputs(frames, darks);

  const int n = static_cast<int>(frames.size());
  const int rows = frames[0].data.rows, cols = frames[0].data.cols;
  const float black = static_cast<float>(frames[0].black_level);
  const float range = static_cast<float>(frames[0].white_level - frames[0].black_level);
  // Saturation is judged on the raw value (black level included), as the sensor clips it.
  const int sat_threshold =
      static_cast<int>(std::ceil(frames[0].black_level + options.saturation_fraction * range));
  // In DN: shot-noise variance of a signal s is s/gain_e_per_dn, read-noise variance σ_r².
  const float gain = static_cast<float>(1.0 / options.gain_e_per_dn);
  const double read_dn = options.read_noise_e / options.gain_e_per_dn;
  const float read_var = static_cast<float>(read_dn * read_dn);
  const float to_output = static_cast<float>(options.gain_e_per_dn / options.output_scale);
  const bool use_darks = !darks.empty();

  float t[kMaxFrames], inv_t[kMaxFrames];
  int shortest = 0;
  double t_sum_all = 0;
  for (int i = 0; i < n; ++i) {
    t[i] = static_cast<float>(frames[i].exposure_s);
    inv_t[i] = 1.0f / t[i];
    t_sum_all += t[i];
    if (t[i] < t[shortest]) shortest = i;
  }

  MergeResult result;
  result.cfa = frames[0].cfa;
  result.merged.create(rows, cols, CV_32FC1);
  result.saturated = cv::Mat::zeros(rows, cols, CV_8UC1);
  std::atomic<long long> saturated_count{0};

  // Row by row, in passes over contiguous float buffers so that the compiler vectorises them.
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, 8), [&](const tbb::blocked_range<int>& r) {
    const size_t w = static_cast<size_t>(cols);
    std::vector<uint8_t> bad(static_cast<size_t>(n) * w);  // per frame: excluded samples
    std::vector<uint8_t> vertical(w + 2);
    std::vector<float> sig(static_cast<size_t>(n) * w);    // per frame: v − black (or dark)
    std::vector<float> valid(static_cast<size_t>(n) * w);
    std::vector<float> sum_s(w), sum_t(w), num(w), den(w), first(w);
    long long local_saturated = 0;
    for (int y = r.begin(); y < r.end(); ++y) {
      std::fill(sum_s.begin(), sum_s.end(), 0.0f);
      std::fill(sum_t.begin(), sum_t.end(), 0.0f);
      std::fill(num.begin(), num.end(), 0.0f);
      std::fill(den.begin(), den.end(), 0.0f);
      for (int i = 0; i < n; ++i) {
        const uint16_t* mid = frames[i].data.ptr<uint16_t>(y);
        uint8_t* b = bad.data() + i * w;
        float* si = sig.data() + i * w;
        if (options.exclude_neighbours) {
          const uint16_t* up = frames[i].data.ptr<uint16_t>(std::max(y - 1, 0));
          const uint16_t* down = frames[i].data.ptr<uint16_t>(std::min(y + 1, rows - 1));
          uint8_t* v = vertical.data() + 1;
          vertical[0] = vertical[w + 1] = 0;
          for (size_t x = 0; x < w; ++x)
            v[x] = static_cast<uint8_t>((up[x] >= sat_threshold) | (mid[x] >= sat_threshold) |
                                        (down[x] >= sat_threshold));
          for (size_t x = 0; x < w; ++x)
            b[x] = static_cast<uint8_t>(vertical[x] | vertical[x + 1] | vertical[x + 2]);
        } else {
          for (size_t x = 0; x < w; ++x) b[x] = static_cast<uint8_t>(mid[x] >= sat_threshold);
        }
        if (use_darks) {
          const float* d = darks[i].ptr<float>(y);
          for (size_t x = 0; x < w; ++x) si[x] = static_cast<float>(mid[x]) - d[x];
        } else {
          for (size_t x = 0; x < w; ++x) si[x] = static_cast<float>(mid[x]) - black;
        }
        // Validity as 0/1 floats: branch-free loops the compiler vectorises.
        float* __restrict vf = valid.data() + i * w;
        const uint8_t* __restrict bb = b;
        for (size_t x = 0; x < w; ++x) vf[x] = 1.0f - static_cast<float>(bb[x]);
        const float ti = t[i];
        float* __restrict ss = sum_s.data();
        float* __restrict st = sum_t.data();
        const float* __restrict sv = si;
        for (size_t x = 0; x < w; ++x) {
          ss[x] += vf[x] * sv[x];
          st[x] += vf[x] * ti;
        }
      }
      // Granados et al. 2010: inverse-variance weights from shot and read noise, evaluated at
      // the shot-noise-optimal first estimate x0 = Σ s / Σ t (DN per second).
      {
        float* __restrict x0 = first.data();
        const float* __restrict ss = sum_s.data();
        const float* __restrict st = sum_t.data();
        for (size_t x = 0; x < w; ++x) x0[x] = std::max(ss[x] / std::max(st[x], 1e-30f), 0.0f);
      }
      for (int i = 0; i < n; ++i) {
        const float* __restrict vf = valid.data() + i * w;
        const float* __restrict sv = sig.data() + i * w;
        const float* __restrict x0 = first.data();
        float* __restrict nu = num.data();
        float* __restrict de = den.data();
        const float t2 = t[i] * t[i], g_t = gain * t[i], inv = inv_t[i];
        for (size_t x = 0; x < w; ++x) {
          const float wgt = vf[x] * t2 / (g_t * x0[x] + read_var + 1e-12f);
          nu[x] += wgt * sv[x] * inv;
          de[x] += wgt;
        }
      }
      float* out = result.merged.ptr<float>(y);
      uint8_t* sat = result.saturated.ptr<uint8_t>(y);
      {
        const float* __restrict nu = num.data();
        const float* __restrict de = den.data();
        float* __restrict o = out;
        for (size_t x = 0; x < w; ++x) o[x] = nu[x] / std::max(de[x], 1e-30f) * to_output;
      }
      for (size_t x = 0; x < w; ++x) {
        if (den[x] > 0) continue;
        // Every sample saturated or next to a saturated photosite. A sample that is itself
        // below the threshold is still a measurement (blooming is a risk, not a certainty): use
        // the shortest such exposure. Otherwise flag the photosite: its value is a lower bound.
        int best = -1;
        for (int i = 0; i < n; ++i)
          if (frames[i].data.ptr<uint16_t>(y)[x] < sat_threshold && (best < 0 || t[i] < t[best]))
            best = i;
        if (best >= 0) {
          out[x] = sig[best * w + x] * inv_t[best] * to_output;
        } else {
          out[x] = range * inv_t[shortest] * to_output;
          sat[x] = 1;
          ++local_saturated;
        }
      }
    }
    saturated_count += local_saturated;
  });
  result.saturated_count = saturated_count.load();
  (void)t_sum_all;

  // Exposure ratios measured on the data: per consecutive pair (by time), the median ratio of
  // photosites that are unsaturated in both, bright enough in the short one (≥ 20 σ_r) and
  // mid-tone in the long one (5 %–80 % of the range), on a sparse grid.
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return t[a] < t[b]; });
  const float min_short = std::max(20.0f * std::sqrt(read_var), 0.002f * range);
  for (int k = 0; k + 1 < n; ++k) {
    const int a = order[k], b = order[k + 1];
    ExposureRatioCheck check;
    check.short_s = t[a];
    check.long_s = t[b];
    check.stated_ratio = frames[b].exposure_s / frames[a].exposure_s;
    std::vector<float> ratios;
    // Every 2nd row/column on small frames; sparser on large ones (≤ ~250k photosites looked at).
    const int stride = std::max(2, static_cast<int>(std::sqrt(double(rows) * cols / 250000.0)) | 1);
    for (int y = 1; y < rows - 1; y += stride) {
      const uint16_t* ra = frames[a].data.ptr<uint16_t>(y);
      const uint16_t* rb = frames[b].data.ptr<uint16_t>(y);
      const uint16_t* rb_up = frames[b].data.ptr<uint16_t>(y - 1);
      const uint16_t* rb_down = frames[b].data.ptr<uint16_t>(y + 1);
      const float* da = use_darks ? darks[a].ptr<float>(y) : nullptr;
      const float* db = use_darks ? darks[b].ptr<float>(y) : nullptr;
      for (int x = 1; x < cols - 1; x += stride) {
        if (rb[x] >= sat_threshold || rb[x - 1] >= sat_threshold || rb[x + 1] >= sat_threshold ||
            rb_up[x] >= sat_threshold || rb_down[x] >= sat_threshold)
          continue;
        const float sa = ra[x] - (da ? da[x] : black);
        const float sb = rb[x] - (db ? db[x] : black);
        if (sa < min_short || sb < 0.05f * range || sb > 0.8f * range) continue;
        ratios.push_back(sb / sa);
      }
    }
    check.samples = static_cast<long long>(ratios.size());
    if (check.samples >= options.ratio_min_samples) {
      auto mid = ratios.begin() + ratios.size() / 2;
      std::nth_element(ratios.begin(), mid, ratios.end());
      check.measured_ratio = *mid;
      const double rel = std::abs(check.measured_ratio / check.stated_ratio - 1.0);
      check.agrees = rel <= options.ratio_tolerance;
      if (!check.agrees) {
        std::ostringstream w;
        w.precision(4);
        w << "exposure ratio " << check.long_s << " s / " << check.short_s << " s measured "
          << check.measured_ratio << " on " << check.samples << " photosites, stated "
          << check.stated_ratio << " (" << rel * 100
          << " % off): check the exposure times (EXIF) and the camera's shutter";
        result.warnings.push_back(w.str());
      }
    }
    result.ratio_checks.push_back(check);
  }
  return result;
}

cv::Mat demosaicBilinear(const cv::Mat& mosaic, Cfa cfa) {
  CV_Assert(mosaic.type() == CV_32FC1);
  if (cfa == Cfa::kMono) return mosaic.clone();
  const int rows = mosaic.rows, cols = mosaic.cols;
  cv::Mat rgb(rows, cols, CV_32FC3);
  tbb::parallel_for(tbb::blocked_range<int>(0, rows, 16), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      cv::Vec3f* out = rgb.ptr<cv::Vec3f>(y);
      for (int x = 0; x < cols; ++x) {
        // Mean of each colour over the 3×3 neighbourhood (own value where the site has it):
        // bilinear interpolation on a Bayer mosaic.
        float sum[3] = {0, 0, 0};
        int count[3] = {0, 0, 0};
        const int own = cfaColor(cfa, y, x);
        for (int dy = -1; dy <= 1; ++dy) {
          const int yy = y + dy;
          if (yy < 0 || yy >= rows) continue;
          const float* m = mosaic.ptr<float>(yy);
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx;
            if (xx < 0 || xx >= cols) continue;
            const int c = cfaColor(cfa, yy, xx);
            // Green at a green site: its own value (the diagonal greens would blur it).
            if (c == own && (dx != 0 || dy != 0)) continue;
            sum[c] += m[xx];
            ++count[c];
          }
        }
        for (int c = 0; c < 3; ++c) out[x][c] = count[c] ? sum[c] / count[c] : 0.0f;
      }
    }
  });
  return rgb;
}

ExrImage mergedToExr(const MergeResult& result, const FrameMetadata& metadata) {
  ExrImage image;
  image.layers.push_back({"", demosaicBilinear(result.merged, result.cfa)});
  cv::Mat mask;
  if (result.cfa == Cfa::kMono) {
    result.saturated.convertTo(mask, CV_32F);
  } else {
    // A demosaiced pixel draws on its 3×3 neighbourhood: flag it when any of those is flagged.
    cv::Mat dilated;
    cv::dilate(result.saturated, dilated, cv::Mat::ones(3, 3, CV_8U));
    dilated.convertTo(mask, CV_32F);
  }
  image.layers.push_back({"saturated", mask});
  auto& a = image.attributes;
  if (metadata.has_angle) a["flarekit.angle_deg"] = metadata.angle_deg;
  if (!metadata.exposures_s.empty()) {
    a["flarekit.exposure_s"] =
        *std::max_element(metadata.exposures_s.begin(), metadata.exposures_s.end());
    a["flarekit.exposures_s"] =
        std::vector<float>(metadata.exposures_s.begin(), metadata.exposures_s.end());
  }
  if (metadata.iso > 0) a["flarekit.iso"] = metadata.iso;
  if (metadata.f_number > 0) a["flarekit.f_number"] = metadata.f_number;
  if (!metadata.camera.empty()) a["flarekit.camera"] = metadata.camera;
  if (!metadata.lens.empty()) a["flarekit.lens"] = metadata.lens;
  if (!metadata.rig.empty()) a["flarekit.rig"] = metadata.rig;
  if (metadata.pixel_pitch_um > 0) a["flarekit.pixel_pitch_um"] = metadata.pixel_pitch_um;
  if (metadata.focal_length_mm > 0) a["flarekit.focal_length_mm"] = metadata.focal_length_mm;
  a["flarekit.units"] = metadata.units;
  a["flarekit.cfa"] = std::string(cfaName(result.cfa));
  a["flarekit.saturated_count"] = static_cast<int>(std::min<long long>(result.saturated_count, INT32_MAX));
  return image;
}

}  // namespace flarekit::acquisition
