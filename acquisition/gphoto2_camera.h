#pragma once
// A tethered camera through libgphoto2 (2.5.30), decoded with LibRaw (acquisition/raw_decode.h).
//
// Setup: camera in M mode, manual focus, stabilisation and long-exposure noise reduction off.
// The camera is found by USB autodetection, or at a PTP/IP port given in the rig file
// ("ptpip:IPV4[:PORT]"; autodetection does not list network cameras). The driver sets the image
// format to RAW only (`imageformat`, or `imagequality` where the driver names it so), brackets by
// setting `shutterspeed` before each frame (the nearest value the camera offers; the real
// exposure is read back from EXIF and kept with the frame), sets `iso` and the aperture
// (`aperture`, or `f-number` on generic PTP and Sony cameras), triggers the capture, waits for
// the camera to report the new file, downloads it into memory, checks its size against what the
// camera announced, deletes it from the camera and decodes it. Its tests run against a PTP/IP
// camera served by the tests (acquisition/testing/ptpip_camera.h); a real camera runs under
// the "hardware" CTest label.
//
// Watchdog: every libgphoto2 socket and USB operation has its own timeout; the wait for the new
// file gives up after the exposure plus Gphoto2Config::capture_timeout_s; a camera answering
// DeviceBusy to the trigger is asked again for up to capture_timeout_s. A failed or timed-out
// capture, trigger, download, truncated file or refused setting throws a transient DeviceError:
// the capture session reconnects (reconnect()) and retries, and stops with the session saved
// after its retries run out. Persistent: no camera, a setting the camera does not have, a file
// that is not RAW. A model or port libgphoto2 does not know is an InputError (the rig file).

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

// rig-check: lists the cameras gphoto2 detects, or opens the PTP/IP port the rig names; false
// when the configured camera is missing.
bool probeGphoto2(const Gphoto2Config& config, std::vector<std::string>* lines);

}  // namespace flarekit::acquisition
