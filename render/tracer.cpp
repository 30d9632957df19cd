#include "render/tracer.h"

#include <algorithm>
#include <cmath>

#include "render/paraxial.h"

namespace flarekit::render {

ReflectanceTables::ReflectanceTables(const Lens& lens, const std::vector<SurfaceCoating>& coatings,
                                     double wavelength_nm)
    : values_(lens.surfaces.size() * 2 * kSamples, 0.0f) {
  for (size_t i = 0; i < lens.surfaces.size(); ++i) {
    if (lens.surfaces[i].is_stop) continue;
    const double n_front = lens.refractiveIndex(static_cast<int>(i) - 1, wavelength_nm);
    const double n_back = lens.refractiveIndex(static_cast<int>(i), wavelength_nm);
    for (int dir = 0; dir < 2; ++dir) {
      const double n1 = dir == 0 ? n_front : n_back;
      const double n2 = dir == 0 ? n_back : n_front;
      float* t = &values_[(i * 2 + static_cast<size_t>(dir)) * kSamples];
      for (int k = 0; k < kSamples; ++k) {
        const double cos_i = static_cast<double>(k) / (kSamples - 1);
        t[k] = static_cast<float>(coatings[i].reflectance(n1, n2, wavelength_nm, cos_i));
      }
    }
  }
}

float ReflectanceTables::lookup(const float* table, double cos_incidence) {
  const double f = std::clamp(cos_incidence, 0.0, 1.0) * (kSamples - 1);
  const int k = std::min(static_cast<int>(f), kSamples - 2);
  const double w = f - k;
  return static_cast<float>(table[k] + w * (table[k + 1] - table[k]));
}

CompiledPath compilePath(const Lens& lens, const std::vector<PathEvent>& path,
                         double wavelength_nm, const ReflectanceTables& tables) {
  const std::vector<double> z = vertexPositions(lens);
  CompiledPath out;
  out.wavelength_nm = wavelength_nm;
  out.z_sensor = z.back() + lens.sensor_distance_mm;
  out.stop_semi_mm = lens.stopSemiAperture_mm();
  for (const PathEvent& e : path) {
    const Surface& s = lens.surfaces[static_cast<size_t>(e.surface)];
    CompiledEvent c;
    c.z = z[static_cast<size_t>(e.surface)];
    c.radius = s.radius_mm;
    c.inv_semi = 1.0 / s.semi_aperture_mm;
    c.kind = e.kind;
    c.eta = lens.refractiveIndex(e.medium_before, wavelength_nm) /
            lens.refractiveIndex(e.medium_after, wavelength_nm);
    c.reflectance = e.kind == EventKind::kStop ? nullptr : tables.table(e.surface, e.forward);
    out.events.push_back(c);
  }
  return out;
}

cv::Vec3d lightDirection(double angle_rad, double roll_rad) {
  // Positive roll turns the light's image counter-clockwise as displayed (y down), the sense of
  // model/'s ViewTransform and predict/'s geometry, so that one φ means one direction everywhere.
  const double s = std::sin(angle_rad);
  return {-s * std::cos(roll_rad), s * std::sin(roll_rad), std::cos(angle_rad)};
}

void TracedRays::resize(int count) {
  const auto c = static_cast<size_t>(count);
  x_mm.assign(c, 0.f);
  y_mm.assign(c, 0.f);
  u.assign(c, 0.f);
  v.assign(c, 0.f);
  r_rel.assign(c, 0.f);
  transmission.assign(c, 0.f);
  alive.assign(c, 0);
}

namespace {

// Rays are traced in blocks, each event applied to the whole block in one loop over rays (struct
// of arrays, branch-light so that the compiler can vectorise the arithmetic).
constexpr int kBlock = 64;

// Slope β of the validity margins folded into r_rel (total internal reflection, missed spheres).
constexpr double kValidityScale = 4.0;

struct Block {
  double px[kBlock], py[kBlock], pz[kBlock];
  double dx[kBlock], dy[kBlock], dz[kBlock];
  double t[kBlock], rr[kBlock], u[kBlock], v[kBlock];
  bool alive[kBlock], stop_seen[kBlock];
};

void applyEvent(const CompiledEvent& e, Block& b, int count) {
  const bool flat = e.radius == 0.0;
  const double R = e.radius;
  const double cz = e.z + R;  // centre of the sphere
  for (int k = 0; k < count; ++k) {
    if (!b.alive[k]) continue;
    double s;
    double nx = 0.0, ny = 0.0, nz = 1.0;
    bool flat_here = flat;
    if (flat) {
      if (std::abs(b.dz[k]) < 1e-12) {
        b.alive[k] = false;
        continue;
      }
      s = (e.z - b.pz[k]) / b.dz[k];
    } else {
      // |o + s d|² = R² with o = p − C; the root on the vertex side, (z − C_z)·R < 0.
      const double ox = b.px[k], oy = b.py[k], oz = b.pz[k] - cz;
      const double bb = ox * b.dx[k] + oy * b.dy[k] + oz * b.dz[k];
      const double cc = ox * ox + oy * oy + oz * oz - R * R;
      const double disc = bb * bb - cc;
      if (disc < 0.0) {
        // Missed the sphere: the ray passes outside every rim (r > |R| > semi-aperture), so it is
        // not part of the ghost. Rather than dropping it (and with it every grid cell it
        // touches), it goes on from the vertex plane with r_rel past |R|/semi-aperture, growing
        // with the miss distance, so cells across the edge are clipped by interpolation.
        if (std::abs(b.dz[k]) < 1e-12) {
          b.alive[k] = false;
          continue;
        }
        s = (e.z - b.pz[k]) / b.dz[k];
        flat_here = true;
        b.rr[k] = std::max(b.rr[k], std::abs(R) * e.inv_semi - kValidityScale * disc / (R * R));
      } else {
        const double sq = std::sqrt(disc);
        const double s1 = -bb - sq;
        s = ((oz + s1 * b.dz[k]) * R < 0.0) ? s1 : -bb + sq;
      }
    }
    const double x = b.px[k] + s * b.dx[k];
    const double y = b.py[k] + s * b.dy[k];
    const double z = b.pz[k] + s * b.dz[k];
    b.px[k] = x;
    b.py[k] = y;
    b.pz[k] = z;
    const double r = std::sqrt(x * x + y * y);
    if (e.kind == EventKind::kStop) {
      if (!b.stop_seen[k]) {
        b.u[k] = x * e.inv_semi;
        b.v[k] = y * e.inv_semi;
        b.stop_seen[k] = true;
      } else {
        // Later crossings of a ghost that passes the stop three times: the iris (as a circle)
        // clips through r_rel (the aperture shape applies at the first crossing only).
        b.rr[k] = std::max(b.rr[k], r * e.inv_semi);
      }
      continue;
    }
    b.rr[k] = std::max(b.rr[k], r * e.inv_semi);
    if (!flat_here) {
      nx = x / R;
      ny = y / R;
      nz = (z - cz) / R;  // unit normal, pointing to −z at the vertex
    }
    double cos_i = -(nx * b.dx[k] + ny * b.dy[k] + nz * b.dz[k]);
    if (cos_i < 0.0) {  // orient the normal against the ray
      nx = -nx;
      ny = -ny;
      nz = -nz;
      cos_i = -cos_i;
    }
    const float refl = ReflectanceTables::lookup(e.reflectance, cos_i);
    if (e.kind == EventKind::kReflect) {
      b.dx[k] += 2.0 * cos_i * nx;
      b.dy[k] += 2.0 * cos_i * ny;
      b.dz[k] += 2.0 * cos_i * nz;
      b.t[k] *= refl;
    } else {
      // Vector form of Snell's law.
      const double eta = e.eta;
      const double kk = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
      // Total internal reflection: past the critical angle (kk < 0) the ray leaves this path.
      // r_rel carries the margin 1 − β·kk, which stays below 1 for every transmitted ray and
      // crosses 1 exactly at the critical angle, so the rasterizer's interpolation puts the TIR
      // edge of a ghost where it belongs instead of losing every grid cell that touches it. The
      // ray itself goes on as the grazing refracted ray (kk = 0), continuous with its
      // transmitted neighbours, so the cells across the edge keep a sensible shape.
      b.rr[k] = std::max(b.rr[k], 1.0 - kValidityScale * kk);
      const double f = eta * cos_i - std::sqrt(std::max(kk, 0.0));
      double ndx = eta * b.dx[k] + f * nx;
      double ndy = eta * b.dy[k] + f * ny;
      double ndz = eta * b.dz[k] + f * nz;
      if (kk < 0.0) {
        const double inv = 1.0 / std::sqrt(ndx * ndx + ndy * ndy + ndz * ndz);
        ndx *= inv;
        ndy *= inv;
        ndz *= inv;
      }
      b.dx[k] = ndx;
      b.dy[k] = ndy;
      b.dz[k] = ndz;
      b.t[k] *= (1.0f - refl);
    }
  }
}

}  // namespace

void traceRays(const CompiledPath& path, const cv::Vec3d& dir, const double* x0, const double* y0,
               int count, TracedRays* out, int offset) {
  Block b;
  for (int start = 0; start < count; start += kBlock) {
    const int m = std::min(kBlock, count - start);
    for (int k = 0; k < m; ++k) {
      b.px[k] = x0[start + k];
      b.py[k] = y0[start + k];
      b.pz[k] = 0.0;
      b.dx[k] = dir[0];
      b.dy[k] = dir[1];
      b.dz[k] = dir[2];
      b.t[k] = 1.0;
      b.rr[k] = 0.0;
      b.u[k] = b.v[k] = 0.0;
      b.alive[k] = true;
      b.stop_seen[k] = false;
    }
    for (const CompiledEvent& e : path.events) applyEvent(e, b, m);
    for (int k = 0; k < m; ++k) {
      const size_t o = static_cast<size_t>(offset + start + k);
      bool ok = b.alive[k] && b.dz[k] > 1e-9;
      double x = 0, y = 0;
      if (ok) {
        const double s = (path.z_sensor - b.pz[k]) / b.dz[k];
        x = b.px[k] + s * b.dx[k];
        y = b.py[k] + s * b.dy[k];
        ok = std::isfinite(x) && std::isfinite(y) && std::abs(x) < 1e6 && std::abs(y) < 1e6;
      }
      out->alive[o] = ok ? 1 : 0;
      out->x_mm[o] = static_cast<float>(x);
      out->y_mm[o] = static_cast<float>(y);
      out->u[o] = static_cast<float>(b.u[k]);
      out->v[o] = static_cast<float>(b.v[k]);
      out->r_rel[o] = static_cast<float>(std::min(b.rr[k], 1e6));
      out->transmission[o] = ok ? static_cast<float>(b.t[k]) : 0.f;
    }
  }
}

void traceGrid(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid& grid,
               TracedRays* out) {
  const int n = grid.n;
  out->n = n;
  out->resize(n * n);
  std::vector<double> xs(static_cast<size_t>(n)), ys(static_cast<size_t>(n));
  const double h = grid.spacing_mm();
  for (int i = 0; i < n; ++i) xs[static_cast<size_t>(i)] = grid.center_x_mm - grid.half_size_mm + i * h;
  std::vector<double> y_row(static_cast<size_t>(n));
  for (int j = 0; j < n; ++j) {
    const double y = grid.center_y_mm - grid.half_size_mm + j * h;
    std::fill(y_row.begin(), y_row.end(), y);
    traceRays(path, dir, xs.data(), y_row.data(), n, out, j * n);
  }
}

bool findStopCenterRay(const CompiledPath& path, const cv::Vec3d& dir, double guess_x,
                       double guess_y, cv::Point2d* origin) {
  return findStopRay(path, dir, 0.0, 0.0, guess_x, guess_y, origin);
}

bool findStopRay(const CompiledPath& path, const cv::Vec3d& dir, double target_u,
                 double target_v, double guess_x, double guess_y, cv::Point2d* origin) {
  TracedRays r;
  r.resize(3);
  double x = guess_x, y = guess_y;
  const double step = 1e-3;
  for (int iter = 0; iter < 20; ++iter) {
    const double xs[3] = {x, x + step, x};
    const double ys[3] = {y, y, y + step};
    traceRays(path, dir, xs, ys, 3, &r);
    // Aperture coordinates are recorded whether or not the ray reaches the sensor; a dead ray
    // before the stop keeps u = v = 0, so require a live centre ray.
    if (!r.alive[0] || !r.alive[1] || !r.alive[2]) return false;
    const double u = (r.u[0] - target_u) * path.stop_semi_mm;
    const double v = (r.v[0] - target_v) * path.stop_semi_mm;
    if (std::hypot(u, v) < 1e-7) {
      *origin = {x, y};
      return true;
    }
    const double a = (r.u[1] - r.u[0]) * path.stop_semi_mm / step;
    const double c = (r.v[1] - r.v[0]) * path.stop_semi_mm / step;
    const double bq = (r.u[2] - r.u[0]) * path.stop_semi_mm / step;
    const double d = (r.v[2] - r.v[0]) * path.stop_semi_mm / step;
    const double det = a * d - bq * c;
    if (std::abs(det) < 1e-12) return false;
    x -= (d * u - bq * v) / det;
    y -= (-c * u + a * v) / det;
  }
  *origin = {x, y};
  return true;
}

}  // namespace flarekit::render
