#include "model/model_renderer.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "model/detail/outline_search.h"
#include "model/intensity.h"

namespace flarekit::model {

// ---------------------------------------------------------------------------------------------
// ViewTransform

ViewTransform ViewTransform::roll(double roll_rad, cv::Point2d center) {
  ViewTransform v;
  v.roll_rad = roll_rad;
  v.image_center = center;
  v.model_center = center;
  return v;
}

cv::Point2d ViewTransform::modelFromImage(cv::Point2d p) const {
  // Undo the counter-clockwise (as displayed, y down) rotation by φ: OpenCV's rotation matrix for
  // +φ is [cos φ, sin φ; −sin φ, cos φ]; its inverse is the transpose.
  const double c = std::cos(roll_rad), s = std::sin(roll_rad);
  const double x = (p.x - image_center.x) / scale, y = (p.y - image_center.y) / scale;
  return {model_center.x + c * x - s * y, model_center.y + s * x + c * y};
}

cv::Point2d ViewTransform::imageFromModel(cv::Point2d q) const {
  const double c = std::cos(roll_rad), s = std::sin(roll_rad);
  const double x = q.x - model_center.x, y = q.y - model_center.y;
  return {image_center.x + scale * (c * x + s * y), image_center.y + scale * (-s * x + c * y)};
}

bool ViewTransform::isIdentity() const {
  return roll_rad == 0 && scale == 1 && image_center == model_center;
}

bool ViewTransform::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (!std::isfinite(roll_rad)) return fail("roll_rad must be finite");
  if (!(scale > 0) || !std::isfinite(scale)) return fail("scale must be positive and finite");
  if (!std::isfinite(image_center.x) || !std::isfinite(image_center.y) ||
      !std::isfinite(model_center.x) || !std::isfinite(model_center.y))
    return fail("centres must be finite");
  return true;
}

bool RenderOptions::IsValid(std::string* error) const {
  if (!distance.IsValid(error)) return false;
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (tile_size < 8 || tile_size > 4096) return fail("tile_size must be in [8, 4096]");
  if (block_size < 1 || block_size > tile_size) return fail("block_size must be in [1, tile_size]");
  return true;
}

cv::Rect ghostPixelBounds(const GhostParameters& g, const ViewTransform& view) {
  const cv::Rect2d box = outlineBounds(g);
  const double grow = g.outside_falloff;
  const double x0 = box.x - grow, y0 = box.y - grow;
  const double x1 = box.x + box.width + grow, y1 = box.y + box.height + grow;
  double lx = 1e300, ly = 1e300, hx = -1e300, hy = -1e300;
  const cv::Point2d corners[4] = {{x0, y0}, {x1, y0}, {x0, y1}, {x1, y1}};
  for (const auto& c : corners) {
    const cv::Point2d p = view.imageFromModel(c);
    lx = std::min(lx, p.x);
    ly = std::min(ly, p.y);
    hx = std::max(hx, p.x);
    hy = std::max(hy, p.y);
  }
  if (!(lx <= hx && ly <= hy)) return {};
  // Pixel i has its centre at i + 0.5: the centres inside [lx, hx] are i in
  // [ceil(lx − 0.5), floor(hx − 0.5)]; one pixel of margin absorbs rounding in the transform.
  const double limit = 1e9;
  const double ix0 = std::clamp(std::ceil(lx - 0.5) - 1, -limit, limit);
  const double iy0 = std::clamp(std::ceil(ly - 0.5) - 1, -limit, limit);
  const double ix1 = std::clamp(std::floor(hx - 0.5) + 1, -limit, limit);
  const double iy1 = std::clamp(std::floor(hy - 0.5) + 1, -limit, limit);
  if (ix1 < ix0 || iy1 < iy0) return {};
  return {static_cast<int>(ix0), static_cast<int>(iy0), static_cast<int>(ix1 - ix0 + 1),
          static_cast<int>(iy1 - iy0 + 1)};
}

// ---------------------------------------------------------------------------------------------
// Per-pixel evaluation

namespace {

struct PreparedGhost {
  const GhostParameters* g = nullptr;
  detail::PreparedShape shape;
  cv::Rect bounds;  // ghostPixelBounds ∩ roi, image coordinates
  int count = 0;    // parameters
};

// Everything the renderer needs at one model point.
struct PointEval {
  double d = 0;
  bool inside = false;
  int segment = 0;  // upper segment 0 or 1
  double t = 0;
  double bx = 0, by = 0;  // nearest point, relative reflected frame
  double rx = 0, ry = 0;  // the point, relative reflected frame
  bool lower = false;
};

// The signed distance at model point q. The magnitude is exact when below `cutoff_inside`
// (inside) or `cutoff_outside` (outside), else only known to be at least that.
inline void evalDistance(const detail::PreparedShape& s, cv::Point2d q,
                         const SignedDistanceOptions& o, PointEval& e, double cutoff_inside = 1e308,
                         double cutoff_outside = 1e308) {
  e.rx = q.x - s.mx;
  e.lower = q.y > s.my;
  e.ry = -std::abs(q.y - s.my);
  e.inside = detail::insideRelative(s, e.rx, e.ry);
  double d2 = 0;
  detail::nearestUpper(s, e.rx, e.ry, o, e.segment, e.t, d2, e.inside ? cutoff_inside : cutoff_outside);
  const double d = std::sqrt(d2);
  e.d = e.inside ? -d : d;
  e.bx = s.seg[e.segment].x(e.t);
  e.by = s.seg[e.segment].y(e.t);
}

// ∂d/∂(Mx, My, L, R, h, Cl, Cr) at the fixed nearest point (envelope theorem).
inline void distanceGradient(const GhostParameters& g, const detail::PreparedShape& s,
                             const PointEval& e, double* grad) {
  double nx = e.rx - e.bx, ny = e.ry - e.by;
  const double len = std::sqrt(nx * nx + ny * ny);
  if (len > 1e-12) {
    const double k = (e.inside ? -1.0 : 1.0) / len;
    nx *= k;
    ny *= k;
  } else {  // on the outline: the outward normal (tangent turned by −90°, clockwise outline)
    const double tx = s.seg[e.segment].dx(e.t), ty = s.seg[e.segment].dy(e.t);
    const double tl = std::sqrt(tx * tx + ty * ty);
    nx = tl > 0 ? ty / tl : 0;
    ny = tl > 0 ? -tx / tl : 0;
  }
  // (nx, ny) = ∂d/∂(relative reflected point). The point enters as (qx − Mx, −|qy − My|).
  grad[param::kMx] = -nx;
  grad[param::kMy] = e.lower ? ny : -ny;
  // Shape parameters: ∂b/∂q from the Bernstein weights of the control-point derivatives
  // (upper segments, relative frame; see ghostOutline).
  const double t = e.t, u = 1 - t;
  const double b0 = u * u * u, b1 = 3 * u * u * t, b2 = 3 * u * t * t, b3 = t * t * t;
  for (int q = param::kL; q <= param::kCr; ++q) grad[q] = 0;
  if (e.segment == 0) {
    const double cl = g.curvature_left;
    // P0 = (−L, 0), P1 = (−L, −Cl·h), P2 = (−Cl·L, −h), P3 = (0, −h)
    grad[param::kL] = -nx * (-b0 - b1 - cl * b2);
    grad[param::kH] = -ny * (-cl * b1 - b2 - b3);
    grad[param::kCl] = -(ny * (-g.height * b1) + nx * (-g.left * b2));
  } else {
    const double cr = g.curvature_right;
    // P0 = (0, −h), P1 = (Cr·R, −h), P2 = (R, −Cr·h), P3 = (R, 0)
    grad[param::kR] = -nx * (cr * b1 + b2 + b3);
    grad[param::kH] = -ny * (-b0 - b1 - cr * b2);
    grad[param::kCr] = -(nx * (g.right * b1) + ny * (-g.height * b2));
  }
}

// The signed distance at model point q searching only the pieces of a block (certified, see
// collectBlockPieces). The sign comes from the side of the tangent at the nearest point where
// that point is a foot of the normal inside a segment (exact there: the outline is convex), else
// from the exact inside test.
inline void evalDistanceInBlock(const detail::PreparedShape& s, const detail::BlockPieces& b,
                                cv::Point2d q, int newton_steps, detail::Candidate& hint,
                                bool has_hint, PointEval& e) {
  e.rx = q.x - s.mx;
  e.lower = q.y > s.my;
  e.ry = -std::abs(q.y - s.my);
  const detail::Candidate c = detail::nearestInPieces(s, b, e.rx, e.ry, newton_steps, has_hint ? &hint : nullptr);
  hint = c;
  e.segment = c.segment;
  e.t = c.t;
  const detail::PowerCubic& seg = s.seg[c.segment];
  e.bx = seg.x(c.t);
  e.by = seg.y(c.t);
  const double vx = e.rx - e.bx, vy = e.ry - e.by;
  const double tx = seg.dx(c.t), ty = seg.dy(c.t);
  const double cross = tx * vy - ty * vx;  // > 0 on the inner side (clockwise outline, y down)
  const double v2 = vx * vx + vy * vy, t2 = tx * tx + ty * ty;
  if (c.t > 0 && c.t < 1 && v2 > 1e-18 && cross * cross >= 0.98 * v2 * t2)
    e.inside = cross > 0;
  else
    e.inside = detail::insideRelative(s, e.rx, e.ry);
  const double d = std::sqrt(c.d2);
  e.d = e.inside ? -d : d;
}

// The signed distance at model point q by the renderer's fast path (detail::certifiedNearest):
// Newton from `hint` (the previous pixel's nearest point) when `has_hint`, else from an angle guess,
// certified as the global nearest point. False when it cannot certify (then the caller runs a
// full search, and `bound`, when Newton converged, is an outline point near p to start it from).
// When true, e.d is exact (no cutoff).
inline bool evalDistanceCertified(const detail::PreparedShape& s, cv::Point2d q,
                                  bool has_hint, const detail::Candidate& hint, PointEval& e,
                                  detail::Candidate& bound, bool& has_bound, double* dt_dx = nullptr) {
  e.rx = q.x - s.mx;
  e.lower = q.y > s.my;
  e.ry = -std::abs(q.y - s.my);
  has_bound = false;
  // The start's segment and t only (Newton does not read d²): the hint's fields were just
  // written one by one, and a copy of the whole struct reads t and d² with one 16-byte load, which
  // cannot take its data from two 8-byte stores still in flight (a store-forwarding stall on
  // the chain from pixel to pixel: a third more time per frame in one build).
  detail::Candidate c = has_hint ? detail::Candidate{hint.segment, hint.t, 0} : detail::angleGuess(s, e.rx, e.ry);
  bool inside = false;
  detail::Certificate result = detail::certifiedNearest(s, e.rx, e.ry, c, inside, dt_dx);
  if (result == detail::Certificate::kNotConverged && has_hint) {
    // The previous pixel's basin was a poor start (the row crossed a joint or the medial axis):
    // one more try from the angle guess.
    c = detail::angleGuess(s, e.rx, e.ry);
    result = detail::certifiedNearest(s, e.rx, e.ry, c, inside, dt_dx);
  }
  if (result != detail::Certificate::kCertified) {
    bound = c;
    has_bound = result == detail::Certificate::kUnproven;
    return false;
  }
  e.segment = c.segment;
  e.t = c.t;
  e.inside = inside;
  const detail::PowerCubic& seg = s.seg[c.segment];
  e.bx = seg.x(c.t);
  e.by = seg.y(c.t);
  const double d = std::sqrt(c.d2);
  e.d = inside ? -d : d;
  return true;
}

// Values (and, when jac != nullptr, the Jacobian row-major [channel][parameter]) of one ghost at
// the point whose distance `e` holds.
inline void shadeGhost(const GhostParameters& g, const detail::PreparedShape& s, const PointEval& e,
                       double* values, double* jac) {
  const int channels = g.channels;
  if (!jac) {
    double border = 0, inside = 0;
    transferValueWeights(e.d, g, border, inside);
    for (int c = 0; c < channels; ++c) values[c] = border * g.border[c] + inside * g.inside[c];
    return;
  }
  const TransferWeights w = transferWeights(e.d, g, true);
  for (int c = 0; c < channels; ++c) values[c] = w.border * g.border[c] + w.inside * g.inside[c];
  const ParameterLayout layout{channels};
  const int n = layout.count();
  std::fill(jac, jac + channels * n, 0.0);
  double grad[param::kShapeCount] = {};
  const bool needs_shape = w.border_d_distance != 0 || w.inside_d_distance != 0;
  if (needs_shape) distanceGradient(g, s, e, grad);
  for (int c = 0; c < channels; ++c) {
    double* row = jac + c * n;
    const double di_dd = w.border_d_distance * g.border[c] + w.inside_d_distance * g.inside[c];
    if (needs_shape)
      for (int k = 0; k < param::kShapeCount; ++k) row[k] = di_dd * grad[k];
    row[layout.ib(c)] = w.border;
    row[layout.ii(c)] = w.inside;
    const double di_df = w.border_d_falloff * g.border[c] + w.inside_d_falloff * g.inside[c];
    const double di_de = w.border_d_exponent * g.border[c] + w.inside_d_exponent * g.inside[c];
    row[w.is_inside ? layout.fi() : layout.fo()] = di_df;
    row[w.is_inside ? layout.ei() : layout.eo()] = di_de;
  }
}

// The values of a plain render (no derivative images) for pixels whose distances are known: the
// transfer function (a third of a fall-off pixel's time, evaluated pixel by pixel) for up to
// kCapacity pixels at once in vector lanes (transferValueWeights). Adds each pixel's value (the
// same bits as shadeGhost without a Jacobian) into its place in the image.
template <int kChannels>
class ShadingQueue {
 public:
  explicit ShadingQueue(const GhostParameters& g) : g_(g) {}

  void push(double distance, float* out) {
    distance_[count_] = distance;
    out_[count_] = out;
    if (++count_ == kCapacity) flush();
  }

  void flush() {
    transferValueWeights(distance_, count_, g_, border_, inside_);
    for (int i = 0; i < count_; ++i)
      for (int c = 0; c < kChannels; ++c)
        out_[i][c] += static_cast<float>(border_[i] * g_.border[c] + inside_[i] * g_.inside[c]);
    count_ = 0;
  }

 private:
  static constexpr int kCapacity = 64;
  const GhostParameters& g_;
  int count_ = 0;
  double distance_[kCapacity], border_[kCapacity], inside_[kCapacity];
  float* out_[kCapacity];
};

// Values (and Jacobian) of one ghost at model point q with the full search.
inline void evalGhost(const GhostParameters& g, const detail::PreparedShape& s, cv::Point2d q,
                      const SignedDistanceOptions& o, double* values, double* jac) {
  PointEval e;
  // Beyond the fall-off ranges the transfer function is constant: the distance need not be exact.
  evalDistance(s, q, o, e, g.inside_falloff, g.outside_falloff);
  shadeGhost(g, s, e, values, jac);
}

void checkInputs(std::span<const GhostParameters> ghosts, int channels, const RenderOptions& options,
                 const ViewTransform& view) {
  if (channels != 1 && channels != 3)
    throw std::invalid_argument("render: channels must be 1 or 3");
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("render options: " + error);
  if (!view.IsValid(&error)) throw std::invalid_argument("view transform: " + error);
  for (size_t i = 0; i < ghosts.size(); ++i) {
    if (ghosts[i].channels != channels)
      throw std::invalid_argument("render: ghost " + std::to_string(i) + " has " +
                                  std::to_string(ghosts[i].channels) + " channels, the image " +
                                  std::to_string(channels));
    if (!isValid(ghosts[i], &error))
      throw std::invalid_argument("render: ghost " + std::to_string(i) + ": " + error);
  }
}

// The core: adds every ghost into `image` (covering roi) and, when `derivatives` is given, fills
// each ghost's derivative images (allocated by the caller, zeroed).
void renderInto(std::span<const GhostParameters> ghosts, cv::Rect roi, cv::Mat& image,
                std::vector<GhostDerivativeImages>* derivatives, const RenderOptions& options,
                const ViewTransform& view) {
  const int channels = image.channels();
  std::vector<PreparedGhost> prepared;
  prepared.reserve(ghosts.size());
  std::vector<int> ghost_index;
  for (size_t i = 0; i < ghosts.size(); ++i) {
    PreparedGhost p;
    p.g = &ghosts[i];
    p.bounds = ghostPixelBounds(ghosts[i], view) & roi;
    p.count = parameterCount(channels);
    if (p.bounds.area() <= 0) continue;
    p.shape = detail::PreparedShape(ghosts[i], options.distance.samples_per_segment,
                                     options.distance.max_sample_turn_deg);
    prepared.push_back(p);
    ghost_index.push_back(static_cast<int>(i));
  }
  if (prepared.empty() || roi.area() <= 0) return;

  const int tile = options.tile_size;
  const int tiles_x = (roi.width + tile - 1) / tile, tiles_y = (roi.height + tile - 1) / tile;
  // Ghost lists per tile.
  std::vector<std::vector<int>> tile_ghosts(static_cast<size_t>(tiles_x) * tiles_y);
  for (size_t k = 0; k < prepared.size(); ++k) {
    const cv::Rect b = prepared[k].bounds;
    const int tx0 = (b.x - roi.x) / tile, tx1 = (b.x + b.width - 1 - roi.x) / tile;
    const int ty0 = (b.y - roi.y) / tile, ty1 = (b.y + b.height - 1 - roi.y) / tile;
    for (int ty = ty0; ty <= ty1; ++ty)
      for (int tx = tx0; tx <= tx1; ++tx) tile_ghosts[static_cast<size_t>(ty) * tiles_x + tx].push_back(static_cast<int>(k));
  }

  const double inv_scale = 1.0 / view.scale;
  const bool identity = view.isIdentity();
  // view.modelFromImage with the roll's cosine and sine taken once (the same arithmetic, so the
  // same points to the bit): it runs for every pixel.
  const double roll_cos = std::cos(view.roll_rad), roll_sin = std::sin(view.roll_rad);
  auto modelFromImage = [&](cv::Point2d p) {
    const double x = (p.x - view.image_center.x) / view.scale, y = (p.y - view.image_center.y) / view.scale;
    return cv::Point2d(view.model_center.x + roll_cos * x - roll_sin * y, view.model_center.y + roll_sin * x + roll_cos * y);
  };
  const SignedDistanceOptions& dopt = options.distance;
  const int block = options.block_size;

  const bool fast = dopt.method == NearestPointMethod::kSampledNewton;

  // The nearest points (t, segment, x) of the last three exact pixels of a row, and dt/dx where
  // the fast path gave it (NaN otherwise): t moves smoothly along a row, so extrapolating them
  // starts Newton close to the answer. From t alone (quadratic) the start is typically 1e-3 px off,
  // and Newton needs a second step to see that it has converged (a step below 1e-5 px); the cubic
  // Hermite extrapolation from the last two pixels' t and dt/dx is often within 1e-5 px, where the
  // first step already is that small.
  struct RowHistory {
    double t[3] = {0, 0, 0};
    double slope[3] = {0, 0, 0};
    int segment[3] = {-1, -1, -1};
    int x[3] = {0, 0, 0};
    // The last Hermite extrapolation's error (t − extrapolated), at x = hermite_x: its error term
    // (t⁗/6) changes slowly along a row, so adding it to the next one cancels most of that.
    double hermite_error = 0;
    int hermite_x = -1;
  };

  // Compiled for each combination of derivative images (with or without: without, every
  // derivative branch and the nearest point's coordinates, which only derivatives read, fold
  // away) and channel count (1 or 3: the per-channel loops unroll).
  auto renderTile = [&]<bool kDerivatives, int kChannels>(int tile_index) {
    std::vector<RowHistory> histories;
    const int tx = tile_index % tiles_x, ty = tile_index / tiles_x;
    const cv::Rect tile_rect(roi.x + tx * tile, roi.y + ty * tile, tile, tile);
    double values[3];
    std::vector<double> jac(static_cast<size_t>(kChannels) * parameterCount(kChannels));
    for (int k : tile_ghosts[tile_index]) {
      const PreparedGhost& pg = prepared[k];
      const GhostParameters& g = *pg.g;
      const cv::Rect region = pg.bounds & tile_rect;
      if (region.area() <= 0) continue;
      GhostDerivativeImages* deriv = kDerivatives ? &(*derivatives)[ghost_index[k]] : nullptr;
      const int n = pg.count;
      const float inside_value[3] = {static_cast<float>(g.inside[0]), static_cast<float>(g.inside[1]),
                                     static_cast<float>(g.inside[2])};
      ShadingQueue<kChannels> shading(g);
      for (int by = region.y; by < region.y + region.height; by += block) {
        // The nearest points of the last three exact pixels of each row of this band of blocks:
        // kept across the blocks of the band, so a row continues into the next block.
        histories.assign(static_cast<size_t>(block), RowHistory{});
        for (int bx = region.x; bx < region.x + region.width; bx += block) {
          const int bw = std::min(block, region.x + region.width - bx);
          const int bh = std::min(block, region.y + region.height - by);
          // Classify the block by the distance at its centre: d is 1-Lipschitz in model pixels,
          // and image pixels are 1/scale model pixels.
          int mode = 0;  // 0 per pixel, 1 constant inside (d ≤ −Fi), 2 nothing (d ≥ Fo)
          cv::Point2d centre(bx + 0.5 * bw, by + 0.5 * bh);
          PointEval ec;
          double reach = 0;
          // The nearest point of the centre (exact when mode == 0): the first pixels' start.
          detail::Candidate centre_nearest;
          bool has_centre_nearest = false;
          if (bw * bh > 1) {
            const cv::Point2d qc = identity ? centre : modelFromImage(centre);
            reach = 0.5 * std::sqrt(double(bw * bw + bh * bh)) * inv_scale;
            detail::Candidate unused;
            bool has_unused = false;
            if (fast && evalDistanceCertified(pg.shape, qc, false, {}, ec, unused, has_unused)) {
              centre_nearest = {ec.segment, ec.t, ec.d * ec.d};
              has_centre_nearest = true;
            } else if (fast && detail::depthLowerBound(pg.shape, qc.x - pg.shape.mx, -std::abs(qc.y - pg.shape.my)) >=
                                   g.inside_falloff + reach + 1e-7) {
              // Deep inside (where the certificate's rolling disc is too small): the sample
              // polygon proves the whole block deeper than Fi, as the full search below would
              // (its distance is never below the true one); 1e-7 px covers rounding.
              mode = 1;
            } else {
              evalDistance(pg.shape, qc, dopt, ec, g.inside_falloff + reach, g.outside_falloff + reach);
            }
            if (mode == 1 || ec.d + reach <= -g.inside_falloff) mode = 1;
            else if (ec.d - reach >= g.outside_falloff) mode = 2;
          }
          if (mode == 2) continue;
          if (mode == 1) {  // the whole block is deeper than Fi: the constant Ii (vectorizable)
            const ParameterLayout layout{kChannels};
            for (int y = by; y < by + bh; ++y) {
              float* out = image.ptr<float>(y - roi.y) + static_cast<size_t>(bx - roi.x) * kChannels;
              for (int i = 0; i < bw; ++i)
                for (int c = 0; c < kChannels; ++c) out[i * kChannels + c] += inside_value[c];
              if (deriv)
                for (int c = 0; c < kChannels; ++c) {
                  float* d = deriv->images[layout.ii(c)].ptr<float>(y - deriv->rect.y) +
                             static_cast<size_t>(bx - deriv->rect.x) * kChannels + c;
                  for (int i = 0; i < bw; ++i) d[i * kChannels] = 1.0f;
                }
            }
            continue;
          }
          // Per-pixel classification without a square root: a pixel at image distance r from the
          // centre is deeper than Fi when r ≤ (−Fi − d_c)·scale, farther than Fo when
          // r ≤ (d_c − Fo)·scale.
          const double deep_radius = (-g.inside_falloff - ec.d) * view.scale;
          const double far_radius = (ec.d - g.outside_falloff) * view.scale;
          const double deep_radius2 = deep_radius >= 0 ? deep_radius * deep_radius : -1;
          const double far_radius2 = far_radius >= 0 ? far_radius * far_radius : -1;
          // Below the cutoffs the centre's distance is exact: every pixel of the block is within
          // |d| + reach of the outline, which bounds the pieces that can be nearest. Collected
          // only when a pixel needs the full search.
          detail::BlockPieces pieces;
          pieces.certified = false;
          bool pieces_ready = !(mode == 0 && bw * bh > 1 && fast);
          detail::Candidate row_start = centre_nearest;  // the previous row's first pixel
          bool has_row_start = has_centre_nearest;
          for (int y = by; y < by + bh; ++y) {
            float* out = image.ptr<float>(y - roi.y) + static_cast<size_t>(bx - roi.x) * kChannels;
            detail::Candidate hint = row_start;  // the previous pixel's nearest point (coherence)
            bool has_hint = has_row_start;
            RowHistory& history = histories[static_cast<size_t>(y - by)];
            double* history_t = history.t;
            double* history_slope = history.slope;
            int* history_segment = history.segment;
            int* history_x = history.x;
            if (history_segment[0] >= 0 && history_x[0] == bx - 1) {  // the row's left neighbour
              hint = {history_segment[0], history_t[0], 0};
              has_hint = true;
            }
            bool first_in_row = true;
            double last_d = 0;  // the last exact distance in this row, at x = last_x
            int last_x = 0;
            bool has_last = false;
            for (int x = bx; x < bx + bw; ++x, out += kChannels) {
              const cv::Point2d p(x + 0.5, y + 0.5);
              int pixel_mode = mode;
              if (mode == 0 && bw * bh > 1) {
                // The same bounds per pixel, with its own distance from the centre, and from the
                // last pixel of the row whose distance is known exactly (d is 1-Lipschitz).
                const double r2 = (p.x - centre.x) * (p.x - centre.x) + (p.y - centre.y) * (p.y - centre.y);
                if (r2 <= deep_radius2) pixel_mode = 1;
                else if (r2 <= far_radius2) continue;
                if (has_last && pixel_mode == 0) {
                  const double step = (x - last_x) * inv_scale;
                  if (last_d + step <= -g.inside_falloff) pixel_mode = 1;
                  else if (last_d - step >= g.outside_falloff) continue;
                }
              }
              // A pixel deeper than Fi: the constant Ii (what the transfer function gives there, bit
              // for bit: Ib·0 + Ii·1), and ∂/∂Ii = 1.
              auto addInside = [&] {
                for (int c = 0; c < kChannels; ++c) out[c] += inside_value[c];
                if (deriv) {
                  const ParameterLayout layout{kChannels};
                  for (int c = 0; c < kChannels; ++c)
                    deriv->images[layout.ii(c)].ptr<float>(y - deriv->rect.y)[(x - deriv->rect.x) * kChannels + c] = 1.0f;
                }
              };
              if (pixel_mode == 1) {
                addInside();
                continue;
              }
              const cv::Point2d q = identity ? p : modelFromImage(p);
              PointEval e;
              bool exact = false;  // e.d is the exact distance (no cutoff)
              detail::Candidate start = hint;
              double hermite = std::numeric_limits<double>::quiet_NaN();  // this pixel's extrapolation
              if (history_segment[0] == hint.segment && history_x[0] == x - 1) {
                const bool same1 = history_segment[1] == hint.segment && history_x[1] == x - 2;
                const bool same2 = same1 && history_segment[2] == hint.segment && history_x[2] == x - 3;
                // dt/dx is per model pixel along x: one image pixel in the identity view.
                const bool slopes = identity && !std::isnan(history_slope[0]);
                if (slopes && same1 && !std::isnan(history_slope[1])) {
                  // The cubic through (x − 2, t, dt/dx) and (x − 1, t, dt/dx), at x.
                  hermite = 5 * history_t[1] + 2 * history_slope[1] - 4 * history_t[0] + 4 * history_slope[0];
                  start.t = history.hermite_x == x - 1 ? hermite + history.hermite_error : hermite;
                } else if (slopes)
                  start.t = history_t[0] + history_slope[0];
                else if (same2)  // quadratic extrapolation
                  start.t = 3 * history_t[0] - 3 * history_t[1] + history_t[2];
                else if (same1)  // linear
                  start.t = 2 * history_t[0] - history_t[1];
                start.t = std::clamp(start.t, 0.0, 1.0);
              }
              detail::Candidate bound;
              bool has_bound = false;
              double slope = std::numeric_limits<double>::quiet_NaN();
              if (fast && evalDistanceCertified(pg.shape, q, has_hint, start, e, bound, has_bound, &slope)) {
                exact = true;
              } else if (fast && bw * bh > 1 && mode == 0) {
                slope = std::numeric_limits<double>::quiet_NaN();  // the block search gives none
                // The fast path fails mostly deeper than the outline's smallest radius of curvature
                // (its rolling disc is too small): half of those pixels (on the benchmark frame) are
                // deeper than Fi, which the sample polygon proves for ~60 instructions instead of
                // the block search's ~2000 (as for the block centres above).
                if (detail::depthLowerBound(pg.shape, e.rx, e.ry) >= g.inside_falloff + 1e-7) {
                  addInside();
                  continue;
                }
                if (!pieces_ready) {
                  pieces = detail::collectBlockPieces(pg.shape, ec.rx, ec.ry, reach, std::abs(ec.d) + reach);
                  pieces_ready = true;
                }
                if (pieces.certified) {
                  if (has_bound) {
                    hint = bound;
                    has_hint = true;
                  }
                  evalDistanceInBlock(pg.shape, pieces, q, dopt.newton_steps, hint, has_hint, e);
                  exact = true;  // the block search has no cutoff
                }
              }
              if (!exact && !pieces.certified) evalDistance(pg.shape, q, dopt, e, g.inside_falloff, g.outside_falloff);
              if (exact) {
                for (int h = 2; h > 0; --h) {
                  history_t[h] = history_t[h - 1];
                  history_slope[h] = history_slope[h - 1];
                  history_segment[h] = history_segment[h - 1];
                  history_x[h] = history_x[h - 1];
                }
                history.hermite_error = e.t - hermite;
                history.hermite_x = std::isnan(hermite) ? -1 : x;
                history_t[0] = e.t;
                history_slope[0] = slope;
                history_segment[0] = e.segment;
                history_x[0] = x;
                hint = {e.segment, e.t, e.d * e.d};
                has_hint = true;
                if (first_in_row) {
                  row_start = hint;
                  has_row_start = true;
                  first_in_row = false;
                }
                last_d = e.d;
                last_x = x;
                has_last = true;
              }
              if (!deriv) {
                shading.push(e.d, out);
                continue;
              }
              shadeGhost(g, pg.shape, e, values, jac.data());
              for (int c = 0; c < kChannels; ++c) out[c] += static_cast<float>(values[c]);
              const size_t offset = static_cast<size_t>(x - deriv->rect.x) * kChannels;
              for (int kk = 0; kk < n; ++kk) {
                float* d = deriv->images[kk].ptr<float>(y - deriv->rect.y) + offset;
                for (int c = 0; c < kChannels; ++c) d[c] = static_cast<float>(jac[c * n + kk]);
              }
            }
          }
        }
      }
      shading.flush();
    }
  };

  const int tile_count = tiles_x * tiles_y;
  auto renderTiles = [&](int begin, int end) {
    for (int i = begin; i != end; ++i) {
      if (derivatives)
        channels == 1 ? renderTile.template operator()<true, 1>(i) : renderTile.template operator()<true, 3>(i);
      else
        channels == 1 ? renderTile.template operator()<false, 1>(i) : renderTile.template operator()<false, 3>(i);
    }
  };
  if (options.parallel && tile_count > 1) {
    tbb::parallel_for(tbb::blocked_range<int>(0, tile_count, 1),
                      [&](const tbb::blocked_range<int>& r) { renderTiles(r.begin(), r.end()); });
  } else {
    renderTiles(0, tile_count);
  }
}

}  // namespace

void evaluateGhost(const GhostParameters& ghost, cv::Point2d p, double* values, double* jacobian,
                   const SignedDistanceOptions& distance, const ViewTransform& view) {
  const detail::PreparedShape s(ghost, distance.samples_per_segment, distance.max_sample_turn_deg);
  evalGhost(ghost, s, view.modelFromImage(p), distance, values, jacobian);
}

void addGhosts(std::span<const GhostParameters> ghosts, cv::Rect roi, cv::Mat& image,
               const RenderOptions& options, const ViewTransform& view) {
  const int channels = image.channels();
  checkInputs(ghosts, channels, options, view);
  if (image.depth() != CV_32F || image.size() != roi.size())
    throw std::invalid_argument("addGhosts: image must be CV_32F of the region's size");
  renderInto(ghosts, roi, image, nullptr, options, view);
}

cv::Mat renderGhosts(std::span<const GhostParameters> ghosts, cv::Rect roi, int channels,
                     const RenderOptions& options, const ViewTransform& view) {
  checkInputs(ghosts, channels, options, view);
  if (roi.width < 0 || roi.height < 0) throw std::invalid_argument("render: negative region size");
  cv::Mat image(roi.size(), CV_MAKETYPE(CV_32F, channels), cv::Scalar::all(0));
  renderInto(ghosts, roi, image, nullptr, options, view);
  return image;
}

cv::Mat renderGhosts(std::span<const GhostParameters> ghosts, cv::Size size, int channels,
                     const RenderOptions& options, const ViewTransform& view) {
  return renderGhosts(ghosts, cv::Rect(0, 0, size.width, size.height), channels, options, view);
}

RenderedGhosts renderGhostsWithDerivatives(std::span<const GhostParameters> ghosts, cv::Rect roi,
                                           int channels, const RenderOptions& options,
                                           const ViewTransform& view) {
  checkInputs(ghosts, channels, options, view);
  if (roi.width < 0 || roi.height < 0) throw std::invalid_argument("render: negative region size");
  RenderedGhosts r;
  r.image = cv::Mat(roi.size(), CV_MAKETYPE(CV_32F, channels), cv::Scalar::all(0));
  r.derivatives.resize(ghosts.size());
  // parameterCount images per ghost, zeroed: tens of megabytes for a frame of ghosts, so allocated
  // and cleared in parallel too.
  auto allocate = [&](size_t i) {
    GhostDerivativeImages& d = r.derivatives[i];
    d.rect = ghostPixelBounds(ghosts[i], view) & roi;
    if (d.rect.area() <= 0) d.rect = cv::Rect(roi.x, roi.y, 0, 0);
    d.images.resize(parameterCount(channels));
    for (auto& m : d.images) m = cv::Mat(d.rect.size(), CV_MAKETYPE(CV_32F, channels), cv::Scalar::all(0));
  };
  if (options.parallel && ghosts.size() > 1)
    tbb::parallel_for(size_t{0}, ghosts.size(), allocate);
  else
    for (size_t i = 0; i < ghosts.size(); ++i) allocate(i);
  renderInto(ghosts, roi, r.image, &r.derivatives, options, view);
  return r;
}

}  // namespace flarekit::model
