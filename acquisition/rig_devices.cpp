// openRig and checkRig: the rig file chooses the backends.
#include <sstream>

#include "acquisition/gphoto2_camera.h"
#include "acquisition/gpio_stepper_head.h"
#include "acquisition/rig.h"
#include "acquisition/simulated_camera.h"
#include "acquisition/tic_head.h"
#ifdef FLAREKIT_ACQUISITION_WITH_RENDER
#include "acquisition/render_scene.h"
#endif

namespace flarekit::acquisition {

RigDevices openRig(const Rig& rig) {
  RigDevices devices;
  auto stage = std::make_shared<SimulatedStage>();
  switch (rig.head_driver) {
    case HeadDriver::kSimulated:
      devices.head = std::make_unique<SimulatedHead>(stage, rig.simulated_head, rig.faults);
      break;
    case HeadDriver::kGpioStepper:
      devices.head = std::make_unique<GpioStepperHead>(rig.gpio, rig.file.string());
      break;
    case HeadDriver::kTic:
      devices.head = std::make_unique<TicHead>(rig.tic, rig.file.string());
      break;
  }
  switch (rig.camera_driver) {
    case CameraDriver::kSimulated: {
#ifdef FLAREKIT_ACQUISITION_WITH_RENDER
      Rig copy = rig;
      devices.camera = std::make_unique<SimulatedCamera>(
          stage, makeRenderScene(rig), makeSensorExposer(rig), rig.sensor.cfa,
          rig.sensor.black_level_dn, [copy](double iso) { return simulatedWhiteLevel(copy, iso); },
          rig.simulation.seed, rig.faults);
#else
      throw RuntimeError("this flarekit was built without the renderer (render/): simulated "
                         "cameras are not available");
#endif
      break;
    }
    case CameraDriver::kGphoto2:
      try {
        devices.camera = std::make_unique<Gphoto2Camera>(rig.gphoto2);
      } catch (const InputError& e) {
        throw InputError(rig.file.string(), e.what());  // a camera.model or camera.port
      }
      break;
  }
  return devices;
}

RigCheckReport checkRig(const Rig& rig) {
  RigCheckReport report;
  auto& lines = report.lines;
  lines.push_back("rig " + rig.name + " (" + rig.file.string() + "): the file is valid");
  auto guard = [&](const char* what, auto&& fn) {
    try {
      if (!fn()) report.ok = false;
    } catch (const InputError&) {
      throw;
    } catch (const std::exception& e) {
      lines.push_back(std::string("MISSING ") + what + ": " + e.what());
      report.ok = false;
    }
  };
  switch (rig.head_driver) {
    case HeadDriver::kSimulated:
      lines.push_back("head: simulated");
      break;
    case HeadDriver::kGpioStepper:
      guard("GPIO", [&] { return probeGpio(rig.gpio, &lines); });
      break;
    case HeadDriver::kTic:
      guard("Tic", [&] { return probeTic(rig.tic, &lines); });
      break;
  }
  switch (rig.camera_driver) {
    case CameraDriver::kSimulated: {
      const auto lens = resolveLensPath(rig);
#ifdef FLAREKIT_ACQUISITION_WITH_RENDER
      auto scene = makeRenderScene(rig);  // loads and validates the lens
      std::ostringstream s;
      s << "camera: simulated, lens " << scene->lensName() << " (" << lens.string() << "), "
        << rig.simulation.width_px << "x" << rig.simulation.height_px << " px, pitch "
        << scene->pixelPitchUm() << " µm";
      lines.push_back(s.str());
#else
      lines.push_back("MISSING renderer: this flarekit was built without render/");
      report.ok = false;
#endif
      break;
    }
    case CameraDriver::kGphoto2:
      try {
        guard("camera", [&] { return probeGphoto2(rig.gphoto2, &lines); });
      } catch (const InputError& e) {
        throw InputError(rig.file.string(), e.what());  // a camera.model or camera.port
      }
      break;
  }
  lines.push_back(report.ok ? "rig-check: everything the rig names was found"
                            : "rig-check: something the rig names is missing (lines marked "
                              "MISSING/BUSY)");
  return report;
}

}  // namespace flarekit::acquisition
