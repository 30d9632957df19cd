#include "render/aperture.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace flarekit::render {

bool ApertureShape::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (kind == ApertureKind::kPolygon && (blades < 3 || blades > 32))
    return fail("aperture blades must be 3..32, got " + std::to_string(blades));
  if (!(rounding >= 0.0 && rounding <= 1.0)) return fail("aperture rounding must be in [0, 1]");
  if (!std::isfinite(rotation_deg)) return fail("aperture rotation must be finite");
  if (kind == ApertureKind::kMask) {
    if (mask.empty()) return fail("mask aperture needs a mask image");
    if (mask.channels() != 1 || (mask.depth() != CV_8U && mask.depth() != CV_32F))
      return fail("aperture mask must be a one-channel 8-bit or float image");
  }
  return true;
}

Aperture::Aperture(const ApertureShape& shape) : shape_(shape) {
  if (shape.kind == ApertureKind::kPolygon) {
    const int n = std::clamp(shape.blades, 3, kMaxEdges);
    const double rot = shape.rotation_deg * M_PI / 180.0;
    apothem_ = static_cast<float>(std::cos(M_PI / n));
    edges_ = n;
    rounding_ = static_cast<float>(shape.rounding);
    for (int k = 0; k < n; ++k) {
      // Vertices at rot + 2πk/n on the unit circle; edge normals halfway between them.
      const double a = rot + M_PI / n + 2.0 * M_PI * k / n;
      edge_nx_[k] = static_cast<float>(std::cos(a));
      edge_ny_[k] = static_cast<float>(std::sin(a));
    }
  } else if (shape.kind == ApertureKind::kMask) {
    if (shape.mask.depth() == CV_8U)
      shape.mask.convertTo(mask_, CV_32F, 1.0 / 255.0);
    else
      mask_ = shape.mask.clone();
    cv::max(mask_, 0.0, mask_);
    cv::min(mask_, 1.0, mask_);
  }
  if (shape.kind != ApertureKind::kMask) {
    const float inner = apothem_ * (1.0f - 1e-4f);
    inner_radius2_ = inner * inner;
  }
}

float Aperture::transmission(float u, float v) const {
  if (shape_.kind != ApertureKind::kMask) {
    // Well inside the inscribed circle (radius = apothem ≤ 1; the margin dwarfs float rounding)
    // every distance function is positive: no need to evaluate the blades.
    if (u * u + v * v < inner_radius2_) return 1.0f;
    return signedDistance(u, v) >= 0.0f ? 1.0f : 0.0f;
  }
  // Bilinear lookup; the mask covers [−1, 1]², pixel centres at (i + 0.5).
  const float fx = (u + 1.0f) * 0.5f * mask_.cols - 0.5f;
  const float fy = (v + 1.0f) * 0.5f * mask_.rows - 0.5f;
  if (!(fx > -1.0f && fy > -1.0f && fx < mask_.cols && fy < mask_.rows)) return 0.0f;
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  const float wx = fx - x0, wy = fy - y0;
  auto at = [&](int x, int y) {
    if (x < 0 || y < 0 || x >= mask_.cols || y >= mask_.rows) return 0.0f;
    return mask_.at<float>(y, x);
  };
  return (1 - wy) * ((1 - wx) * at(x0, y0) + wx * at(x0 + 1, y0)) +
         wy * ((1 - wx) * at(x0, y0 + 1) + wx * at(x0 + 1, y0 + 1));
}

cv::Mat Aperture::raster(int size) const {
  cv::Mat out(size, size, CV_32FC1);
  const float footprint = 2.0f / size;
  for (int j = 0; j < size; ++j)
    for (int i = 0; i < size; ++i) {
      const float u = -1.0f + (i + 0.5f) * 2.0f / size;
      const float v = -1.0f + (j + 0.5f) * 2.0f / size;
      out.at<float>(j, i) = coverage(u, v, footprint);
    }
  return out;
}

}  // namespace flarekit::render
