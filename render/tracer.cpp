#include "render/tracer.h"

#include <algorithm>
#include <cmath>

// GCC 12's AVX-512 intrinsics start some results from an "undefined" vector, which
// -Wmaybe-uninitialized reports inside the header (GCC bug 105593).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <immintrin.h>
#pragma GCC diagnostic pop

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
    c.inv_radius = s.isFlat() ? 0.0 : 1.0 / s.radius_mm;
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
// of arrays). The loops are branch-free so that the compiler vectorises them: every lane computes
// both sides of each case and selects (the same IEEE operations as a scalar case analysis, so a
// ray's result does not depend on its block), and every lane goes on computing after its ray
// died (alive = 0): the state of dead rays is meaningless and never read. The one gather, the
// reflectance lookup, has its own loops between the vector loops. 256 rays a block (the arrays an
// event touches, about 35 KB, still in the EPYC's 48 KB L1): the calls and loop set-ups of an
// event are spread over more rays; 64 traced the Nikon 28-75 (1280×720) 3 % and the Heliar 2.5 %
// slower than 128 on one thread, whose blocks, with the blocked rays dropped at the stop, run
// part empty, and 128 traced the Nikon 2.6 % slower than 256 (medians of 5 runs, 495 and 482 ms).
constexpr int kBlock = 256;

// Slope β of the validity margins folded into r_rel (total internal reflection, missed spheres).
constexpr double kValidityScale = 4.0;

// The vector loops are also built for AVX2 (4 doubles a vector instead of SSE2's 2) and AVX-512
// (x86-64-v4: 8 doubles, masked selects; 27 % less tracing time on the project's EPYC), chosen at
// load time by the CPU. The library is built with -ffp-contract=off, so no clone fuses a multiply
// and an add: every clone performs the same IEEE operations and images do not depend on the
// machine.
#if defined(__clang__)
// Clang (the fuzzing build, scripts/fuzz.sh) does not clone templates nor know arch=x86-64-v4 in
// function multiversioning: one portable version there.
#define FLAREKIT_VECTOR_LOOP
#else
#define FLAREKIT_VECTOR_LOOP __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#endif

// Lane flags are doubles (1 = set) so that the masks have the width of the data they select.
struct Block {
  alignas(64) double px[kBlock], py[kBlock], pz[kBlock];
  alignas(64) double dx[kBlock], dy[kBlock], dz[kBlock];
  alignas(64) double t[kBlock], rr[kBlock], u[kBlock], v[kBlock];
  alignas(64) double alive[kBlock], stop_seen[kBlock];
  // Scratch of one event: ray parameter to the surface, sphere discriminant (< 0: the ray missed
  // the sphere), oriented unit normal and cos(incidence), reflectance.
  alignas(64) double s[kBlock], disc[kBlock];
  alignas(64) double tir[kBlock];  // 1 = past the critical angle
  alignas(64) double reached[kBlock];  // 1 = reached the sensor (reachSensor)
  alignas(64) double passing[kBlock];  // 1 = may still pass every rim and the stop (markPassing)
  alignas(64) double nx[kBlock], ny[kBlock], nz[kBlock], cos_i[kBlock];
  alignas(64) float refl[kBlock];
  // Scratch of the reflectance lookup: table index, interpolation weight, the two samples.
  alignas(64) double weight[kBlock];
  alignas(64) int index[kBlock];
  alignas(64) float r0[kBlock], r1[kBlock];
};

// The ray parameter s to the event's surface for every lane: the plane of the vertex, or the
// sphere on its vertex-side hemisphere, extended past the rim. Returns whether a lane missed the
// sphere (then b.disc < 0 marks them; the caller falls back to the plane there). The discriminant
// itself marks the misses, and they are counted: a flag a lane (miss ? 1 : 0) stored and or-ed
// made the loop's masks go through integer registers, and the Nikon 28-75's whole trace 14 %
// slower (1280×720, one thread).
template <bool kFlat>
FLAREKIT_VECTOR_LOOP bool rayParameters(const CompiledEvent& e, Block& b, int count) {
  const double R = e.radius;
  const double cz = e.z + R;  // centre of the sphere
  const double ez = e.z;
  long long misses = 0;  // (a count of the lanes' width vectorises, as in markPassing)
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const double px = b.px[k], py = b.py[k], pz = b.pz[k];
    const double dx = b.dx[k], dy = b.dy[k], dz = b.dz[k];
    if constexpr (kFlat) {
      b.s[k] = (ez - pz) / dz;
    } else {
      // |o + s d|² = R² with o = p − C; the root on the vertex side, (z − C_z)·R < 0.
      const double ox = px, oy = py, oz = pz - cz;
      const double bb = ox * dx + oy * dy + oz * dz;
      const double cc = ox * ox + oy * oy + oz * oz - R * R;
      const double disc = bb * bb - cc;
      const double sq = std::sqrt(std::max(disc, 0.0));
      const double s1 = -bb - sq, s2 = -bb + sq;
      b.s[k] = (oz + s1 * dz) * R < 0.0 ? s1 : s2;
      b.disc[k] = disc;
      misses += disc < 0.0;
    }
  }
  return misses != 0;
}

// Missed the sphere: the ray passes outside every rim (r > |R| > semi-aperture), so it is not
// part of the ghost. Rather than dropping it (and with it every grid cell it touches), it goes on
// from the vertex plane with r_rel past |R|/semi-aperture, growing with the miss distance, so
// cells across the edge are clipped by interpolation. (Only for blocks with a miss: it costs two
// divisions a lane.)
FLAREKIT_VECTOR_LOOP void missedSphere(const CompiledEvent& e, Block& b, int count) {
  const double R = e.radius;
  const double ez = e.z;
  const double miss_base = std::abs(R) * e.inv_semi;
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const bool miss = b.disc[k] < 0.0;
    const double dz = b.dz[k];
    const double s_plane = (ez - b.pz[k]) / dz;
    const double rr_miss = std::max(b.rr[k], miss_base - kValidityScale * b.disc[k] / (R * R));
    const bool dies = miss & (std::abs(dz) < 1e-12);
    b.s[k] = miss ? s_plane : b.s[k];
    b.rr[k] = miss ? rr_miss : b.rr[k];
    b.alive[k] = dies ? 0.0 : b.alive[k];
  }
}

// Moves every ray of the block by its parameter s to the event's surface. Records the stop
// crossing, or the normal and the cosine of incidence for the optical events. `planes`: some
// lanes (b.disc < 0) met the vertex plane instead of the sphere.
template <bool kFlat, bool kStop>
FLAREKIT_VECTOR_LOOP void moveToSurface(const CompiledEvent& e, Block& b, int count, bool planes) {
  const double R = e.radius;
  const double inv_R = e.inv_radius;
  const double cz = e.z + R;  // centre of the sphere
  const double inv_semi = e.inv_semi;
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const double dx = b.dx[k], dy = b.dy[k], dz = b.dz[k];
    const double s = b.s[k];
    const double rr = b.rr[k];
    const double x = b.px[k] + s * dx;
    const double y = b.py[k] + s * dy;
    const double z = b.pz[k] + s * dz;
    const double r = std::sqrt(x * x + y * y);
    if constexpr (kFlat) b.alive[k] = std::abs(dz) < 1e-12 ? 0.0 : b.alive[k];
    b.px[k] = x;
    b.py[k] = y;
    b.pz[k] = z;
    if constexpr (kStop) {
      // Later crossings of a ghost that passes the stop three times: the iris (as a circle)
      // clips through r_rel (the aperture shape applies at the first crossing only).
      const bool first = b.stop_seen[k] == 0.0;
      b.u[k] = first ? x * inv_semi : b.u[k];
      b.v[k] = first ? y * inv_semi : b.v[k];
      b.stop_seen[k] = 1.0;
      b.rr[k] = first ? rr : std::max(rr, r * inv_semi);
    } else {
      b.rr[k] = std::max(rr, r * inv_semi);
      double nx = 0.0, ny = 0.0, nz = 1.0;
      if constexpr (!kFlat) {
        // Unit normal, pointing to −z at the vertex (by the reciprocal of R: three divisions a
        // lane and event were the tracer's slowest instructions).
        const bool plane_here = planes & (b.disc[k] < 0.0);
        nx = plane_here ? 0.0 : x * inv_R;
        ny = plane_here ? 0.0 : y * inv_R;
        nz = plane_here ? 1.0 : (z - cz) * inv_R;
      }
      const double c = -(nx * dx + ny * dy + nz * dz);
      const bool flip = c < 0.0;  // orient the normal against the ray
      b.nx[k] = flip ? -nx : nx;
      b.ny[k] = flip ? -ny : ny;
      b.nz[k] = flip ? -nz : nz;
      b.cos_i[k] = flip ? -c : c;
    }
  }
}

template <bool kStop>
void intersect(const CompiledEvent& e, Block& b, int count) {
  if (e.radius == 0.0) {
    rayParameters<true>(e, b, count);
    moveToSurface<true, kStop>(e, b, count, false);
    return;
  }
  const bool misses = rayParameters<false>(e, b, count);
  if (misses) missedSphere(e, b, count);
  moveToSurface<false, kStop>(e, b, count, misses);
}

// Reflectances: ReflectanceTables::lookup written out, lane by lane the same operations, in three
// loops (index, gather, blend) that each vectorise (AVX2 has a gather). Built for the baseline and
// AVX2 as FLAREKIT_VECTOR_LOOP would; for AVX-512 the lookup is written out below.
__attribute__((always_inline)) inline void lookupReflectanceLoops(const float* __restrict__ table,
                                                                  Block& b, int count) {
  constexpr int kLast = ReflectanceTables::kSamples - 1;
  for (int k = 0; k < count; ++k) {
    const double c0 = b.cos_i[k];
    const double c = c0 >= 0.0 ? (c0 <= 1.0 ? c0 : 1.0) : 0.0;  // NaN (dead lanes) to 0
    const double f = c * kLast;
    const int i = std::min(static_cast<int>(f), kLast - 1);
    b.weight[k] = f - i;
    b.index[k] = i;
  }
  for (int k = 0; k < count; ++k) {
    b.r0[k] = table[b.index[k]];
    b.r1[k] = table[b.index[k] + 1];
  }
  for (int k = 0; k < count; ++k) {
    const float t0 = b.r0[k], t1 = b.r1[k];
    b.refl[k] = static_cast<float>(t0 + b.weight[k] * (t1 - t0));
  }
}

#if defined(__clang__)
void lookupReflectance(const float* __restrict__ table, Block& b, int count) {
  lookupReflectanceLoops(table, b, count);
}
#else
__attribute__((target("default"))) void lookupReflectance(const float* __restrict__ table,
                                                          Block& b, int count) {
  lookupReflectanceLoops(table, b, count);
}
__attribute__((target("avx2"))) void lookupReflectance(const float* __restrict__ table, Block& b,
                                                       int count) {
  lookupReflectanceLoops(table, b, count);
}

// AVX-512: the table's 128 intervals sit in registers, their left samples in eight vectors of 16
// and their steps (right − left sample, in float as above) in eight more, and 16 lanes at a time
// pick theirs by two-table permutes (32 entries by the index's low 5 bits) and blends (bits 5 and
// 6), instead of 32 scalar loads a vector: the Nikon 28-75's trace (1280×720, one thread) took
// 8 % less time. The same operations on every lane as the loops above: the same floats.
__attribute__((target("arch=x86-64-v4"))) void lookupReflectance(const float* __restrict__ table,
                                                                 Block& b, int count) {
  constexpr int kLast = ReflectanceTables::kSamples - 1;
  static_assert(kLast == 128 && kBlock % 16 == 0,
                "8 vectors of 16 intervals, whole vectors of lanes a block");
  __m512 left[8], step[8];
  for (int q = 0; q < 8; ++q) {
    left[q] = _mm512_loadu_ps(table + 16 * q);
    step[q] = _mm512_sub_ps(_mm512_loadu_ps(table + 16 * q + 1), left[q]);
  }
  const __m512d zero = _mm512_setzero_pd(), one = _mm512_set1_pd(1.0);
  const __m512d last = _mm512_set1_pd(kLast);
  const __m256i last_interval = _mm256_set1_epi32(kLast - 1);
  // Lanes past `count` (up to the block's end) are computed too, on stale values, and never read.
  for (int k = 0; k < count; k += 16) {
    __m512d w[2];
    __m256i i[2];
    for (int h = 0; h < 2; ++h) {
      const __m512d c0 = _mm512_load_pd(b.cos_i + k + 8 * h);
      // c0 ≥ 0 ? min(c0, 1) : 0, NaN to 0, as above.
      const __m512d c = _mm512_maskz_mov_pd(_mm512_cmp_pd_mask(c0, zero, _CMP_GE_OQ),
                                            _mm512_min_pd(one, c0));
      const __m512d f = _mm512_mul_pd(c, last);
      i[h] = _mm256_min_epi32(_mm512_cvttpd_epi32(f), last_interval);
      w[h] = _mm512_sub_pd(f, _mm512_cvtepi32_pd(i[h]));
    }
    const __m512i idx = _mm512_inserti64x4(_mm512_castsi256_si512(i[0]), i[1], 1);
    const __mmask16 bit5 = _mm512_test_epi32_mask(idx, _mm512_set1_epi32(32));
    const __mmask16 bit6 = _mm512_test_epi32_mask(idx, _mm512_set1_epi32(64));
    __m512 picked[2];  // left sample, step
    for (int side = 0; side < 2; ++side) {
      const __m512* t = side == 0 ? left : step;
      const __m512 a = _mm512_permutex2var_ps(t[0], idx, t[1]);
      const __m512 c = _mm512_permutex2var_ps(t[2], idx, t[3]);
      const __m512 d = _mm512_permutex2var_ps(t[4], idx, t[5]);
      const __m512 e = _mm512_permutex2var_ps(t[6], idx, t[7]);
      picked[side] = _mm512_mask_blend_ps(bit6, _mm512_mask_blend_ps(bit5, a, c),
                                          _mm512_mask_blend_ps(bit5, d, e));
    }
    const __m256 t0[2] = {_mm512_castps512_ps256(picked[0]), _mm512_extractf32x8_ps(picked[0], 1)};
    const __m256 dt[2] = {_mm512_castps512_ps256(picked[1]), _mm512_extractf32x8_ps(picked[1], 1)};
    for (int h = 0; h < 2; ++h) {
      const __m512d r = _mm512_add_pd(_mm512_cvtps_pd(t0[h]),
                                      _mm512_mul_pd(w[h], _mm512_cvtps_pd(dt[h])));
      _mm256_store_ps(b.refl + k + 8 * h, _mm512_cvtpd_ps(r));
    }
  }
}
#endif  // !__clang__

FLAREKIT_VECTOR_LOOP void reflect(Block& b, int count) {
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const double c = b.cos_i[k];
    b.dx[k] += 2.0 * c * b.nx[k];
    b.dy[k] += 2.0 * c * b.ny[k];
    b.dz[k] += 2.0 * c * b.nz[k];
    b.t[k] *= b.refl[k];
  }
}

FLAREKIT_VECTOR_LOOP void refract(double eta, Block& b, int count) {
  int any_tir = 0;
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const double c = b.cos_i[k];
    const double nx = b.nx[k], ny = b.ny[k], nz = b.nz[k];
    // Vector form of Snell's law.
    const double kk = 1.0 - eta * eta * (1.0 - c * c);
    // Total internal reflection: past the critical angle (kk < 0) the ray leaves this path.
    // r_rel carries the margin 1 − β·kk, which stays below 1 for every transmitted ray and
    // crosses 1 exactly at the critical angle, so the rasterizer's interpolation puts the TIR
    // edge of a ghost where it belongs instead of losing every grid cell that touches it. The
    // ray itself goes on as the grazing refracted ray (kk = 0), continuous with its
    // transmitted neighbours, so the cells across the edge keep a sensible shape.
    b.rr[k] = std::max(b.rr[k], 1.0 - kValidityScale * kk);
    const double f = eta * c - std::sqrt(std::max(kk, 0.0));
    const double ndx = eta * b.dx[k] + f * nx;
    const double ndy = eta * b.dy[k] + f * ny;
    const double ndz = eta * b.dz[k] + f * nz;
    const bool tir = kk < 0.0;
    b.dx[k] = ndx;
    b.dy[k] = ndy;
    b.dz[k] = ndz;
    b.tir[k] = tir ? 1.0 : 0.0;
    any_tir |= tir;
    b.t[k] *= (1.0f - b.refl[k]);
  }
  if (!any_tir) return;
  // The grazing rays past the critical angle, normalised (only in blocks that have one).
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const double ndx = b.dx[k], ndy = b.dy[k], ndz = b.dz[k];
    const double inv = 1.0 / std::sqrt(ndx * ndx + ndy * ndy + ndz * ndz);
    const bool tir = b.tir[k] != 0.0;
    b.dx[k] = tir ? ndx * inv : ndx;
    b.dy[k] = tir ? ndy * inv : ndy;
    b.dz[k] = tir ? ndz * inv : ndz;
  }
}

void applyEvent(const CompiledEvent& e, Block& b, int count) {
  if (e.kind == EventKind::kStop) {
    intersect<true>(e, b, count);
    return;
  }
  intersect<false>(e, b, count);
  lookupReflectance(e.reflectance, b, count);
  if (e.kind == EventKind::kReflect)
    reflect(b, count);
  else
    refract(e.eta, b, count);
}

// Writes ray `o` of `out` as one that does not reach the image.
void writeDead(TracedRays* out, size_t o) {
  out->alive[o] = 0;
  out->x_mm[o] = out->y_mm[o] = 0.f;
  out->u[o] = out->v[o] = 0.f;
  out->r_rel[o] = 1e6f;
  out->transmission[o] = 0.f;
}

// Marks in b.passing the lanes that may still pass every rim and the stop circle, judged on the
// values the output will carry (r_rel only grows, the aperture coordinates are fixed at the first
// stop crossing, and the output's r_rel, u and v are floats), and returns how many. A vector loop:
// as a scalar test per lane after every event it cost more than the lanes it dropped saved.
FLAREKIT_VECTOR_LOOP int markPassing(Block& b, int count) {
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    // The float values compared as doubles (exactly: a float widens to double without rounding),
    // so that every mask has the width of a double lane.
    const double rr = static_cast<float>(std::min(b.rr[k], 1e6));
    const float u = static_cast<float>(b.u[k]), v = static_cast<float>(b.v[k]);
    const double uv = u * u + v * v;
    const bool inside_stop = (b.stop_seen[k] == 0.0) | (uv <= 1.0);
    const bool pass = (b.alive[k] != 0.0) & !(rr > 1.0) & inside_stop;
    b.passing[k] = pass ? 1.0 : 0.0;
  }
  long long passing = 0;  // (a count of the lane's width vectorises)
  for (int k = 0; k < count; ++k) passing += b.passing[k] != 0.0;
  return static_cast<int>(passing);
}

// Drops the lanes that can no longer pass (written to `out` as dead, and their rays appended to
// `dropped` when given) when they are at least a quarter of the block, moving the others to the
// front; ray[] maps lanes to rays. Returns the lanes left. (Moving the lanes costs about as much
// as one event of them: dropping a quarter pays for itself within a few events.)
int dropBlocked(Block& b, int live, int* ray, TracedRays* out, int first, std::vector<int>* dropped) {
  const int passing = markPassing(b, live);
  if (4 * passing > 3 * live) return live;
  int j = 0;
  for (int k = 0; k < live; ++k) {
    if (b.passing[k] == 0.0) {
      writeDead(out, static_cast<size_t>(first + ray[k]));
      if (dropped) dropped->push_back(first + ray[k]);
      continue;
    }
    if (j != k) {
      ray[j] = ray[k];
      b.px[j] = b.px[k];
      b.py[j] = b.py[k];
      b.pz[j] = b.pz[k];
      b.dx[j] = b.dx[k];
      b.dy[j] = b.dy[k];
      b.dz[j] = b.dz[k];
      b.t[j] = b.t[k];
      b.rr[j] = b.rr[k];
      b.u[j] = b.u[k];
      b.v[j] = b.v[k];
      b.alive[j] = b.alive[k];
      b.stop_seen[j] = b.stop_seen[k];
    }
    ++j;
  }
  return j;
}

// Moves every ray of the block that heads for the sensor (alive, d_z > 0) to the sensor plane,
// and marks in b.reached those that reach it at a finite position (|x|, |y| < 1e6 mm); the
// others get x = y = 0. (A vector loop: its division was one a ray in the scalar write-out.)
FLAREKIT_VECTOR_LOOP void reachSensor(double z_sensor, Block& b, int count) {
#pragma GCC ivdep
  for (int k = 0; k < count; ++k) {
    const bool heading = (b.alive[k] != 0.0) & (b.dz[k] > 1e-9);
    const double s = (z_sensor - b.pz[k]) / b.dz[k];
    const double x = heading ? b.px[k] + s * b.dx[k] : 0.0;
    const double y = heading ? b.py[k] + s * b.dy[k] : 0.0;
    // NaN and infinities fail the comparisons too.
    const bool reached = heading & (std::abs(x) < 1e6) & (std::abs(y) < 1e6);
    b.px[k] = x;
    b.py[k] = y;
    b.reached[k] = reached ? 1.0 : 0.0;
  }
}

// When traceBlocks drops the rays certain to be blocked (past a rim or outside the stop circle),
// once they are a quarter of a block: never, after every event, or after each stop crossing only.
// Where most rays are blocked, early and for good (boundGhost's search grid over the whole front
// element), the test after every event pays; in a ghost's own grid it cost about what dropping
// saved, while the test after the stop crossings alone (where the iris blocks) made the Nikon
// 28-75's whole trace 8 % faster (1280×720, 10°, one thread).
enum class Drop { kNever, kAfterEveryEvent, kAfterStop };

// Traces rays [0, count), the origins of rays [first, first + m) written by
// `origins(first, m, x, y)`, into `out` from `offset` on. Dropped rays (`drop`) are reported dead,
// their indices appended to `dropped` when given.
template <typename Origins>
void traceBlocks(const CompiledPath& path, const cv::Vec3d& dir, int count, Origins origins,
                 TracedRays* out, int offset, Drop drop = Drop::kNever,
                 std::vector<int>* dropped = nullptr) {
  Block b;
  int ray[kBlock];
  for (int start = 0; start < count; start += kBlock) {
    const int m = std::min(kBlock, count - start);
    origins(start, m, b.px, b.py);
    for (int k = 0; k < m; ++k) {
      b.pz[k] = 0.0;
      b.dx[k] = dir[0];
      b.dy[k] = dir[1];
      b.dz[k] = dir[2];
      b.t[k] = 1.0;
      b.rr[k] = 0.0;
      b.u[k] = b.v[k] = 0.0;
      b.alive[k] = 1.0;
      b.stop_seen[k] = 0.0;
      ray[k] = k;
    }
    int live = m;
    for (const CompiledEvent& e : path.events) {
      applyEvent(e, b, live);
      if (drop == Drop::kAfterEveryEvent || (drop == Drop::kAfterStop && e.kind == EventKind::kStop))
        live = dropBlocked(b, live, ray, out, offset + start, dropped);
      if (live == 0) break;
    }
    reachSensor(path.z_sensor, b, live);
    for (int k = 0; k < live; ++k) {
      const size_t o = static_cast<size_t>(offset + start + ray[k]);
      if (b.alive[k] == 0.0) {  // a dead ray's state is meaningless (see above)
        writeDead(out, o);
        continue;
      }
      const bool reached = b.reached[k] != 0.0;
      out->alive[o] = reached ? 1 : 0;
      out->x_mm[o] = static_cast<float>(b.px[k]);
      out->y_mm[o] = static_cast<float>(b.py[k]);
      out->u[o] = static_cast<float>(b.u[k]);
      out->v[o] = static_cast<float>(b.v[k]);
      out->r_rel[o] = static_cast<float>(std::min(b.rr[k], 1e6));
      out->transmission[o] = reached ? static_cast<float>(b.t[k]) : 0.f;
    }
  }
}

// Traces `grid_count` grids of one size (grids[g].n = n for all g) one after another, in full
// blocks: grid g's rays from index g·n² on (out->n = n). A refined cell's small grid is thus part
// of a block, not one of its own per grid or row.
void traceGridList(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid* grids,
                   int grid_count, TracedRays* out, Drop drop, std::vector<int>* dropped = nullptr) {
  const int n = grids[0].n, nn = n * n;
  out->n = n;
  out->resize(nn * grid_count);
  // Origins made on the fly, a block at a time, walking the grids' columns and rows (no integer
  // division a ray, and the spacing's division once a grid).
  traceBlocks(
      path, dir, nn * grid_count,
      [&](int first, int m, double* x, double* y) {
        int g = first / nn, i = first % nn % n, j = first % nn / n;
        double x_first = 0.0, y_first = 0.0, h = 0.0;
        auto enter = [&](const RayGrid& grid) {
          x_first = grid.center_x_mm - grid.half_size_mm;
          y_first = grid.center_y_mm - grid.half_size_mm;
          h = grid.spacing_mm();
        };
        enter(grids[g]);
        for (int k = 0; k < m; ++k) {
          x[k] = x_first + i * h;
          y[k] = y_first + j * h;
          if (++i < n) continue;
          i = 0;
          if (++j < n) continue;
          j = 0;
          if (++g < grid_count) enter(grids[g]);
        }
      },
      out, 0, drop, dropped);
}

}  // namespace

void traceRays(const CompiledPath& path, const cv::Vec3d& dir, const double* x0, const double* y0,
               int count, TracedRays* out, int offset) {
  traceBlocks(
      path, dir, count,
      [&](int first, int m, double* x, double* y) {
        std::copy_n(x0 + first, m, x);
        std::copy_n(y0 + first, m, y);
      },
      out, offset);
}

void traceGrid(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid& grid,
               TracedRays* out, bool passing_only) {
  traceGridList(path, dir, &grid, 1, out, passing_only ? Drop::kAfterEveryEvent : Drop::kNever);
}

void traceGridCorners(const CompiledPath& path, const cv::Vec3d& dir, const RayGrid& grid,
                      TracedRays* out) {
  // Rays that cannot pass are dropped on the way (most of a vignetted ghost's box: on the Nikon
  // 28-75 at 10°, 62 % of its grids' rays have no passing ray among their eight neighbours, and
  // 27 % of the grids' ray-events came after the ray could no longer pass); those next to a
  // passing ray are traced again whole, from their origins, which gives them the result
  // traceGrid gives (a ray's result does not depend on its block).
  std::vector<int> dropped;
  traceGridList(path, dir, &grid, 1, out, Drop::kAfterStop, &dropped);
  if (dropped.empty()) return;
  const int n = grid.n;
  // A dropped ray cannot pass, so its neighbours' verdicts are final. The rays with a passing ray
  // among their eight neighbours: the passing rays widened by one along the rows, then along the
  // columns: three passes over the grid instead of up to nine tests and two integer divisions a
  // dropped ray (whose share of the Nikon 28-75's trace fell from 2.5 to 1.3 %).
  const auto nn = static_cast<size_t>(n) * static_cast<size_t>(n);
  const auto row = static_cast<size_t>(n);
  std::vector<uint8_t> passing(nn), near_in_row(nn), near_passing(nn);
  for (size_t k = 0; k < nn; ++k) passing[k] = out->passes(k);
  for (size_t first = 0; first < nn; first += row)
    for (size_t i = 0; i < row; ++i) {
      const size_t k = first + i;
      near_in_row[k] =
          passing[k] | (i > 0 ? passing[k - 1] : 0) | (i + 1 < row ? passing[k + 1] : 0);
    }
  for (size_t k = 0; k < nn; ++k)
    near_passing[k] = near_in_row[k] | (k >= row ? near_in_row[k - row] : 0) |
                      (k + row < nn ? near_in_row[k + row] : 0);
  std::vector<int> again;
  for (const int k : dropped)
    if (near_passing[static_cast<size_t>(k)]) again.push_back(k);
  if (again.empty()) return;
  // The origins as traceGridList makes them.
  const double x_first = grid.center_x_mm - grid.half_size_mm;
  const double y_first = grid.center_y_mm - grid.half_size_mm;
  const double h = grid.spacing_mm();
  const int m = static_cast<int>(again.size());
  std::vector<double> xs(again.size()), ys(again.size());
  for (size_t q = 0; q < again.size(); ++q) {
    xs[q] = x_first + (again[q] % n) * h;
    ys[q] = y_first + (again[q] / n) * h;
  }
  TracedRays traced;
  traced.resize(m);
  traceRays(path, dir, xs.data(), ys.data(), m, &traced);
  for (size_t q = 0; q < again.size(); ++q) {
    const auto o = static_cast<size_t>(again[q]);
    out->x_mm[o] = traced.x_mm[q];
    out->y_mm[o] = traced.y_mm[q];
    out->u[o] = traced.u[q];
    out->v[o] = traced.v[q];
    out->r_rel[o] = traced.r_rel[q];
    out->transmission[o] = traced.transmission[q];
    out->alive[o] = traced.alive[q];
  }
}

void traceGrids(const CompiledPath& path, const cv::Vec3d& dir, const std::vector<RayGrid>& grids,
                TracedRays* out) {
  if (grids.empty()) {
    out->resize(0);
    return;
  }
  traceGridList(path, dir, grids.data(), static_cast<int>(grids.size()), out, Drop::kNever);
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
    // Damped: where the live rays of a ghost are a small patch of the plane (the Heliar's ghost
    // of surfaces 3 and 0 at 6°: 354 of 3721 rays over 60 mm), a full step can land on a ray that
    // never reaches the sensor; halve it until it does not.
    double dx = (d * u - bq * v) / det, dy = (-c * u + a * v) / det;
    for (int halving = 0; halving < 12; ++halving, dx *= 0.5, dy *= 0.5) {
      const double xn = x - dx, yn = y - dy;
      traceRays(path, dir, &xn, &yn, 1, &r);
      if (r.alive[0]) break;
    }
    x -= dx;
    y -= dy;
  }
  *origin = {x, y};
  return true;
}

}  // namespace flarekit::render
