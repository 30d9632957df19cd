#include "common/image.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/atomic_file.h"
#include "common/error.h"

namespace flarekit {

cv::Mat luminance(const cv::Mat& image) {
  if (image.type() == CV_32FC1) return image;
  CV_Assert(image.type() == CV_32FC3);
  cv::Mat y;
  cv::transform(image, y, cv::Matx13f(kLuminanceR, kLuminanceG, kLuminanceB));
  return y;
}

bool PreviewOptions::IsValid(std::string* error) const {
  if (!std::isfinite(exposure_ev)) {
    if (error) *error = "exposure_ev must be finite";
    return false;
  }
  if (!(key_percentile > 0 && key_percentile < 100)) {
    if (error) *error = "key_percentile must be in (0, 100)";
    return false;
  }
  if (!(fixed_scale >= 0) || !std::isfinite(fixed_scale)) {
    if (error) *error = "fixed_scale must be >= 0";
    return false;
  }
  return true;
}

double autoExposureScale(const cv::Mat& linear, const PreviewOptions& options) {
  cv::Mat y = luminance(linear);
  std::vector<float> values;
  values.reserve(y.total());
  for (int r = 0; r < y.rows; ++r) {
    const float* p = y.ptr<float>(r);
    for (int c = 0; c < y.cols; ++c)
      if (std::isfinite(p[c]) && p[c] > 0) values.push_back(p[c]);
  }
  if (values.empty()) return 1.0;
  size_t k = std::min(values.size() - 1,
                      static_cast<size_t>(options.key_percentile / 100.0 * double(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<long>(k), values.end());
  double key = values[k];
  return key > 0 ? 0.18 / key : 1.0;
}

cv::Mat tonemapForDisplay(const cv::Mat& linear, const PreviewOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw std::invalid_argument("PreviewOptions: " + why);
  CV_Assert(linear.type() == CV_32FC1 || linear.type() == CV_32FC3);
  double scale = options.fixed_scale > 0 ? options.fixed_scale : autoExposureScale(linear, options);
  scale *= std::exp2(options.exposure_ev);
  cv::Mat rgb;
  if (linear.channels() == 1)
    cv::cvtColor(linear, rgb, cv::COLOR_GRAY2RGB);
  else
    rgb = linear;
  cv::Mat out(linear.size(), CV_8UC3);
  auto encode = [](double v) {
    v = v / (1.0 + v);  // Reinhard
    v = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
    return static_cast<uint8_t>(std::clamp(std::lround(255.0 * v), 0L, 255L));
  };
  for (int r = 0; r < rgb.rows; ++r) {
    const cv::Vec3f* src = rgb.ptr<cv::Vec3f>(r);
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(r);
    for (int c = 0; c < rgb.cols; ++c) {
      const cv::Vec3f& p = src[c];
      if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
        dst[c] = cv::Vec3b(255, 0, 255);
        continue;
      }
      // BGR order for OpenCV's writers.
      dst[c] = cv::Vec3b(encode(std::max(0.0, p[2] * scale)), encode(std::max(0.0, p[1] * scale)),
                         encode(std::max(0.0, p[0] * scale)));
    }
  }
  return out;
}

void writeImage8(const std::filesystem::path& path, const cv::Mat& image8) {
  writeFileAtomically(path, [&](const std::filesystem::path& temporary) {
    bool ok = false;
    try {
      ok = cv::imwrite(temporary.string(), image8);
    } catch (const cv::Exception& e) {
      throw RuntimeError("cannot write " + path.string() + ": " + e.what());
    }
    if (!ok)
      throw RuntimeError("cannot write " + path.string() +
                         ": OpenCV could not encode it (is the extension .png?)");
  });
}

void writePreviewPng(const std::filesystem::path& path, const cv::Mat& linear,
                     const PreviewOptions& options) {
  writeImage8(path, tonemapForDisplay(linear, options));
}

}  // namespace flarekit
