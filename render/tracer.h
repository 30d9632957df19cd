#pragma once
// Bundle tracing (Hullin 2011 §3.2, DESIGN "Bundle tracing"): a regular grid of parallel rays
// from the plane of the first vertex (z = 0) is walked through a fixed sequence of surface events
// (render/ghosts.h). Spheres are intersected on their vertex-side hemisphere, extended past their
// rims, with negative ray parameters allowed. A ray that misses a sphere or meets total internal
// reflection is not part of the ghost: it gets r_rel > 1 (so the rasterizer shows nothing there)
// but goes on (from the vertex plane, or undeviated) so that the grid cells across those edges
// are clipped by interpolation rather than lost whole; rays are dropped only when they cannot
// reach the sensor. Each ray keeps
// r_rel = max r / semi-aperture over the surfaces it meets, its aperture coordinates (u, v) at the
// first stop crossing (stop semi-aperture = 1), its transmission and its sensor position.

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "render/coating.h"
#include "render/ghosts.h"
#include "render/lens.h"

namespace flarekit::render {

// Reflectance of every surface at one wavelength as a function of cos(incidence), sampled for
// fast lookup (the curves are smooth; 1/64 steps in cos θ keep errors below 1e-4 away from the
// critical angle).
class ReflectanceTables {
 public:
  static constexpr int kSamples = 129;
  ReflectanceTables() = default;  // no surfaces (for assigning to)
  ReflectanceTables(const Lens& lens, const std::vector<SurfaceCoating>& coatings,
                    double wavelength_nm);
  // R(cos θ) of surface i for light arriving travelling forward (from the object side) or back.
  const float* table(int surface, bool forward) const {
    return &values_[(static_cast<size_t>(surface) * 2 + (forward ? 0 : 1)) * kSamples];
  }
  static float lookup(const float* table, double cos_incidence);

 private:
  std::vector<float> values_;
};

struct CompiledEvent {
  double z = 0.0;          // vertex position
  double radius = 0.0;     // 0 = flat
  double inv_radius = 0.0; // 1 / radius (0 when flat): the unit normal by multiplication
  double inv_semi = 0.0;   // 1 / semi-aperture (r_rel)
  EventKind kind = EventKind::kRefract;
  double eta = 1.0;        // n_before / n_after (refraction)
  const float* reflectance = nullptr;  // R(cos θ) table for this surface and direction
};

// One path at one wavelength, ready to trace.
struct CompiledPath {
  std::vector<CompiledEvent> events;
  double z_sensor = 0.0;
  double stop_semi_mm = 1.0;
  double wavelength_nm = 0.0;
};
CompiledPath compilePath(const Lens& lens, const std::vector<PathEvent>& path,
                         double wavelength_nm, const ReflectanceTables& tables);

// Unit direction of a distant light (render/flare_renderer.h convention): θ > 0 images towards
// −x, the roll φ turns it about the axis.
cv::Vec3d lightDirection(double angle_rad, double roll_rad);

// A square grid of n×n ray origins in the z = 0 plane, nodes at centre ± half_size.
struct RayGrid {
  double center_x_mm = 0.0, center_y_mm = 0.0, half_size_mm = 1.0;
  int n = 2;
  double spacing_mm() const { return 2.0 * half_size_mm / (n - 1); }
};

// Traced rays (struct of arrays, row-major over the grid: index = j·n + i, x along i).
struct TracedRays {
  int n = 0;
  std::vector<float> x_mm, y_mm;  // sensor position
  std::vector<float> u, v;        // aperture coordinates at the first stop crossing
  std::vector<float> r_rel;       // max r / semi-aperture (stop crossings after the first count too)
  std::vector<float> transmission;
  // 0 = never reached the sensor (parallel to a plane it had to cross, or not heading to the
  // sensor); such a ray has x = y = 0, transmission 0 and, if it died before the sensor,
  // u = v = 0 and r_rel = 1e6.
  std::vector<uint8_t> alive;
  void resize(int count);
  // Whether ray k passes every rim and the stop circle (r_rel ≤ 1, u² + v² ≤ 1, as floats).
  bool passes(size_t k) const {
    return alive[k] && r_rel[k] <= 1.0f && u[k] * u[k] + v[k] * v[k] <= 1.0f;
  }
};

// Traces `count` rays of direction `dir` from (x0[k], y0[k], 0).
void traceRays(const CompiledPath& path, const cv::Vec3d& dir, const double* x0, const double* y0,
               int count, TracedRays* out, int offset = 0);
// Traces a grid (out->n = grid.n). With `passing_only`, for callers that want only the rays that
// pass (TracedRays::passes): the others may be cut
// short and reported dead (no work for rays certain to be blocked); those that may pass get the
// same result as without.
void traceGrid(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid& grid,
               TracedRays* out, bool passing_only = false);
// Traces a grid for buildTriangles (render/raster.h): as traceGrid, but a ray that cannot pass
// (as with `passing_only`) and has no passing ray among its eight neighbours may be reported dead.
// No grid quad that shows part of the ghost has such a ray as a corner, and the quads next to
// those that do are told apart from them by their passing corners alone, so buildTriangles makes
// the same triangles and refines the same quads as from traceGrid.
void traceGridCorners(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid& grid,
                      TracedRays* out);
// Traces grids of one size (grids[g].n = n for all g) one after another, in full blocks:
// grid g's rays from index g·n² on (out->n = n). Each ray gets the same result as from traceGrid.
void traceGrids(const CompiledPath& path, const cv::Vec3d& dir, const std::vector<RayGrid>& grids,
                TracedRays* out);

// The point in the z = 0 plane from which a ray of direction `dir` passes the centre of the stop
// on `path` (found by Newton iteration on the real trace, started from the paraxial guess; each
// step halved until it lands on a ray that reaches the sensor). Returns false when the search
// finds no such ray: it is local, and may miss a ray that exists far from the guess.
bool findStopCenterRay(const CompiledPath& path, const cv::Vec3d& dir, double guess_x,
                       double guess_y, cv::Point2d* origin);
// The same for the ray through aperture coordinates (target_u, target_v) (stop semi-aperture = 1).
bool findStopRay(const CompiledPath& path, const cv::Vec3d& dir, double target_u,
                 double target_v, double guess_x, double guess_y, cv::Point2d* origin);

}  // namespace flarekit::render
