#pragma once
// Paraxial ray-transfer (ABCD) matrices (Lee & Eisemann 2013 §3; lenses/README.md).
//
// State (y, w): height above the axis and slope dy/ds along the direction of travel. Matrices:
//   translation by an axial distance t:   [[1, t], [0, 1]]
//   refraction n1 → n2 at curvature c:    [[1, 0], [−σ (n2 − n1) c / n2, n1 / n2]]
//   reflection at curvature c:            [[1, 0], [2 σ c, 1]]
// with c = 1/R in the lens's global sign convention and σ = +1 travelling towards +z, −1 towards
// −z (a surface seen from behind has the opposite curvature). A ghost's matrix is the product
// along its event path (render/ghosts.h), from the plane of the first vertex (z = 0) to the
// sensor. The system is rotationally symmetric, so x and y use the same matrix.

#include <vector>

#include "render/ghosts.h"
#include "render/lens.h"

namespace flarekit::render {

struct RayMatrix {
  double a = 1.0, b = 0.0, c = 0.0, d = 1.0;
  // this · other: apply `other` first.
  RayMatrix operator*(const RayMatrix& o) const {
    return {a * o.a + b * o.c, a * o.b + b * o.d, c * o.a + d * o.c, c * o.b + d * o.d};
  }
};

// Axial position (mm from the first vertex) of every surface's vertex.
std::vector<double> vertexPositions(const Lens& lens);

struct PathMatrices {
  RayMatrix to_stop;    // z = 0 plane → first crossing of the stop plane
  bool crosses_stop = false;
  RayMatrix to_last;    // z = 0 plane → just after the last event
  RayMatrix to_sensor;  // z = 0 plane → sensor plane
};
PathMatrices pathMatrices(const Lens& lens, const std::vector<PathEvent>& path, double wavelength_nm);

// The direct path from the first to the last surface (no translation to the sensor).
RayMatrix systemMatrix(const Lens& lens, double wavelength_nm);
// The direct path from the z = 0 plane to the stop.
RayMatrix matrixToStop(const Lens& lens, double wavelength_nm);

// A ghost's paraxial image (Lee & Eisemann §3.2): the stop's image on the sensor. For a light
// with slopes (w_x, w_y) = (d_x/d_z, d_y/d_z), the ray through the stop centre lands at
// center_per_slope_mm · (w_x, w_y), and a ray through stop point s·(u, v) (s = stop semi-aperture,
// |(u, v)| ≤ 1) lands magnification · s · (u, v) away from it.
struct ParaxialGhost {
  double center_per_slope_mm = 0.0;  // B − A·B1/A1
  double magnification = 0.0;        // A / A1 (signed: negative = the aperture is flipped)
  double radius_mm = 0.0;            // |A / A1| · stop semi-aperture
  // Entrance side: where the stop-centre ray crosses z = 0 per unit slope (−B1/A1), and the radius
  // of the pupil region that passes the stop (s / |A1|).
  double pupil_center_per_slope_mm = 0.0;
  double pupil_radius_mm = 0.0;
  // Sensor irradiance per incident irradiance, ignoring Fresnel: 1/A² (pupil area → ghost area).
  double area_gain = 0.0;
  bool valid = false;  // false when the path never crosses the stop or A1 = 0
};
ParaxialGhost paraxialGhost(const Lens& lens, const std::vector<PathEvent>& path,
                            double wavelength_nm);

}  // namespace flarekit::render
