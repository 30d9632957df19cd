#pragma once
// The shape of the iris: a circle, an n-blade polygon with optional rounding, or a mask image
// (Hullin 2011 §3.2: the aperture is applied per pixel through the interpolated aperture
// coordinates (u, v) of each ray, normalised so the stop's semi-aperture is 1).

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace flarekit::render {

enum class ApertureKind { kCircle, kPolygon, kMask };

struct ApertureShape {
  ApertureKind kind = ApertureKind::kPolygon;  // default: a 6-blade iris, as most photo lenses
  int blades = 6;               // number of blades (kPolygon), 3..32
  // 0 = straight blades; 1 = a circle. Between them the polygon's corners are rounded: the shape
  // is the set of points whose polygon distance function blends to a circle (see aperture.cpp).
  double rounding = 0.0;
  double rotation_deg = 0.0;    // rotation of the polygon about the axis (in image coordinates)
  // kMask: CV_8UC1 or CV_32FC1 transmission image, 0..1 (or 0..255), covering the square
  // [−1, 1]² of aperture coordinates; row 0 at v = −1 (y down as images).
  cv::Mat mask;

  bool IsValid(std::string* error) const;
};

// Transmission (0..1) of the aperture at normalised aperture coordinates (u, v) (radius 1 = the
// stop's semi-aperture; the polygon is inscribed in the unit circle). Thread-safe.
class Aperture {
 public:
  explicit Aperture(const ApertureShape& shape);
  float transmission(float u, float v) const;
  // Signed distance to the edge in aperture units (> 0 inside) for circles and polygons (with
  // rounding: the blend of the polygon's and the circle's distance functions); masks have none.
  bool hasDistance() const { return shape_.kind != ApertureKind::kMask; }
  float signedDistance(float u, float v) const {
    const float circle = 1.0f - std::sqrt(u * u + v * v);
    if (shape_.kind == ApertureKind::kCircle) return circle;
    float m = -1e30f;
    for (int k = 0; k < edges_; ++k) m = std::max(m, u * edge_nx_[k] + v * edge_ny_[k]);
    const float polygon = apothem_ - m;
    return rounding_ == 0.0f ? polygon : (1.0f - rounding_) * polygon + rounding_ * circle;
  }
  // The polygon's edges (outward unit normals, distance from the centre), for culling.
  int edgeCount() const { return edges_; }
  float edgeNormalX(int k) const { return edge_nx_[k]; }
  float edgeNormalY(int k) const { return edge_ny_[k]; }
  float apothem() const { return apothem_; }
  float rounding() const { return rounding_; }
  // Antialiased transmission for a pixel whose footprint spans `footprint` aperture units:
  // clamp(0.5 + distance / footprint, 0, 1); masks are sampled bilinearly.
  float coverage(float u, float v, float footprint) const {
    if (shape_.kind == ApertureKind::kMask) return transmission(u, v);
    const float d = signedDistance(u, v);
    return std::clamp(0.5f + d / std::max(footprint, 1e-6f), 0.0f, 1.0f);
  }
  // A size×size image of the transmission over [−1, 1]² (for the starburst FFT and previews).
  cv::Mat raster(int size) const;
  const ApertureShape& shape() const { return shape_; }

 private:
  ApertureShape shape_;
  cv::Mat mask_;            // CV_32FC1, 0..1
  static constexpr int kMaxEdges = 32;
  float edge_nx_[kMaxEdges] = {}, edge_ny_[kMaxEdges] = {};  // outward polygon edge normals
  int edges_ = 0;
  float apothem_ = 1.0f;    // distance of the edges from the centre
  float rounding_ = 0.0f;
  float inner_radius2_ = 0.0f;  // (apothem·(1 − 1e-4))²: points within are surely inside
};

}  // namespace flarekit::render
