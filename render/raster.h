#pragma once
// Ghost rasterization (Hullin 2011 §3.2; Bodonyi & Kunkli 2023 §4). Each cell of a traced ray
// grid is a quad on the sensor, split into two triangles along a fixed diagonal. A pixel centre
// inside a triangle (top-left fill rule, so shared edges count once) receives
//   irradiance = T · E · A(u, v) · C(r_rel)
// with T·E, (u, v) and r_rel interpolated linearly over the triangle, A the aperture (antialiased
// over one pixel footprint) and C = clamp(0.5 + (1 − r_rel)/footprint) the rim vignetting. E is
// the ray grid's irradiance (pupil area / sensor area of its cells), Gouraud-shaded: at each ray
// that of the cells beside it (Hullin 2011 §5), so a ghost's light does not step at cell edges.
// Triangles smaller than a pixel (caustics, distant ghosts) are splatted instead: their flux goes
// to the pixels under points spread over them, so none is lost between pixel centres.
// Both rasterizers below call the same per-pixel function, so they give the same image up to
// the order of floating-point additions.

#include <vector>

#include <opencv2/core.hpp>

#include "render/aperture.h"
#include "render/tracer.h"

namespace flarekit::render {

// Triangles smaller than this (in pixels) are splatted rather than point-sampled.
inline constexpr float kSplatArea = 1.0f;

struct RasterTriangle {
  float ox = 0, oy = 0;            // origin (first vertex), pixel coordinates
  float ea[3], eb[3], ec[3];       // edge functions e = a·(x−ox) + b·(y−oy) + c, ≥ 0 inside
  bool top_left[3];                // edges that own their pixel centres on ties
  float u0, ux, uy, v0, vx, vy;    // aperture coordinates: u = u0 + ux (x−ox) + uy (y−oy)
  float r0, rx, ry;                // r_rel
  float t0, tx, ty;                // transmission × irradiance (transmission alone: flat, below)
  float aperture_footprint;        // aperture units spanned by one pixel
  float rim_footprint;             // r_rel units spanned by one pixel
  cv::Vec3f weight;                // colour weight; × E_in × pupil area / sensor area when flat
                                   // (splatted, or beside no cell showing the ghost)
  // Every point lies inside the aperture and the rims by at least half a pixel footprint
  // (the distance functions are concave, so checking the corners suffices): A = C = 1.
  bool interior;
  // Rim band triangles (not interior): every point lies inside the rims, or inside the aperture,
  // by a whole footprint and 1e-5 more, so that C = 1, or A = 1, comes out exactly at every pixel
  // however the interpolation rounds; the rasterizer then skips computing it.
  bool rim_clear, aperture_clear;
  // Below kSplatArea pixels the triangle's flux is splatted over points inside it instead of
  // sampled at pixel centres; its corners (pixels) and area are kept for that.
  bool splat;
  float px[3], py[3];
  float area_px;
  int x0, y0, x1, y1;              // pixel bounding box, inclusive, clipped to the image
  int batch;                       // which (ghost, wavelength) it came from
};

// How a traced grid maps to pixels: sensor millimetres from the optical axis to pixel
// coordinates, the axis at the image centre plus axis_offset_px.
struct SensorMapping {
  int width_px = 0, height_px = 0;
  double pixel_pitch_mm = 0.0;
  cv::Point2d axis_offset_px{0.0, 0.0};  // FlareRenderOptions::optical_axis_offset_px
  double toPixelX(double x_mm) const {
    return width_px * 0.5 + axis_offset_px.x + x_mm / pixel_pitch_mm;
  }
  double toPixelY(double y_mm) const {
    return height_px * 0.5 + axis_offset_px.y + y_mm / pixel_pitch_mm;
  }
};

// Builds the triangles of a traced grid. `cell_flux` = E_in × the beam cross-section of one
// grid cell (spacing² · |d_z|); `weight` the colour weight of this wavelength. Quads with two or
// more dead corners are skipped, a quad with one gives the triangle of its three live corners
// (when not refined); so are quads whose four corners all lie outside the ghost (r_rel > 1 or
// |(u, v)| > 1), as in Bodonyi & Kunkli §4.1. Appends to `out`.
// When `refine` is given, quads across a discontinuous edge — a dead corner next to a valid one,
// r_rel crossing 1 with a jump of more than kRefineJump within the quad (rays turning grazing),
// or a fold of the map (a caustic: the quad's orientation on the sensor is mixed or differs from
// a neighbour's) — are left out and their indices (j·n + i of the quad's first corner) appended to it,
// for the caller to trace more finely.
inline constexpr float kRefineJump = 0.3f;
// Triangles entirely outside a rim or a straight iris edge are dropped.
// The grid's rays start at index `first_ray` of `rays` (several grids traced together, see
// traceGrids); rays.n is its side.
void buildTriangles(const TracedRays& rays, const SensorMapping& mapping, const Aperture& aperture,
                    double cell_flux, const cv::Vec3f& weight, int batch,
                    std::vector<RasterTriangle>* out, std::vector<int>* refine = nullptr,
                    size_t first_ray = 0);

// Value (before the colour weight) of a triangle at pixel centre (x, y), 0 outside it.
float shadeTriangle(const RasterTriangle& t, const Aperture& aperture, float x, float y);

// Working memory the rasterizers keep between calls when given one (FlareRenderer holds one per
// renderer): the per-ghost buffers, whose pages stay mapped from frame to frame. A per-ghost
// buffer covers the ghost's bounding box, up to the whole frame (3.7 MB a plane at 1280×720):
// allocated afresh per batch, the Heliar's 84 batches took 20–170 k page faults a frame. One call
// at a time per RasterScratch.
class RasterScratch {
 public:
  // Buffer number `slot` (created empty the first time; the caller sizes it).
  std::vector<float>& buffer(size_t slot);

 private:
  std::vector<std::vector<float>> buffers_;
};

// Reference: rasterizes one batch after another, each into its own buffer over its bounding
// box, added to `image` (CV_32FC3, must have the mapping's size) in batch order. Parallel over
// batches; the same image whatever the threads. The buffers come from `scratch` when given (same
// image either way).
void rasterizePerGhost(const std::vector<std::vector<RasterTriangle>>& batches,
                       const Aperture& aperture, cv::Mat* image, RasterScratch* scratch = nullptr);

// Only the batches for which keep[batch] is true (nullptr = all), into `image`, serially.
void rasterizeBatches(const std::vector<std::vector<RasterTriangle>>& batches,
                      const std::vector<bool>* keep, const Aperture& aperture, cv::Mat* image);

struct TileOptions {
  // Bodonyi & Kunkli §4.3/§5.4 use 128² coarse and 8² fine tiles on a GPU. On a CPU each
  // (triangle, tile, row) costs a span set-up, which dominates small tiles: single-threaded on
  // the Nikon 28-75 at 1280×720 (2.3 M triangles) 8² fine tiles took 11.4 s, 16² 6.3 s, 64²
  // 3.0 s, 128² 2.5 s (per-ghost: 6.6–7.4 s). 256² fine tiles (their three planes, 768 KB,
  // still in L2) split fewer triangles than 128²: the tiles' work fell from 47 to 44 ms on the
  // Heliar and from 836 to 734 ms on the Nikon (one thread, 10°), and their 15 tiles still share
  // out well over two cores (the measured tile times, dealt greedily in order to two workers,
  // end within 4 % of an even split). 320² and 512² tiles, whose planes spill from L2, took
  // longer.
  int coarse_tile_px = 256;  // first-level tiles
  int fine_tile_px = 256;    // second-level tiles; must divide coarse_tile_px
  bool IsValid(std::string* error) const;
};

// Tiled accumulation (Bodonyi & Kunkli §4.3–4.4): all batches' triangles are binned into coarse
// then fine screen tiles; every pixel sums the triangles of its tile once, in a tile-local
// buffer, and is written once. Adds to `image`; with `overwrite`, writes every pixel instead (the
// same pixels as adding to a zeroed image, so `image` need not be initialised: no serial pass
// over the frame to zero it first).
void rasterizeTiled(const std::vector<std::vector<RasterTriangle>>& batches,
                    const Aperture& aperture, const TileOptions& options, cv::Mat* image,
                    bool overwrite = false);

}  // namespace flarekit::render
