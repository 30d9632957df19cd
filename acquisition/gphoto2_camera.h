#pragma once
// A tethered camera through libgphoto2 (2.5.30), decoded with LibRaw (acquisition/raw_decode.h).
//
// Setup: camera in M mode, manual focus, stabilisation and long-exposure noise reduction off.
// The driver sets `imageformat` to RAW only, brackets by setting `shutterspeed` before each frame
// (the nearest value the camera offers; the real exposure is read back from EXIF and kept with
// the frame), sets `iso` and `aperture`, captures, downloads the file into memory, deletes it
// from the camera and decodes it. Debian's libgphoto2 has no virtual camera for capture, so this
// backend is kept thin and its tests need a real camera (CTest label "hardware").
//
// Failures: DeviceError — transient for a busy camera or a failed transfer (GP_ERROR_CAMERA_BUSY,
// GP_ERROR_IO*, timeouts), persistent for a missing camera or an unsupported setting.

#include <memory>
#include <string>
#include <vector>

#include "acquisition/device.h"
#include "acquisition/rig.h"

namespace flarekit::acquisition {

class Gphoto2Camera : public Camera {
 public:
  explicit Gphoto2Camera(const Gphoto2Config& config);
  ~Gphoto2Camera() override;
  Gphoto2Camera(Gphoto2Camera&&) noexcept;
  Gphoto2Camera& operator=(Gphoto2Camera&&) noexcept;

  std::string describe() const override;
  void setExposure(double exposure_s) override;
  void setIso(double iso) override;
  void setAperture(double f_number) override;
  RawFrame capture() override;
  RawFrame captureDark() override;
  void reconnect() override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Parses a gphoto2 shutter speed ("1/250", "0.3", "4", "30\"", "bulb" → 0) to seconds.
double parseShutterSpeed(const std::string& text);
// The choice closest to `exposure_s` in log space; empty when there are none.
std::string nearestShutterSpeed(const std::vector<std::string>& choices, double exposure_s);

// rig-check: lists the cameras gphoto2 detects; false when the configured one is missing.
bool probeGphoto2(const Gphoto2Config& config, std::vector<std::string>* lines);

}  // namespace flarekit::acquisition
