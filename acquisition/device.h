#pragma once
// Interfaces of the rig's hardware (docs/design.md, Hardware): a RotationHead that turns the
// camera about a vertical axis through the entrance pupil, and a Camera that takes linear RAW
// frames. Backends live in their own files (simulated_*.cpp, gpio_stepper_head.cpp, tic_head.cpp,
// gphoto2_camera.cpp) and are chosen by the rig file (acquisition/rig.h).
//
// Failure contract: every method throws DeviceError on a hardware failure. `transient()` tells
// the capture session whether retrying the same call may succeed (a dropped USB transfer, a busy
// camera); a persistent error (a disconnected device, a driver fault) ends the session cleanly
// with the manifest intact so that `flarekit capture --resume` can continue it. Bad configuration
// is an InputError. Devices are used from one thread at a time.

#include <cstdint>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "common/error.h"

namespace flarekit::acquisition {

// A hardware failure: exit code 1, with what to do in the message.
class DeviceError : public RuntimeError {
 public:
  DeviceError(std::string_view message, bool transient)
      : RuntimeError(message), transient_(transient) {}
  bool transient() const { return transient_; }

 private:
  bool transient_;
};

// Colour filter array layout of a RAW frame, named by the colours of the top-left 2×2 block
// read row by row (kRGGB: R at (0,0), G at (0,1) and (1,0), B at (1,1)).
enum class Cfa { kMono, kRGGB, kBGGR, kGRBG, kGBRG };
std::string_view cfaName(Cfa cfa);
// Parses "mono", "RGGB", ... (case-insensitive); false when unknown.
bool parseCfa(std::string_view text, Cfa* cfa);
// Colour index (0 R, 1 G, 2 B) of photosite (row, col); 1 for kMono.
int cfaColor(Cfa cfa, int row, int col);

// One linear RAW exposure: photosite values before any demosaicing.
struct RawFrame {
  cv::Mat data;               // CV_16UC1, visible area only, one value per photosite (DN)
  Cfa cfa = Cfa::kMono;       // layout of `data`
  double black_level = 0;     // DN of a photosite that received no light
  double white_level = 65535; // DN at which photosites saturate (clip)
  double exposure_s = 0;      // the exposure actually used (from EXIF for real cameras)
  double iso = 0;             // 0 when unknown
  double f_number = 0;        // 0 when unknown
  double focal_length_mm = 0; // lens focal length from EXIF; 0 when unknown
  int64_t capture_time = 0;   // when the frame was taken, Unix seconds; 0 when unknown
  std::string camera;         // camera model, for metadata
};

// Turns the camera. Angles in degrees; θ = 0 puts the light on the optical axis.
class RotationHead {
 public:
  virtual ~RotationHead() = default;
  // Short description for logs and the manifest ("GPIO stepper on gpiochip0 (1.8° ×16 × 3:1)").
  virtual std::string describe() const = 0;
  // Finds the reference position and sets it to `home_angle_deg` of the rig file.
  virtual void home() = 0;
  // Moves to an absolute angle and returns when the head stands still there.
  virtual void moveTo(double angle_deg) = 0;
  // The angle the head stands at (as commanded after a completed move).
  virtual double angleDeg() const = 0;
  // Tries to re-open the device after a transient error (no-op by default).
  virtual void reconnect() {}
};

// Takes RAW frames. Settings persist until changed.
class Camera {
 public:
  virtual ~Camera() = default;
  virtual std::string describe() const = 0;
  virtual void setExposure(double exposure_s) = 0;
  virtual void setIso(double iso) = 0;
  virtual void setAperture(double f_number) = 0;
  // Takes one frame with the current settings.
  virtual RawFrame capture() = 0;
  // Takes one frame with no light reaching the sensor (for dark frames). Real cameras cannot
  // block the light themselves: they throw InputError saying how to make dark frames by hand.
  virtual RawFrame captureDark() = 0;
  // Tries to re-open the device after a transient error (no-op by default).
  virtual void reconnect() {}
};

}  // namespace flarekit::acquisition
