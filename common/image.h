#pragma once
// Image conventions (docs/design.md): cv::Mat CV_32FC1 (luminance) or CV_32FC3 (linear R,G,B
// in memory order), linear radiance, x right, y down, pixel (i, j) centred at (i + 0.5, j + 0.5).
// Pictures for people (PNG previews) are the only gamma-encoded images, made here.

#include <filesystem>

#include <opencv2/core.hpp>

namespace flarekit {

// Rec. 709 luminance weights of linear R, G, B.
inline constexpr double kLuminanceR = 0.2126, kLuminanceG = 0.7152, kLuminanceB = 0.0722;

// Rec. 709 luminance of a CV_32FC3 (R,G,B) image; a CV_32FC1 image is returned as is.
cv::Mat luminance(const cv::Mat& image);

// Rec. 709 luminance of `channels` values (1: the value itself, 3: R, G, B).
inline double luminance(const double* values, int channels) {
  return channels == 3 ? kLuminanceR * values[0] + kLuminanceG * values[1] + kLuminanceB * values[2]
                       : values[0];
}

struct PreviewOptions {
  // Exposure adjustment in stops on top of the automatic exposure (0 = automatic only).
  double exposure_ev = 0.0;
  // Percentile of the non-zero luminance that is mapped to mid-grey by the automatic exposure;
  // high percentiles keep bright ghosts from clipping.
  double key_percentile = 90.0;
  // Fixed linear scale instead of the automatic exposure when > 0 (for series that must match).
  double fixed_scale = 0.0;

  bool IsValid(std::string* error) const;
};

// Tone-maps linear radiance to an 8-bit BGR image (OpenCV's order, for cv::imwrite): automatic
// exposure, Reinhard's x / (1 + x), sRGB encoding. Non-finite pixels show magenta.
cv::Mat tonemapForDisplay(const cv::Mat& linear, const PreviewOptions& options = {});

// The scale the automatic exposure would use for `linear` (for matching a series of previews).
double autoExposureScale(const cv::Mat& linear, const PreviewOptions& options = {});

// Writes an 8-bit image (PNG chosen by the extension) atomically.
void writeImage8(const std::filesystem::path& path, const cv::Mat& image8);

// Tone-maps and writes a PNG preview atomically.
void writePreviewPng(const std::filesystem::path& path, const cv::Mat& linear,
                     const PreviewOptions& options = {});

}  // namespace flarekit
