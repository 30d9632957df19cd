#include "render/spectrum.h"

#include <algorithm>
#include <cmath>

namespace flarekit::render {
namespace {

// CIE 1931 2° standard colorimetric observer, 380–780 nm in 10 nm steps: x̄, ȳ, z̄
// (CIE 015:2004 Table T.4; public standard data).
constexpr double kCmf[][3] = {
    {0.001368, 0.000039, 0.006450},  // 380 nm
    {0.004243, 0.000120, 0.020050},  // 390 nm
    {0.014310, 0.000396, 0.067850},  // 400 nm
    {0.043510, 0.001210, 0.207400},  // 410 nm
    {0.134380, 0.004000, 0.645600},  // 420 nm
    {0.283900, 0.011600, 1.385600},  // 430 nm
    {0.348280, 0.023000, 1.747060},  // 440 nm
    {0.336200, 0.038000, 1.772110},  // 450 nm
    {0.290800, 0.060000, 1.669200},  // 460 nm
    {0.195360, 0.090980, 1.287640},  // 470 nm
    {0.095640, 0.139020, 0.812950},  // 480 nm
    {0.032010, 0.208020, 0.465180},  // 490 nm
    {0.004900, 0.323000, 0.272000},  // 500 nm
    {0.009300, 0.503000, 0.158200},  // 510 nm
    {0.063270, 0.710000, 0.078250},  // 520 nm
    {0.165500, 0.862000, 0.042160},  // 530 nm
    {0.290400, 0.954000, 0.020300},  // 540 nm
    {0.433450, 0.994950, 0.008750},  // 550 nm
    {0.594500, 0.995000, 0.003900},  // 560 nm
    {0.762100, 0.952000, 0.002100},  // 570 nm
    {0.916300, 0.870000, 0.001650},  // 580 nm
    {1.026300, 0.757000, 0.001100},  // 590 nm
    {1.062200, 0.631000, 0.000800},  // 600 nm
    {1.002600, 0.503000, 0.000340},  // 610 nm
    {0.854450, 0.381000, 0.000190},  // 620 nm
    {0.642400, 0.265000, 0.000050},  // 630 nm
    {0.447900, 0.175000, 0.000020},  // 640 nm
    {0.283500, 0.107000, 0.000000},  // 650 nm
    {0.164900, 0.061000, 0.000000},  // 660 nm
    {0.087400, 0.032000, 0.000000},  // 670 nm
    {0.046770, 0.017000, 0.000000},  // 680 nm
    {0.022700, 0.008210, 0.000000},  // 690 nm
    {0.011359, 0.004102, 0.000000},  // 700 nm
    {0.005790, 0.002091, 0.000000},  // 710 nm
    {0.002899, 0.001047, 0.000000},  // 720 nm
    {0.001440, 0.000520, 0.000000},  // 730 nm
    {0.000690, 0.000249, 0.000000},  // 740 nm
    {0.000332, 0.000120, 0.000000},  // 750 nm
    {0.000166, 0.000060, 0.000000},  // 760 nm
    {0.000083, 0.000030, 0.000000},  // 770 nm
    {0.000042, 0.000015, 0.000000},  // 780 nm
};
constexpr int kCmfCount = sizeof(kCmf) / sizeof(kCmf[0]);
constexpr double kCmfStart_nm = 380.0, kCmfStep_nm = 10.0;

}  // namespace

cv::Vec3d cieColorMatching(double wavelength_nm) {
  const double f = (wavelength_nm - kCmfStart_nm) / kCmfStep_nm;
  if (!(f >= 0.0 && f <= kCmfCount - 1)) return {0, 0, 0};
  const int k = std::min(static_cast<int>(f), kCmfCount - 2);
  const double w = f - k;
  return {kCmf[k][0] + w * (kCmf[k + 1][0] - kCmf[k][0]),
          kCmf[k][1] + w * (kCmf[k + 1][1] - kCmf[k][1]),
          kCmf[k][2] + w * (kCmf[k + 1][2] - kCmf[k][2])};
}

cv::Vec3d xyzToLinearSrgb(const cv::Vec3d& c) {
  // IEC 61966-2-1, D65 white.
  return {3.2406 * c[0] - 1.5372 * c[1] - 0.4986 * c[2],
          -0.9689 * c[0] + 1.8758 * c[1] + 0.0415 * c[2],
          0.0557 * c[0] - 0.2040 * c[1] + 1.0570 * c[2]};
}

std::vector<SpectralSample> spectralSamples(int n) {
  if (n <= 0)
    return {{650.0, {1.f, 0.f, 0.f}}, {510.0, {0.f, 1.f, 0.f}}, {475.0, {0.f, 0.f, 1.f}}};
  const double lo = 380.0, hi = 780.0, step = (hi - lo) / n;
  std::vector<SpectralSample> out;
  double y_sum = 0.0;
  for (int k = 0; k < n; ++k) {
    const double l = lo + (k + 0.5) * step;
    y_sum += cieColorMatching(l)[1] * step;
  }
  for (int k = 0; k < n; ++k) {
    const double l = lo + (k + 0.5) * step;
    // Riemann sum of ∫ S(λ) x̄(λ) dλ, normalised so a flat S = 1 gives Y = 1.
    const cv::Vec3d xyz = cieColorMatching(l) * (step / y_sum);
    const cv::Vec3d rgb = xyzToLinearSrgb(xyz);
    out.push_back({l, cv::Vec3f(static_cast<float>(rgb[0]), static_cast<float>(rgb[1]),
                                static_cast<float>(rgb[2]))});
  }
  return out;
}

std::vector<BandWavelength> sampleBand(int spectral_samples, int index, double step_nm) {
  const double lo = 380.0, hi = 780.0;
  std::vector<BandWavelength> band;
  if (spectral_samples <= 0) {
    for (double l = lo; l <= hi + 1e-9; l += step_nm) {
      const double w = xyzToLinearSrgb(cieColorMatching(l))[index];
      if (w > 0) band.push_back({l, w});
    }
    return band;
  }
  const double bin = (hi - lo) / spectral_samples, b0 = lo + index * bin;
  const int steps = std::max(1, static_cast<int>(std::floor(bin / step_nm)));
  for (int k = 0; k < steps; ++k) band.push_back({b0 + (k + 0.5) * bin / steps, 1.0});
  return band;
}

}  // namespace flarekit::render
