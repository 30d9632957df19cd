#pragma once
// The renderer's building blocks, shared by renderFlare, the benchmarks and the tests: the
// prepared state of one render, ray bounding per ghost, the traced triangles of one ghost at one
// wavelength, the direct path, the paraxial sprite of a ghost, and a brute-force reference.

#include <optional>
#include <vector>

#include <opencv2/core.hpp>

#include "render/aperture.h"
#include "render/coating.h"
#include "render/flare_renderer.h"
#include "render/ghosts.h"
#include "render/raster.h"
#include "render/spectrum.h"
#include "render/tracer.h"

namespace flarekit::render {

struct RenderSetup {
  Lens lens;                             // stopped down / refocused working copy
  std::vector<SurfaceCoating> coatings;  // per surface
  std::vector<SpectralSample> samples;   // wavelengths and colour weights
  std::vector<ReflectanceTables> tables; // per sample
  SensorMapping mapping;
  cv::Vec3d direction;                   // unit direction of the light's rays
  double light_irradiance = 1.0;
  Aperture aperture{ApertureShape{}};
  double search_half_mm = 1.0;           // half-size of the square searched for each ghost's rays
};

// Applies the options to a copy of the lens (f-number, focus) and precomputes the rest.
// Throws InputError for invalid options. prepareLensSetup then aimSetup.
RenderSetup prepareRender(const Lens& lens, const LightDirection& light,
                          const FlareRenderOptions& options);
// The part of the setup that depends on the lens and the lens options only (sameLensOptions):
// the working lens, its coatings, the wavelengths and their reflectance tables. A renderer keeps
// it over the frames of one sequence (the tables were a tenth of a Heliar matrix frame) and only
// aims it at each frame's light. Throws InputError for invalid options.
RenderSetup prepareLensSetup(const Lens& lens, const FlareRenderOptions& options);
// The rest of the setup, for one light: the image mapping, the light's direction and irradiance,
// the aperture and the square searched for each ghost's rays. Throws InputError for invalid
// options.
void aimSetup(RenderSetup& setup, const LightDirection& light, const FlareRenderOptions& options);
// Whether prepareLensSetup makes the same lens, coatings, wavelengths and reflectance tables from
// both option sets (for one lens): every option those depend on is the same.
bool sameLensOptions(const FlareRenderOptions& a, const FlareRenderOptions& b);

// Coatings as FlareRenderOptions describes them.
std::vector<SurfaceCoating> surfaceCoatings(const Lens& lens, const FlareRenderOptions& options);

// Ray bounding (DESIGN "Ray Bounding"; Bodonyi & Kunkli §4.1): a coarse 33² trace over the
// first surface's rim finds the rays that pass every rim (r_rel ≤ 1) and the stop circle; the
// square around them, one coarse cell wider, is where the fine grid goes. Empty when none pass.
std::optional<RayGrid> boundGhost(const RenderSetup& setup, const CompiledPath& path);

// Traces one ghost at one sample on an n×n grid inside its bound and appends its triangles.
// Returns the number of rays traced (0 when the ghost does not reach the image).
long long traceGhostTriangles(const RenderSetup& setup, const Ghost& ghost, int sample, int n,
                              int batch, std::vector<RasterTriangle>* out);

// Brute-force reference: n×n rays over the ghost's bound (widened by 10 %), each ray that passes
// the rims deposits its own flux T·A(u, v)·(cell area) into the pixel it lands in. Adds to image.
void splatGhost(const RenderSetup& setup, const Ghost& ghost, int sample, int n, cv::Mat* image);

// The direct (no reflection) light at one sample: flux reaching the sensor through the iris
// (E_in × mm²) and its flux-weighted centroid on the sensor (pixels).
struct DirectLight {
  double flux = 0.0;
  cv::Point2d center_px{0, 0};
  bool valid = false;
};
DirectLight traceDirectLight(const RenderSetup& setup, int sample, int n = 48);

// Paraxial intensity estimate of a ghost (Lee & Eisemann §3): reflectances at normal incidence at
// 550 nm, times the paraxial area gain capped at a ghost one pixel across.
double ghostIntensityEstimate(const RenderSetup& setup, const Ghost& ghost);

// Transmission of a ghost's path at normal incidence (product of 1 − R and the two R).
double pathTransmissionAtNormal(const RenderSetup& setup, const std::vector<PathEvent>& path,
                                double wavelength_nm);

// The matrix method's sprite of one ghost (all samples) added to `image`.
void addMatrixSprite(const RenderSetup& setup, const Ghost& ghost, cv::Mat* image);
// All ghosts' sprites, rows in parallel. With `zero_first`, each row is zeroed just before its
// sprites are added, so `image` (of the right size and type) need not be initialised: the same
// pixels as zeroing it first, in one parallel pass over the frame instead of a serial memset of
// 11 MB before it (1280×720; the Heliar's matrix render took 15 % less CPU time).
void addMatrixSprites(const RenderSetup& setup, const std::vector<Ghost>& ghosts, cv::Mat* image,
                      bool zero_first = false);

}  // namespace flarekit::render
