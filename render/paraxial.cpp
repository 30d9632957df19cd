#include "render/paraxial.h"

#include <cmath>

namespace flarekit::render {
namespace {

RayMatrix translation(double t) { return {1.0, t, 0.0, 1.0}; }

}  // namespace

std::vector<double> vertexPositions(const Lens& lens) {
  std::vector<double> z(lens.surfaces.size(), 0.0);
  for (size_t i = 1; i < lens.surfaces.size(); ++i) z[i] = z[i - 1] + lens.surfaces[i - 1].thickness_mm;
  return z;
}

PathMatrices pathMatrices(const Lens& lens, const std::vector<PathEvent>& path,
                          double wavelength_nm) {
  const std::vector<double> z = vertexPositions(lens);
  PathMatrices out;
  RayMatrix m;
  double z_prev = 0.0;
  for (const PathEvent& e : path) {
    const Surface& s = lens.surfaces[static_cast<size_t>(e.surface)];
    const double zi = z[static_cast<size_t>(e.surface)];
    m = translation(std::abs(zi - z_prev)) * m;
    z_prev = zi;
    const double sigma = e.forward ? 1.0 : -1.0;
    const double c = s.isFlat() ? 0.0 : 1.0 / s.radius_mm;
    switch (e.kind) {
      case EventKind::kStop:
        if (!out.crosses_stop) {
          out.to_stop = m;
          out.crosses_stop = true;
        }
        break;
      case EventKind::kReflect:
        m = RayMatrix{1.0, 0.0, 2.0 * sigma * c, 1.0} * m;
        break;
      case EventKind::kRefract: {
        const double n1 = lens.refractiveIndex(e.medium_before, wavelength_nm);
        const double n2 = lens.refractiveIndex(e.medium_after, wavelength_nm);
        m = RayMatrix{1.0, 0.0, -sigma * (n2 - n1) * c / n2, n1 / n2} * m;
        break;
      }
    }
  }
  out.to_last = m;
  const double z_sensor = z.back() + lens.sensor_distance_mm;
  out.to_sensor = translation(std::abs(z_sensor - z_prev)) * m;
  return out;
}

RayMatrix systemMatrix(const Lens& lens, double wavelength_nm) {
  return pathMatrices(lens, directPath(lens), wavelength_nm).to_last;
}

RayMatrix matrixToStop(const Lens& lens, double wavelength_nm) {
  return pathMatrices(lens, directPath(lens), wavelength_nm).to_stop;
}

ParaxialGhost paraxialGhost(const Lens& lens, const std::vector<PathEvent>& path,
                            double wavelength_nm) {
  const PathMatrices m = pathMatrices(lens, path, wavelength_nm);
  ParaxialGhost g;
  if (!m.crosses_stop || m.to_stop.a == 0.0) return g;
  const RayMatrix& s = m.to_stop;
  const RayMatrix& f = m.to_sensor;
  // Lee & Eisemann §3.2: rays of slope w entering at height y reach the stop at A1 y + B1 w and
  // the sensor at A y + B w. Eliminating y: sensor = (A/A1)·stop + (B − A B1/A1)·w.
  g.center_per_slope_mm = f.b - f.a * s.b / s.a;
  g.magnification = f.a / s.a;
  g.radius_mm = std::abs(g.magnification) * lens.stopSemiAperture_mm();
  g.pupil_center_per_slope_mm = -s.b / s.a;
  g.pupil_radius_mm = lens.stopSemiAperture_mm() / std::abs(s.a);
  g.area_gain = f.a != 0.0 ? 1.0 / (f.a * f.a) : 0.0;
  g.valid = true;
  return g;
}

}  // namespace flarekit::render
