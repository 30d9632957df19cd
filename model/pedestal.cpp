#include "model/pedestal.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace flarekit::model {

std::array<double, kPedestalTerms> pedestalTerms(cv::Point2d p, cv::Size capture_size) {
  const double w = capture_size.width;
  const double u = (p.x - 0.5 * w) / w, v = (p.y - 0.5 * capture_size.height) / w;
  return {1, u, v, u * u, u * v, v * v};
}

std::string pedestalTermName(int index, int channels) {
  static const char* const kNames[kPedestalTerms] = {"P00", "P10", "P01", "P20", "P11", "P02"};
  static const char* const kChannels[3] = {"_R", "_G", "_B"};
  if (index < 0 || index >= kPedestalTerms * channels)
    throw std::out_of_range("pedestal term index");
  std::string name = kNames[index % kPedestalTerms];
  if (channels == 3) name += kChannels[index / kPedestalTerms];
  return name;
}

std::vector<std::string> pedestalTermNames(int channels) {
  std::vector<std::string> names;
  for (int k = 0; k < kPedestalTerms * channels; ++k)
    names.push_back(pedestalTermName(k, channels));
  return names;
}

double Pedestal::at(cv::Point2d p, cv::Size capture_size, int channel) const {
  if (empty()) return 0;
  const cv::Point2d q(std::clamp(p.x, 0.0, double(capture_size.width)),
                      std::clamp(p.y, 0.0, double(capture_size.height)));
  const auto t = pedestalTerms(q, capture_size);
  double value = 0;
  for (int k = 0; k < kPedestalTerms; ++k)
    value += coefficients[channel * kPedestalTerms + k] * t[k];
  return value;
}

void Pedestal::addTo(cv::Mat& image, cv::Size capture_size, const ViewTransform& view) const {
  if (empty()) return;
  if (image.type() != CV_32FC(channels))
    throw std::invalid_argument("pedestal: image type does not match its channels");
  // at(view.modelFromImage(pixel centre), c) for every pixel and channel, in the same arithmetic
  // (so to the bit), with the view's cosine and sine and each pixel's terms computed once.
  const double cs = std::cos(view.roll_rad), sn = std::sin(view.roll_rad);
  const double w = capture_size.width, h = capture_size.height;
  for (int y = 0; y < image.rows; ++y) {
    float* row = image.ptr<float>(y);
    const double my = (y + 0.5 - view.image_center.y) / view.scale;
    for (int x = 0; x < image.cols; ++x) {
      const double mx = (x + 0.5 - view.image_center.x) / view.scale;
      const cv::Point2d q(std::clamp(view.model_center.x + cs * mx - sn * my, 0.0, w),
                          std::clamp(view.model_center.y + sn * mx + cs * my, 0.0, h));
      const auto t = pedestalTerms(q, capture_size);
      for (int c = 0; c < channels; ++c) {
        double value = 0;
        for (int k = 0; k < kPedestalTerms; ++k) value += coefficients[c * kPedestalTerms + k] * t[k];
        float& v = row[x * channels + c];
        v = std::max(0.0f, v + static_cast<float>(value));
      }
    }
  }
}

cv::Mat Pedestal::image(cv::Size capture_size) const {
  cv::Mat out = cv::Mat::zeros(capture_size, CV_32FC(channels));
  if (empty()) return out;
  for (int y = 0; y < capture_size.height; ++y) {
    float* row = out.ptr<float>(y);
    for (int x = 0; x < capture_size.width; ++x)
      for (int c = 0; c < channels; ++c)
        row[x * channels + c] = static_cast<float>(at({x + 0.5, y + 0.5}, capture_size, c));
  }
  return out;
}

}  // namespace flarekit::model
