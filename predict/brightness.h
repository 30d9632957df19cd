#pragma once
// Brightness of a model's flare in a scene (Walch et al. 2018 §3.4.1, Eq. 2):
//
//   B = (N_F² / N_R²) · (ISO_R / ISO_F) · (t_R / t_F) · (l_R·α_R) / (l_F·α_F)
//
// with F the capture the model was fitted to and R the scene (its camera and one light). The model's
// overlay times B is in the scene camera's linear image units. In exposure values
// (Stingray 2017 / Lagarde & de Rousiers: EV100 = log2(N²/t · 100/S)):
//
//   log2 B = (EV100_F − EV100_R) + log2((l_R·α_R) / (l_F·α_F))
//
// so a brighter exposure of the scene camera (lower EV100_R) or a brighter light raises the flare.

namespace flarekit::predict {

// Exposure settings of one camera (capture or scene).
struct ExposureSettings {
  double f_number = 0;    // N (> 0)
  double iso = 0;         // S (> 0)
  double exposure_s = 0;  // t, seconds (> 0)
};

// EV100 = log2(N² / t · 100 / S). Throws std::invalid_argument for non-positive settings.
double ev100(const ExposureSettings& settings);

// The light terms of Eq. 2: l·α of the capture's light and of the scene light, both lux (> 0).
struct LightPower {
  double capture_illuminance_lux = 0;  // l_F·α_F
  double scene_illuminance_lux = 0;    // l_R·α_R
};

struct BrightnessScale {
  double scale = 0;        // B (Eq. 2)
  double log2_scale = 0;   // log2 B = ev_difference + log2 light ratio
  double ev100_capture = 0;  // EV100_F
  double ev100_scene = 0;    // EV100_R
};

// B by Eq. 2, computed in exposure values (the two forms are equal; the test checks both).
BrightnessScale brightnessScale(const ExposureSettings& capture, const ExposureSettings& scene,
                                const LightPower& light);

// Eq. 2 written as the paper writes it (a product of ratios); for tests and cross-checks.
double brightnessScaleProduct(const ExposureSettings& capture, const ExposureSettings& scene,
                              const LightPower& light);

}  // namespace flarekit::predict
