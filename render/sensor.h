#pragma once
// A camera sensor: turns a linear radiance image (render/flare_renderer.h units) and an exposure
// time into a RAW-like uint16 frame with photon shot noise, read noise, black level, quantisation
// and clipping (docs/design.md, "The physical renderer"). The acquisition layer's simulated
// camera uses it, so HDR merging sees realistic noise and saturation.
//
// Model, per pixel (EMVA 1288 style):
//   mean electrons  μ_e = radiance · electrons_per_unit_s · exposure_s   (clipped at full well)
//   electrons       e   ~ Poisson(μ_e)
//   DN              = round(e / gain_e_per_dn + N(0, read_noise_e / gain_e_per_dn) + black_level)
//   clipped to [0, white_level_dn]
// with gain_e_per_dn = base_gain_e_per_dn · base_iso / iso. Mono sensors see the luminance
// (Rec. 709 weights) of an RGB radiance; Bayer RGGB sensors see R at (even x, even y), G at
// (odd, even) and (even, odd), B at (odd, odd).

#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

namespace flarekit::render {

enum class ColorFilter { kMono, kBayerRggb };

struct SensorModel {
  int bit_depth = 14;               // ADC bits (8..16); the white level defaults to 2^bits − 1
  double black_level_dn = 512.0;    // offset added to every pixel, DN
  double white_level_dn = 0.0;      // saturation level in DN; 0 = 2^bit_depth − 1
  double iso = 100.0;               // ISO setting; gain scales with base_iso / iso
  double base_iso = 100.0;          // ISO at which base_gain_e_per_dn applies
  double base_gain_e_per_dn = 4.0;  // electrons per DN at base ISO (conversion gain)
  double read_noise_e = 3.0;        // Gaussian read noise, electrons RMS (before the gain)
  double full_well_e = 60000.0;     // electrons a pixel holds; 0 = unlimited
  // Radiometric scale: mean photo-electrons per second that a pixel collects at relative
  // irradiance 1 (render units). Folds in E_in, pixel area, quantum efficiency and photon energy.
  double electrons_per_unit_s = 1.0e7;
  ColorFilter color_filter = ColorFilter::kMono;
  bool shot_noise = true;  // Poisson photon noise (false: mean electrons, for tests)
  bool read_noise = true;  // Gaussian read noise

  bool IsValid(std::string* error) const;
  double gainEPerDn() const { return base_gain_e_per_dn * base_iso / iso; }
  double whiteLevelDn() const;
};

// One RAW frame: `radiance` CV_32FC1 or CV_32FC3 (R,G,B), non-negative (NaN counts as 0);
// returns CV_16UC1 of the same size. Deterministic for a given seed (same result on every
// machine and thread count); different seeds give independent noise. Throws InputError on
// invalid options, an empty image or a negative / non-finite exposure. Thread-safe.
cv::Mat exposeRaw(const cv::Mat& radiance, double exposure_s, const SensorModel& sensor,
                  uint64_t seed);

// The noise-free expectation of exposeRaw in DN (float, before quantisation, clipped at white):
// for HDR merge tests and camera models that want the mean. CV_32FC1.
cv::Mat expectedRaw(const cv::Mat& radiance, double exposure_s, const SensorModel& sensor);

}  // namespace flarekit::render
