#pragma once
// The light's own image: the starburst (Hullin 2011 §3.3). The Fraunhofer diffraction pattern of
// the iris is the power spectrum of its transmission, |FFT(aperture)|²; it scales linearly with
// the wavelength, so each wavelength's copy is stretched by λ / 550 nm and the copies are summed
// with their colour weights. The pattern carries the whole directly transmitted flux.
//
// A single wavelength's pattern rings radially: the iris's diffraction fringes, here 4 bins apart
// (the iris spans a quarter of the FFT). A real light's spectrum blurs them out, and Hullin sums
// copies at 5 nm steps for that (§3.3, "sufficiently fine to blur out the radial ringing present
// in the individual spectral terms"). Each traced wavelength therefore draws the band it stands
// for (render/spectrum.h sampleBand), not its single wavelength: rendered at 650/510/475 nm alone,
// a 6-blade starburst was a hexagon of dots with a hard red rim where the fringes of the longest
// wavelength ended.

#include <span>

#include <opencv2/core.hpp>

#include "render/aperture.h"
#include "render/spectrum.h"

namespace flarekit::render {

// The normalised (sum 1) centred power spectrum of the aperture: CV_32FC1, fft_size², the iris
// rasterised at fft_size / 4 pixels across and zero-padded (cv::dft).
cv::Mat starburstPattern(const Aperture& aperture, int fft_size = 256);

// The pattern of a band of wavelengths: copies of `pattern` (at the scale of some wavelength λ₀)
// stretched by λ / λ₀, weighted and summed; normalised to sum 1. The result is at the scale of the
// band's longest wavelength, returned in *scale_nm (its half-width spans the pattern's half-width
// at that wavelength): every copy is then shrunk, never cut at the border. Same size and type as
// `pattern`; an empty band gives an empty image.
cv::Mat starburstBand(const cv::Mat& pattern, std::span<const BandWavelength> band, double* scale_nm);

// Adds `flux_px` (relative irradiance × pixels: the value sum the spot must have) of the pattern
// times `weight` to `image` (CV_32FC3), centred at `center_px`, the pattern's half-width
// (fft_size / 2 bins) spanning `radius_px` pixels. Energy is kept when the pattern is shrunk
// below one bin per pixel (area resampling).
void addStarburst(const cv::Mat& pattern, cv::Point2d center_px, double radius_px,
                  double flux_px, const cv::Vec3f& weight, cv::Mat* image);

// Adds a soft halo of total value `flux_px` × weight: a radial profile (1 + (r/r_h)²)^(−3/2)
// with r_h = radius_px, cut at 4 r_h and normalised over the pixels drawn.
void addHalo(cv::Point2d center_px, double radius_px, double flux_px, const cv::Vec3f& weight,
             cv::Mat* image);

}  // namespace flarekit::render
