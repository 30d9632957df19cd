#pragma once
// The physical ghost renderer (Hullin et al. 2011; Lee & Eisemann 2013; Bodonyi & Kunkli 2023):
// one call renders the flare of a lens for one light direction.
//
// Radiometric unit. Every image is *relative sensor irradiance*: the irradiance on the sensor
// divided by the irradiance E_in that the (collimated) light delivers on a plane normal to its
// direction at the entrance pupil. A ghost that spreads the light falling on a pupil area A over a
// sensor area A' with transmission T has the value T·A/A'. The light's own image (the focused
// spot) carries its whole transmitted flux T·A_pupil·E_in spread by the starburst/PSF, so its
// peak pixel is A_pupil/A_pixel ≈ 10⁵–10⁶ times brighter than a ghost of value ~1: a capture of
// it saturates as a real one does. To turn a pixel value into photo-electrons a camera model
// multiplies by E_in·(pixel area)·(quantum efficiency)·(exposure time)/(photon energy) — in
// FlareKit that product is SensorModel::electrons_per_unit_s × exposure_s (render/sensor.h).
//
// Colour: R, G, B are linear sRGB primaries. In RGB mode the channels are the renders at 650,
// 510 and 475 nm; in spectral mode N wavelengths over 380–780 nm are integrated with the CIE 1931
// colour-matching functions and converted to linear sRGB, normalised so that a spectrally flat
// (equal-energy) light of relative irradiance 1 gives Y = 1.
//
// Geometry (docs/design.md, Conventions): the optical axis meets the image at (W/2, H/2) (or
// where FlareRenderOptions::optical_axis_offset_px moves it), pixel (i, j) is centred at
// (i + 0.5, j + 0.5), x right, y down, square pixels. θ > 0 moves the light's image towards −x;
// the roll φ turns the light direction about the optical axis so the light's image sits on the
// ray from the axis at 180° + φ measured counter-clockwise on screen (positive φ turns the flare
// counter-clockwise as displayed, as model/ and predict/ do). The iris keeps its orientation (the
// camera does not roll).
//
// Threading: renderFlare may be called from several threads at once; each call uses TBB inside.
// FlareRenderer (below) keeps its working memory between renders.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/exr.h"
#include "render/aperture.h"
#include "render/lens.h"

namespace flarekit::render {

// Direction of the (distant) light relative to the camera.
struct LightDirection {
  double angle_deg = 0.0;  // θ: angle between the light and the optical axis (0 = on axis)
  double roll_deg = 0.0;   // φ: rotation about the optical axis (0 = light in the horizontal plane)
};

enum class RenderMethod {
  kTiled,     // bundle tracing + tiled accumulation of all ghosts' quads (Bodonyi & Kunkli §4)
  kPerGhost,  // bundle tracing + one rasterization pass per ghost (Hullin §3.2, the reference)
  kMatrix,    // paraxial ghost matrices (Lee & Eisemann §3): one aperture sprite per ghost
};

struct FlareRenderOptions {
  int width_px = 1280;   // image width in pixels
  int height_px = 720;   // image height in pixels
  // Sensor size in mm. The image is the largest centred crop of this sensor with square pixels:
  // pixel pitch = min(sensor_width_mm / width_px, sensor_height_mm / height_px).
  double sensor_width_mm = 36.0;
  double sensor_height_mm = 24.0;
  // Principal point: where the optical axis meets the image, in pixels from the image centre
  // (x right, y down; sub-pixel values work), as on a sensor whose centre sits (−dx, −dy) pixel
  // pitches from the axis. Everything drawn moves with it. At most the image size per axis;
  // default (0, 0) = the centre.
  cv::Point2d optical_axis_offset_px{0.0, 0.0};
  // Working f-number; 0 = the lens's own stop opening. Larger values stop the iris down
  // (stopDown in render/lens.h); smaller than the widest opening is an error.
  double f_number = 0.0;
  // true: sensor at the paraxial infinity focus instead of the file's sensor distance.
  bool focus_at_infinity = false;
  // 0 = RGB mode (three wavelengths 650/510/475 nm). N ≥ 3 = spectral mode with N wavelengths
  // spread evenly over 380–780 nm, integrated with the CIE 1931 colour-matching functions.
  int spectral_samples = 0;
  // Rays per side of the entrance-pupil grid for each ghost and wavelength (Hullin §3.2 uses
  // 16²–128²); the grid is bounded per ghost to the part of the pupil that reaches the sensor.
  int grid_size = 64;
  RenderMethod method = RenderMethod::kTiled;
  // Keep only the N brightest ghosts by the intensity estimate (0 = all).
  int max_ghosts = 0;
  // Drop ghosts whose intensity estimate is below this fraction of the brightest one (0 = none).
  double min_relative_intensity = 0.0;
  // Keep only ghosts whose two reflections lie on the same side of the stop (the ones that cross
  // the stop once; OpenLensFlare / LensFlareFramework convention).
  bool same_side_of_stop_only = false;
  // Coatings: every interface carries one quarter-wave layer of index coating_ior (or the lens
  // file's coating_ior when it names one and this is left at 0) designed for its own coating_nm,
  // or for default_coating_nm where the file gives none. coating_override_nm > 0 replaces every
  // design wavelength; uncoated = true removes all coatings (bare Fresnel reflection).
  double coating_ior = 0.0;           // 0 = lens file's value, else 1.38 (MgF₂)
  double default_coating_nm = 620.0;  // for surfaces without coating_nm (lenses/README.md)
  double coating_override_nm = 0.0;   // 0 = per-surface values
  bool uncoated = false;
  ApertureShape aperture;  // iris shape (default 6 straight blades)
  // The light's own image: a bright spot carrying the flux that passes the lens directly, spread
  // by the starburst (Fraunhofer pattern of the iris, Hullin §3.3). Off = ghosts only.
  bool light_source = true;
  bool starburst = true;  // shape the source spot as the iris's power spectrum; false = a point
  // Radius of the starburst sprite in pixels (its extent at 550 nm; longer wavelengths spread
  // further). 0 = 1/8 of the image diagonal.
  double starburst_radius_px = 0.0;
  // Fraction of the source flux spread into a wide halo around it (scatter; 0 = none).
  double halo_fraction = 0.0;
  // Keep every ghost as its own image in FlareImage::ghosts (ground-truth layers).
  bool ghost_layers = false;
  // Scale of the incident light (E_in in the units above; 1 = relative irradiance).
  double light_irradiance = 1.0;

  bool IsValid(std::string* error) const;
};

// One ghost's ground truth.
struct GhostRecord {
  int id = 0;         // stable index over all two-reflection sequences (render/ghosts.h)
  int surface_a = 0;  // first reflection (the later surface, index into Lens::surfaces)
  int surface_b = 0;  // second reflection (b < a)
  double intensity_estimate = 0.0;  // ranking estimate (relative to E_in)
  // Measured on the rendered ghost layer (luminance of its image), so only filled when
  // FlareRenderOptions::ghost_layers: energy = Σ pixel luminance (relative irradiance × pixels),
  // luminance centroid, and bounding box of the pixels above 1e-4 of its peak (empty when the
  // ghost is off the image).
  double energy = 0.0;
  cv::Point2d centroid_px{0, 0};
  cv::Rect bbox_px;
  cv::Mat image;  // CV_32FC3, only when FlareRenderOptions::ghost_layers
};

// What happened in one render (a summary).
struct RenderSummary {
  int ghosts_enumerated = 0;  // all two-reflection sequences of the lens
  int ghosts_rendered = 0;    // after culling
  int wavelengths = 0;
  long long rays_traced = 0;  // rays traced (bounding passes + grids, over ghosts and wavelengths)
  int threads = 0;
  double trace_ms = 0.0, raster_ms = 0.0, source_ms = 0.0, total_ms = 0.0;
  std::string BriefReport() const;
};

struct FlareImage {
  cv::Mat radiance;  // CV_32FC3 (R,G,B), width_px × height_px, relative sensor irradiance
  // Where the light's own image falls (pixels; may lie outside the image).
  cv::Point2d light_image_px{0, 0};
  std::vector<GhostRecord> ghosts;  // rendered ghosts, brightest estimate first
  // flarekit.* metadata for the EXR header: lens, angle, roll, f-number, method, wavelengths,
  // grid, pixel pitch, light image position, radiometric unit, and the optical axis offset
  // (flarekit.optical_axis_offset_px) when it is not (0, 0).
  ExrAttributes attributes;
  RenderSummary summary;
};

// Renders the flare. Throws InputError when the options are invalid (message from IsValid) or the
// f-number cannot be reached. The lens is not modified. A one-off FlareRenderer: for a sequence of
// renders, keep a FlareRenderer and a FlareImage instead.
FlareImage renderFlare(const Lens& lens, const LightDirection& light,
                       const FlareRenderOptions& options);

// Renders flares one after another with the same working memory: the triangle lists of the traced
// ghosts, and the image planes of the FlareImage it renders into. A sequence of renders of one
// size (a capture sweep, the simulated camera, a benchmark) then allocates nothing large after the
// first one. A fresh 1280×720 RGB image is 11 MB that the allocator maps from the operating system
// and returns to it after each frame; its first-touch page faults alone took as long as a whole
// matrix render (Heliar, 1280×720: 3.5–5 ms without, 9–10.5 ms with).
// Threading: one FlareRenderer renders one flare at a time (each render uses TBB inside); render
// several at once with one FlareRenderer each.
class FlareRenderer {
 public:
  FlareRenderer();
  ~FlareRenderer();
  FlareRenderer(FlareRenderer&&) noexcept;
  FlareRenderer& operator=(FlareRenderer&&) noexcept;

  // Renders into *out, which ends up as renderFlare's result (same pixels, bit for bit). Its
  // radiance and ghost layers are overwritten in place when they have the size and type and no
  // other cv::Mat shares their pixels; an image handed out earlier (a copy of the cv::Mat header)
  // keeps its pixels, and *out gets new ones. Throws as renderFlare; *out is then unspecified.
  void render(const Lens& lens, const LightDirection& light, const FlareRenderOptions& options,
              FlareImage* out);

 private:
  struct Scratch;
  std::unique_ptr<Scratch> scratch_;
};

// The EXR image of a render: main layer = radiance; with ghost layers, "ghost.<id>" (R,G,B) each
// with attributes flarekit.ghost.<id>.surfaces (Vec2i), .centroid_px (Vec2d), .bbox_px
// (x, y, w, h as float vector) and .energy.
ExrImage toExrImage(const FlareImage& image);

}  // namespace flarekit::render
