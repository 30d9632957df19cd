#pragma once
// The simulated rig's scene and sensor: the physical renderer (render/flare_renderer.h) with the
// rig's lens, and the renderer's sensor model (render/sensor.h). Built only when render/ is.

#include <memory>

#include "acquisition/rig.h"
#include "acquisition/simulated_camera.h"

namespace flarekit::acquisition {

// The renderer as a SceneProvider for the rig's [simulation] section. Radiance and truth of one
// angle come from one render (cached), so truth/ matches the frames exactly. The angle asked for
// is the head's: the light is rendered at angle − angle_zero_offset_deg, on a sensor whose optical
// axis meets the image optical_axis_offset_px from its centre.
std::shared_ptr<SceneProvider> makeRenderScene(const Rig& rig);

// render::exposeRaw with the rig's [sensor] section at the ISO asked for.
RawExposer makeSensorExposer(const Rig& rig);

// The white level the simulated sensor really clips at at `iso`: the ADC's, or the full well if
// lower.
double simulatedWhiteLevel(const Rig& rig, double iso);

}  // namespace flarekit::acquisition
