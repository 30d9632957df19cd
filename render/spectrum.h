#pragma once
// Wavelength sampling and colour (DESIGN "Spectral"): the RGB mode traces 650, 510 and 475 nm
// into R, G and B; the spectral mode traces N wavelengths over 380–780 nm and integrates them
// with the CIE 1931 2° colour-matching functions into XYZ, then linear sRGB (IEC 61966-2-1
// matrix, D65). Normalisation: a spectrally flat light of relative irradiance 1 gives Y = 1.

#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::render {

struct SpectralSample {
  double wavelength_nm = 550.0;
  cv::Vec3f rgb_weight;  // contribution of this wavelength's render to linear R, G, B
};

// spectral_samples = 0: the three RGB-mode wavelengths, weights (1,0,0), (0,1,0), (0,0,1).
// N ≥ 3: N wavelengths at the centres of N equal bins over 380–780 nm.
std::vector<SpectralSample> spectralSamples(int spectral_samples);

// CIE 1931 2° colour-matching functions (x̄, ȳ, z̄) at `wavelength_nm`, linearly interpolated
// from the standard's table at 10 nm steps (CIE 015:2004 Table T.4, every second row); 0 outside
// 380–780 nm.
cv::Vec3d cieColorMatching(double wavelength_nm);

// XYZ → linear sRGB (IEC 61966-2-1).
cv::Vec3d xyzToLinearSrgb(const cv::Vec3d& xyz);

// One wavelength of the band a sample stands for, and its relative weight.
struct BandWavelength {
  double wavelength_nm = 550.0;
  double weight = 1.0;
};

// The wavelengths sample `index` of spectralSamples(spectral_samples) stands for, every `step_nm`,
// with relative weights: in the RGB mode its channel's colour-matching function in linear sRGB
// (the positive part) over 380–780 nm, in the spectral mode its bin, evenly (at least the
// sample's own wavelength). What a single traced wavelength cannot show and a band can: the
// starburst's radial ringing, which blurs out over a real light's spectrum (Hullin 2011 §3.3).
std::vector<BandWavelength> sampleBand(int spectral_samples, int index, double step_nm = 5.0);

}  // namespace flarekit::render
