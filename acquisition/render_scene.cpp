#include "acquisition/render_scene.h"

#include <cmath>
#include <mutex>

#include "common/image.h"
#include "render/flare_renderer.h"
#include "render/lens.h"
#include "render/sensor.h"

namespace flarekit::acquisition {
namespace {

render::SensorModel sensorModel(const Rig& rig, double iso) {
  render::SensorModel m;
  const SensorConfig& s = rig.sensor;
  m.bit_depth = s.bit_depth;
  m.black_level_dn = s.black_level_dn;
  m.white_level_dn = s.white_level_dn;
  m.iso = iso;
  m.base_iso = s.base_iso;
  m.base_gain_e_per_dn = s.base_gain_e_per_dn;
  m.read_noise_e = s.read_noise_e;
  m.full_well_e = s.full_well_e;
  m.electrons_per_unit_s = s.electrons_per_unit_s;
  m.color_filter = s.cfa == Cfa::kMono ? render::ColorFilter::kMono : render::ColorFilter::kBayerRggb;
  return m;
}

class RenderScene : public SceneProvider {
 public:
  explicit RenderScene(const Rig& rig) : rig_(rig) {
    lens_ = render::loadLens(resolveLensPath(rig));
    const auto& sim = rig.simulation;
    options_.width_px = sim.width_px;
    options_.height_px = sim.height_px;
    options_.sensor_width_mm = sim.sensor_width_mm;
    options_.sensor_height_mm = sim.sensor_height_mm;
    options_.grid_size = sim.grid_size;
    options_.spectral_samples = sim.spectral_samples;
    options_.light_irradiance = sim.light_irradiance;
    options_.starburst_radius_px = sim.starburst_radius_px;
    options_.max_ghosts = sim.max_ghosts;
    options_.optical_axis_offset_px = sim.optical_axis_offset_px;
    options_.ghost_layers = true;
    std::string error;
    if (!options_.IsValid(&error))
      throw InputError(rig.file.string(), "simulation: " + error);
    pitch_um_ = 1000.0 * std::min(sim.sensor_width_mm / sim.width_px,
                                  sim.sensor_height_mm / sim.height_px);
    focal_length_mm_ = render::paraxialProperties(lens_).efl_mm;
  }

  cv::Mat radiance(double angle_deg, double f_number) override {
    return render(angle_deg, f_number).radiance;
  }

  ExrImage truth(double angle_deg, double f_number) override {
    const render::FlareImage& image = render(angle_deg, f_number);
    ExrImage full = render::toExrImage(image);
    const bool mono = rig_.sensor.cfa == Cfa::kMono;
    // The frames' channels: luminance for a mono sensor (what render/sensor.h's mono sensor
    // sees), R,G,B for a Bayer sensor.
    for (auto& layer : full.layers)
      if (mono) layer.image = luminance(layer.image);
    full.attributes["flarekit.truth"] = std::string("noise-free radiance from the renderer");
    // The head's angle, as the frames carry it; the angle rendered beside it when they differ.
    full.attributes["flarekit.angle_deg"] = angle_deg;
    if (rig_.simulation.angle_zero_offset_deg != 0.0)
      full.attributes["flarekit.true_angle_deg"] = trueAngleDeg(angle_deg);
    // The lens as the rig file names it, not where this machine found it: truth files must not
    // depend on the folder the capture ran in.
    full.attributes["flarekit.lens_file"] = rig_.simulation.lens.string();
    return full;
  }

  std::string lensName() const override { return lens_.name; }
  double pixelPitchUm() const override { return pitch_um_; }
  double focalLengthMm() const override { return focal_length_mm_; }

 private:
  const render::FlareImage& render(double angle_deg, double f_number) {
    if (!cached_ || angle_deg != angle_ || f_number != f_number_) {
      render::FlareRenderOptions options = options_;
      options.f_number = f_number;
      // θ > 0 moves the light's image to −x (docs/design.md). One renderer for the whole
      // capture: its frame buffers and triangle lists are reused.
      cached_ = false;
      renderer_.render(lens_, render::LightDirection{trueAngleDeg(angle_deg), 0.0}, options,
                       &image_);
      angle_ = angle_deg;
      f_number_ = f_number;
      cached_ = true;
    }
    return image_;
  }

  // The angle between the light and the optical axis when the head reports `head_angle_deg`.
  double trueAngleDeg(double head_angle_deg) const {
    return head_angle_deg - rig_.simulation.angle_zero_offset_deg;
  }

  Rig rig_;
  render::Lens lens_;
  render::FlareRenderOptions options_;
  double pitch_um_ = 0;
  double focal_length_mm_ = 0;  // paraxial EFL of the lens
  bool cached_ = false;
  double angle_ = 0, f_number_ = 0;
  render::FlareRenderer renderer_;
  render::FlareImage image_;
};

}  // namespace

std::shared_ptr<SceneProvider> makeRenderScene(const Rig& rig) {
  return std::make_shared<RenderScene>(rig);
}

RawExposer makeSensorExposer(const Rig& rig) {
  return [rig](const cv::Mat& radiance, double exposure_s, double iso, uint64_t seed) {
    return render::exposeRaw(radiance, exposure_s, sensorModel(rig, iso), seed);
  };
}

double simulatedWhiteLevel(const Rig& rig, double iso) {
  render::SensorModel m = sensorModel(rig, iso);
  double white = m.whiteLevelDn();
  if (m.full_well_e > 0) white = std::min(white, m.black_level_dn + m.full_well_e / m.gainEPerDn());
  return std::floor(white);
}

}  // namespace flarekit::acquisition
