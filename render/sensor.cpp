#include "render/sensor.h"

#include <cmath>
#include <random>

#include <tbb/parallel_for.h>

#include "common/error.h"

namespace flarekit::render {
namespace {

// SplitMix64 (Steele, Lea & Flood 2014): decorrelated per-row seeds from one user seed, so rows
// can be drawn in parallel and the frame does not depend on the thread count.
uint64_t splitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

// What the pixel at (x, y) sees: luminance for mono sensors, one colour for RGGB.
inline float pixelRadiance(const cv::Mat& radiance, int x, int y, ColorFilter filter) {
  float value;
  if (radiance.channels() == 1) {
    value = radiance.at<float>(y, x);
  } else {
    const cv::Vec3f& c = radiance.at<cv::Vec3f>(y, x);
    if (filter == ColorFilter::kMono) {
      value = 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
    } else {
      const int channel = (y % 2 == 0) ? ((x % 2 == 0) ? 0 : 1) : ((x % 2 == 0) ? 1 : 2);
      value = c[channel];
    }
  }
  return std::isfinite(value) && value > 0.0f ? value : 0.0f;
}

void check(const cv::Mat& radiance, double exposure_s, const SensorModel& sensor) {
  std::string error;
  if (!sensor.IsValid(&error)) throw InputError("sensor model: " + error);
  if (radiance.empty()) throw InputError("sensor model: empty radiance image");
  if (radiance.depth() != CV_32F || (radiance.channels() != 1 && radiance.channels() != 3))
    throw InputError("sensor model: radiance must be CV_32FC1 or CV_32FC3");
  if (!(exposure_s >= 0) || !std::isfinite(exposure_s))
    throw InputError("sensor model: exposure time must be finite and ≥ 0");
}

}  // namespace

bool SensorModel::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (bit_depth < 8 || bit_depth > 16) return fail("bit depth must be 8..16");
  const double max_dn = std::ldexp(1.0, bit_depth) - 1.0;
  if (!(black_level_dn >= 0 && black_level_dn < max_dn)) return fail("black level must be in [0, 2^bits − 1)");
  if (!(white_level_dn == 0 || (white_level_dn > black_level_dn && white_level_dn <= max_dn)))
    return fail("white level must be 0 (= 2^bits − 1) or between the black level and 2^bits − 1");
  if (!(iso > 0 && base_iso > 0 && std::isfinite(iso) && std::isfinite(base_iso))) return fail("ISO values must be positive");
  if (!(base_gain_e_per_dn > 0 && std::isfinite(base_gain_e_per_dn))) return fail("gain must be positive (electrons per DN)");
  if (!(read_noise_e >= 0 && std::isfinite(read_noise_e))) return fail("read noise must be ≥ 0 electrons");
  if (!(full_well_e >= 0 && std::isfinite(full_well_e))) return fail("full well must be ≥ 0 (0 = unlimited)");
  if (!(electrons_per_unit_s >= 0 && std::isfinite(electrons_per_unit_s))) return fail("radiometric scale must be ≥ 0");
  return true;
}

double SensorModel::whiteLevelDn() const {
  return white_level_dn > 0 ? white_level_dn : std::ldexp(1.0, bit_depth) - 1.0;
}

cv::Mat expectedRaw(const cv::Mat& radiance, double exposure_s, const SensorModel& sensor) {
  check(radiance, exposure_s, sensor);
  cv::Mat out(radiance.size(), CV_32FC1);
  const double gain = sensor.gainEPerDn(), white = sensor.whiteLevelDn();
  const double scale = sensor.electrons_per_unit_s * exposure_s;
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x) {
      double e = pixelRadiance(radiance, x, y, sensor.color_filter) * scale;
      if (sensor.full_well_e > 0) e = std::min(e, sensor.full_well_e);
      out.at<float>(y, x) = static_cast<float>(std::min(white, e / gain + sensor.black_level_dn));
    }
  return out;
}

cv::Mat exposeRaw(const cv::Mat& radiance, double exposure_s, const SensorModel& sensor,
                  uint64_t seed) {
  check(radiance, exposure_s, sensor);
  cv::Mat out(radiance.size(), CV_16UC1);
  const double gain = sensor.gainEPerDn(), white = sensor.whiteLevelDn();
  const double scale = sensor.electrons_per_unit_s * exposure_s;
  tbb::parallel_for(0, radiance.rows, [&](int y) {
    std::mt19937_64 rng(splitMix(seed ^ splitMix(static_cast<uint64_t>(y) + 1)));
    std::normal_distribution<double> gauss(0.0, 1.0);
    auto* row = out.ptr<uint16_t>(y);
    for (int x = 0; x < radiance.cols; ++x) {
      double mean = pixelRadiance(radiance, x, y, sensor.color_filter) * scale;
      // A full pixel holds no more; clipping the mean first keeps the draw cheap and bounded.
      if (sensor.full_well_e > 0) mean = std::min(mean, sensor.full_well_e);
      double electrons = mean;
      if (sensor.shot_noise && mean > 0) {
        if (mean < 1e6) {
          std::poisson_distribution<long long> poisson(mean);
          electrons = static_cast<double>(poisson(rng));
        } else {
          // Poisson ≈ Normal(μ, μ) to far better than one DN at these counts.
          electrons = std::max(0.0, mean + std::sqrt(mean) * gauss(rng));
        }
        if (sensor.full_well_e > 0) electrons = std::min(electrons, sensor.full_well_e);
      }
      double dn = electrons / gain + sensor.black_level_dn;
      if (sensor.read_noise) dn += sensor.read_noise_e / gain * gauss(rng);
      dn = std::clamp(std::round(dn), 0.0, white);
      row[x] = static_cast<uint16_t>(dn);
    }
  });
  return out;
}

}  // namespace flarekit::render
