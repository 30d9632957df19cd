#pragma once
// The light's own image in an exposure short enough not to clip it (a capture's light exposure,
// acquisition/capture.h): where it is, its brightest pixel and its flux. The capture session
// records these in the manifest (the light's stability) and `flarekit metrics` measures the light
// with them (metrics/capture_metrics.h), so both read the light alike.
//
// The flux is the sum of the luminance over a disc about the light's centre, of radius
// lightFluxRadiusPx (an eighth of the image diagonal, the reach of the simulated starburst): the
// light's direct image and its near spread, not its far veil. Sums of noise are unbiased, so the
// disc needs no threshold.

#include <opencv2/core.hpp>

namespace flarekit {

struct LightSpot {
  bool found = false;              // the light's image is in the exposure
  cv::Point2d center{0, 0};        // luminance-weighted centroid of its half-maximum core (pixels
                                   // ≥ ½ peak, or clipped, connected to the brightest), image
                                   // pixels
  double peak = 0;                 // the brightest pixel's luminance (a lower bound if clipped)
  double flux = 0;                 // Σ luminance over the disc of flux_radius_px about center
  double flux_radius_px = 0;       // that disc's radius
  double half_max_radius_px = 0;   // radius of a disc of the half-maximum core's area
  bool cut = false;                // the disc leaves the image: flux is only part of the light's
  int saturated = 0;               // clipped pixels within the disc (peak and flux are then lower
                                   // bounds)
  double noise_sigma = 0;          // the exposure's pixel noise σ (neighbour differences)

  // Found, wholly inside the image and unclipped: a measurement of the whole light.
  bool whole() const { return found && !cut && saturated == 0; }
};

// An eighth of the image diagonal, pixels.
double lightFluxRadiusPx(cv::Size size);

// The light's image in `image` (CV_32FC1 luminance or CV_32FC3 linear R,G,B; luminance is used).
// `saturated` (CV_8U or CV_32F, non-zero = clipped; may be empty) marks clipped pixels. The light
// is found when its brightest pixel stands above 50 × the pixel noise σ (or clips); the flux disc
// has `flux_radius_px` (0: lightFluxRadiusPx(image size)).
LightSpot measureLightSpot(const cv::Mat& image, const cv::Mat& saturated = {},
                           double flux_radius_px = 0);

}  // namespace flarekit
