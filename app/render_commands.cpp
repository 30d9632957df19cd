// flarekit lens-info, flarekit simulate, flarekit bench render: parse options, call render/.
#include <cstdio>
#include <iostream>
#include <memory>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "app/commands.h"
#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "common/log.h"
#include "render/benchmark.h"
#include "render/flare_renderer.h"
#include "render/lens.h"

namespace flarekit::app {
namespace {

using namespace flarekit::render;

std::string format(const char* fmt, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, v);
  return buf;
}

nlohmann::json lensInfoJson(const Lens& lens, const LensInfo& info) {
  nlohmann::json surfaces = nlohmann::json::array();
  for (const Surface& s : lens.surfaces) {
    nlohmann::json j = {{"radius_mm", s.radius_mm}, {"thickness_mm", s.thickness_mm},
                        {"ior_d", s.ior_d}, {"semi_aperture_mm", s.semi_aperture_mm},
                        {"is_stop", s.is_stop}};
    j["abbe_d"] = s.abbe_d ? nlohmann::json(*s.abbe_d) : nlohmann::json(nullptr);
    j["coating_nm"] = s.coating_nm ? nlohmann::json(*s.coating_nm) : nlohmann::json(nullptr);
    surfaces.push_back(j);
  }
  return {{"name", info.name},
          {"file", info.file},
          {"source", info.source},
          {"surfaces", surfaces},
          {"stop_index", info.stop_index},
          {"efl_mm", info.paraxial.efl_mm},
          {"bfd_mm", info.paraxial.bfd_mm},
          {"f_number", info.paraxial.f_number},
          {"entrance_pupil_z_mm", info.paraxial.entrance_pupil_z_mm},
          {"entrance_pupil_radius_mm", info.paraxial.entrance_pupil_radius_mm},
          {"sensor_distance_mm", info.sensor_distance_mm},
          {"ghosts_all", info.ghosts_all},
          {"ghosts_same_side_of_stop", info.ghosts_same_side}};
}

void registerLensInfo(CLI::App& app) {
  struct Options {
    std::string lens;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("lens-info", "Show a lens prescription and its paraxial properties");
  cmd->add_option("LENS", o->lens, "Lens file (.json, or pbrt .dat)")->required();
  cmd->add_flag("--json", o->json, "Print one JSON object");
  cmd->callback([o] {
    const Lens lens = loadLens(o->lens);
    const LensInfo info = describeLens(lens);
    if (o->json) {
      std::cout << jsonText(lensInfoJson(lens, info)) << "\n";
      return;
    }
    std::ostringstream out;
    out << info.name << "\n  file: " << info.file << "\n  source: " << info.source << "\n";
    out << "  #   radius mm   thick mm   n_d     V_d    semi-ap mm  coating nm\n";
    for (size_t i = 0; i < lens.surfaces.size(); ++i) {
      const Surface& s = lens.surfaces[i];
      char line[160];
      std::snprintf(line, sizeof line, "  %-3zu %10.3f %10.3f %7.4f %6s %10.3f  %s%s\n", i,
                    s.radius_mm, s.thickness_mm, s.ior_d,
                    s.abbe_d ? format("%.2f", *s.abbe_d).c_str() : "-", s.semi_aperture_mm,
                    s.coating_nm ? format("%.0f", *s.coating_nm).c_str() : "-",
                    s.is_stop ? "  (stop)" : "");
      out << line;
    }
    const auto& p = info.paraxial;
    out << "  effective focal length: " << format("%.3f", p.efl_mm) << " mm\n"
        << "  back focal distance:    " << format("%.3f", p.bfd_mm) << " mm\n"
        << "  sensor distance:        " << format("%.3f", info.sensor_distance_mm) << " mm\n"
        << "  f-number:               " << format("%.3f", p.f_number) << "\n"
        << "  entrance pupil:         radius " << format("%.3f", p.entrance_pupil_radius_mm)
        << " mm at " << format("%.3f", p.entrance_pupil_z_mm) << " mm behind the first vertex\n"
        << "  ghosts (two reflections): " << info.ghosts_all << " all, " << info.ghosts_same_side
        << " with both reflections on the same side of the stop\n";
    std::cout << out.str();
  });
}

void registerSimulate(CLI::App& app) {
  struct Options {
    std::string lens, out, preview, sensor = "36x24", wavelengths = "rgb", method = "tiled";
    std::string aperture = "polygon", aperture_mask;
    double angle = 0, roll = 0;
    int blades = 6;
    double rounding = 0, aperture_rotation = 0;
    bool ghost_layers = false, starburst = false, no_source = false, same_side = false;
    bool uncoated = false, infinity = false;
    FlareRenderOptions render;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand("simulate", "Render the physical lens flare of a lens for one light direction");
  cmd->add_option("--lens", o->lens, "Lens file (.json or pbrt .dat)")->required();
  cmd->add_option("--angle", o->angle, "Light angle θ from the optical axis, degrees")->required();
  cmd->add_option("--roll", o->roll, "Roll φ of the light about the optical axis, degrees");
  cmd->add_option("--f-number", o->render.f_number, "Working f-number (0 = the lens's own)");
  cmd->add_option("--width", o->render.width_px, "Image width in pixels")->capture_default_str();
  cmd->add_option("--height", o->render.height_px, "Image height in pixels")->capture_default_str();
  cmd->add_option("--sensor-mm", o->sensor, "Sensor size WxH in mm")->capture_default_str();
  cmd->add_option("--wavelengths", o->wavelengths, "rgb, or a number N ≥ 3 of spectral samples")->capture_default_str();
  cmd->add_option("--grid", o->render.grid_size, "Rays per side of each ghost's grid")->capture_default_str();
  cmd->add_option("--method", o->method, "tiled, per-ghost or matrix")->capture_default_str();
  cmd->add_option("--max-ghosts", o->render.max_ghosts, "Keep only the N brightest ghosts (0 = all)");
  cmd->add_option("--min-intensity", o->render.min_relative_intensity,
                  "Drop ghosts below this fraction of the brightest estimate");
  cmd->add_flag("--same-side", o->same_side, "Only ghosts with both reflections on one side of the stop");
  cmd->add_flag("--ghost-layers", o->ghost_layers, "Write each ghost as its own EXR layer ghost.<id>");
  cmd->add_flag("--starburst", o->starburst, "Shape the light's own image as the iris's diffraction starburst (else a point)");
  cmd->add_option("--starburst-radius", o->render.starburst_radius_px, "Starburst radius in pixels (0 = image diagonal / 8)");
  cmd->add_option("--halo", o->render.halo_fraction, "Fraction of the light's flux spread into a halo");
  cmd->add_flag("--no-source", o->no_source, "Leave out the light's own image (ghosts only)");
  cmd->add_option("--aperture", o->aperture, "circle, polygon or mask")->capture_default_str();
  cmd->add_option("--blades", o->blades, "Iris blades (polygon)")->capture_default_str();
  cmd->add_option("--rounding", o->rounding, "Blade rounding 0..1 (polygon)");
  cmd->add_option("--aperture-rotation", o->aperture_rotation, "Iris rotation, degrees");
  cmd->add_option("--aperture-mask", o->aperture_mask, "Grey image of the iris transmission (with --aperture mask)");
  cmd->add_option("--coating-nm", o->render.coating_override_nm, "Design wavelength of every coating (0 = per surface)");
  cmd->add_flag("--uncoated", o->uncoated, "No anti-reflection coatings");
  cmd->add_flag("--focus-infinity", o->infinity, "Put the sensor at the paraxial infinity focus");
  cmd->add_option("--preview", o->preview, "Also write a tone-mapped PNG preview");
  cmd->add_option("--out", o->out, "Output EXR (linear relative irradiance)")->required();
  cmd->callback([o] {
    FlareRenderOptions r = o->render;
    double sw = 0, sh = 0;
    char x = 0;
    std::istringstream sensor(o->sensor);
    if (!(sensor >> sw >> x >> sh) || x != 'x' || sw <= 0 || sh <= 0)
      throw InputError("--sensor-mm: expected WxH in mm, e.g. 36x24, got '" + o->sensor + "'");
    r.sensor_width_mm = sw;
    r.sensor_height_mm = sh;
    if (o->wavelengths == "rgb") {
      r.spectral_samples = 0;
    } else {
      try {
        size_t used = 0;
        r.spectral_samples = std::stoi(o->wavelengths, &used);
        if (used != o->wavelengths.size()) throw std::invalid_argument("");
      } catch (const std::exception&) {
        throw InputError("--wavelengths: expected rgb or a number, got '" + o->wavelengths + "'");
      }
    }
    if (o->method == "tiled") r.method = RenderMethod::kTiled;
    else if (o->method == "per-ghost") r.method = RenderMethod::kPerGhost;
    else if (o->method == "matrix") r.method = RenderMethod::kMatrix;
    else throw InputError("--method: expected tiled, per-ghost or matrix, got '" + o->method + "'");
    if (o->aperture == "circle") r.aperture.kind = ApertureKind::kCircle;
    else if (o->aperture == "polygon") r.aperture.kind = ApertureKind::kPolygon;
    else if (o->aperture == "mask") {
      r.aperture.kind = ApertureKind::kMask;
      if (o->aperture_mask.empty()) throw InputError("--aperture mask needs --aperture-mask IMAGE");
      r.aperture.mask = cv::imread(o->aperture_mask, cv::IMREAD_GRAYSCALE);
      if (r.aperture.mask.empty()) throw InputError(o->aperture_mask + ": cannot read the aperture mask image");
    } else throw InputError("--aperture: expected circle, polygon or mask, got '" + o->aperture + "'");
    r.aperture.blades = o->blades;
    r.aperture.rounding = o->rounding;
    r.aperture.rotation_deg = o->aperture_rotation;
    r.ghost_layers = o->ghost_layers;
    r.starburst = o->starburst;
    r.light_source = !o->no_source;
    r.same_side_of_stop_only = o->same_side;
    r.uncoated = o->uncoated;
    r.focus_at_infinity = o->infinity;
    std::string error;
    if (!r.IsValid(&error)) throw InputError(error);
    const Lens lens = loadLens(o->lens);
    const FlareImage image = renderFlare(lens, LightDirection{o->angle, o->roll}, r);
    writeExr(o->out, toExrImage(image));
    if (!o->preview.empty()) {
      // Automatic exposure on the 90th percentile of the lit pixels: those are the ghosts, which
      // cover far more pixels than the light's own image (orders of magnitude brighter, clipped).
      PreviewOptions preview;
      writePreviewPng(o->preview, image.radiance, preview);
    }
    logInfo(image.summary.BriefReport());
  });
}

void registerBench(CLI::App& app) {
  struct Options {
    std::string lens;
    bool json = true;
    RenderBenchmarkOptions bench;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = benchCommand(app).add_subcommand(
      "render", "Time the tiled, per-ghost and matrix renderers on one lens (ghosts only)");
  cmd->add_option("--lens", o->lens, "Lens file")->required();
  cmd->add_option("--width", o->bench.width_px, "Image width")->capture_default_str();
  cmd->add_option("--height", o->bench.height_px, "Image height")->capture_default_str();
  cmd->add_option("--grid", o->bench.grid_size, "Rays per side")->capture_default_str();
  cmd->add_option("--angle", o->bench.angle_deg, "Light angle, degrees")->capture_default_str();
  cmd->add_option("--repetitions", o->bench.repetitions, "Renders per method (median reported)")->capture_default_str();
  cmd->add_flag("--json", o->json, "Print one JSON object (the only output format)");
  cmd->callback([o] {
    const Lens lens = loadLens(o->lens);
    std::cout << jsonText(benchmarkRender(lens, o->bench).toJson()) << "\n";
  });
}

}  // namespace

void registerRenderCommands(CLI::App& app) {
  registerLensInfo(app);
  registerSimulate(app);
  registerBench(app);
}

}  // namespace flarekit::app
