#pragma once
// The light's own image: the starburst (Hullin 2011 §3.3). The Fraunhofer diffraction pattern of
// the iris is the power spectrum of its transmission, |FFT(aperture)|²; it scales linearly with
// the wavelength, so each wavelength's copy is stretched by λ / 550 nm and the copies are summed
// with their colour weights. The pattern carries the whole directly transmitted flux.

#include <opencv2/core.hpp>

#include "render/aperture.h"

namespace flarekit::render {

// The normalised (sum 1) centred power spectrum of the aperture: CV_32FC1, fft_size², the iris
// rasterised at fft_size / 4 pixels across and zero-padded (cv::dft).
cv::Mat starburstPattern(const Aperture& aperture, int fft_size = 256);

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
