#pragma once
// Rig files (rigs/*.toml): which rotation head and camera a capture uses and how they are wired,
// the sensor's noise model (for the HDR merge weights), the capture defaults, and for simulated
// rigs the scene (lens, image size, light) and seeded fault injection. Every key is documented in
// the shipped rig files (rigs/sim-heliar.toml is the reference). Errors name the file and the
// key: "rigs/x.toml: head.microsteps: must be one of 1, 2, 4, ..., 256, got 3".

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "acquisition/device.h"

namespace flarekit::acquisition {

enum class HeadDriver { kSimulated, kGpioStepper, kTic };
enum class CameraDriver { kSimulated, kGphoto2 };

// Geometry and motion shared by the stepper heads.
struct StepperGeometry {
  int full_steps_per_rev = 200;  // motor full steps per revolution (1.8° motors: 200)
  int microsteps = 16;           // driver microstepping (1..256, a power of two)
  double gear_ratio = 1.0;       // motor turns per turn of the head (> 0)
  double max_speed_deg_s = 10;   // cruise speed of the head
  double accel_deg_s2 = 20;      // constant acceleration and deceleration of the head
  // Backlash: targets are always approached moving in `approach_sign` (+1 or −1); a move the
  // other way overshoots by backlash_deg and comes back.
  double backlash_deg = 0.5;
  int approach_sign = +1;
  double min_deg = -90, max_deg = 90;  // soft limits (moves outside them are refused)
  double home_angle_deg = 0;           // the angle the home position stands for
  int home_direction = -1;             // direction to search the home switch in (−1 or +1)
  double home_search_deg = 360;        // give up homing after this much travel
  double home_speed_deg_s = 2;         // homing speed
  double home_backoff_deg = 1;         // move off the switch after it triggered

  double microstepsPerDeg() const { return full_steps_per_rev * microsteps * gear_ratio / 360.0; }
};

struct GpioStepperConfig {
  std::string chip = "gpiochip0";  // gpiochip name, path (/dev/gpiochip0) or label
  int step_line = -1, dir_line = -1;  // line offsets on the chip
  int enable_line = -1;               // -1 = none
  bool enable_active_low = true;      // A4988/DRV8825/TMC2209 ENABLE is active low
  bool dir_high_is_positive = true;   // DIR level that turns the head towards +θ
  int home_line = -1;                 // home switch input; -1 = no switch (home = current pos)
  bool home_active_low = true;        // switch pulls the line low when pressed (pull-up)
  double step_pulse_us = 2.0;         // STEP high time (A4988 1 µs, DRV8825 1.9 µs)
  double dir_setup_us = 1.0;          // DIR set-up before the first STEP edge
  StepperGeometry geometry;
};

struct TicConfig {
  std::string serial;                 // serial number to pick one controller ("" = the first)
  int step_mode_microsteps = 16;      // the Tic's step mode (as set with ticcmd/ticgui)
  double command_timeout_s = 1.0;     // the controller's command timeout (reset while moving)
  double move_timeout_s = 120;        // give up waiting for a move after this long
  StepperGeometry geometry;
};

struct SimulatedHeadConfig {
  double speed_deg_s = 0;  // 0 = moves are instantaneous; else the simulated move takes time
};

// What every head shares: the pause after each move before the first exposure, for the head and
// the camera on it to stop swinging (a stepper's ringing, a belt's spring). Real heads need it;
// the simulated one keeps it too (tests set it tiny).
struct HeadSettleConfig {
  double settle_s = 0;  // seconds (0 = expose at once), at most 60
};

struct Gphoto2Config {
  // Camera model as gphoto2 --auto-detect lists it ("" = the first camera; for a PTP/IP port
  // "" = libgphoto2's generic "PTP/IP Camera").
  std::string model;
  // Port: "usb:001,004", or "ptpip:IPV4[:PORT]" for a camera on the network (PTP/IP, port
  // 15740 by default), which autodetection cannot find; "" = the first camera detected.
  std::string port;
  // The value of the camera's `imageformat` (or, where the driver has none, `imagequality`)
  // setting that means RAW only; "" = leave the camera's setting alone (default "RAW").
  std::string imageformat = "RAW";
  // Watchdog: the longest a capture may take beyond its exposure time before the camera is
  // reconnected and the capture retried, seconds (default 30).
  double capture_timeout_s = 30;
};

// The sensor's noise model (render/sensor.h conventions) and geometry.
struct SensorConfig {
  Cfa cfa = Cfa::kMono;
  int bit_depth = 14;
  double black_level_dn = 512;
  double white_level_dn = 0;  // 0 = 2^bit_depth − 1
  double base_iso = 100;
  double base_gain_e_per_dn = 4.0;  // electrons per DN at base ISO
  double read_noise_e = 3.0;
  double full_well_e = 0;  // 0 = unlimited
  double electrons_per_unit_s = 1e7;  // simulated rigs: electrons/s per unit of render radiance
  double pixel_pitch_um = 0;          // 0 = unknown (simulated rigs compute it)

  double gainEPerDn(double iso) const { return base_gain_e_per_dn * base_iso / iso; }
};

struct SimulationConfig {
  std::filesystem::path lens;  // lens prescription (resolved against the rig file's folder and
                               // the working folder)
  int width_px = 320, height_px = 214;
  double sensor_width_mm = 36, sensor_height_mm = 24;
  int grid_size = 48;
  int spectral_samples = 0;
  double light_irradiance = 1.0;
  double starburst_radius_px = 0;
  int max_ghosts = 0;
  uint64_t seed = 1;
  // Imperfections of a real rig, for the fitter to measure. Where the optical axis meets the
  // image, in pixels from its centre (x right, y down; |dx| ≤ W/4, |dy| ≤ H/4; default (0, 0)):
  // FlareRenderOptions::optical_axis_offset_px.
  cv::Point2d optical_axis_offset_px{0.0, 0.0};
  // The head's reading at which the light is on the optical axis, degrees (|o| ≤ 5; default 0):
  // the scene is rendered at θ − o while frames and manifest keep the head's θ.
  double angle_zero_offset_deg = 0.0;
  // A light that drifts: its irradiance changes linearly by this many percent from the capture
  // plan's first frame to its last (and the end-of-capture light check), for the capture's light
  // stability figures to measure (|d| ≤ 50; default 0). The frames, their light exposures and
  // truth/ all carry it.
  double light_drift_pct = 0.0;
};

// The lens on a real rig's camera (a simulated rig's lens is its [simulation] prescription).
struct LensConfig {
  std::string name;            // recorded in the manifest, frames and flare model
  double focal_length_mm = 0;  // 0 = unknown; predictions use it to check a scene's camera
};

struct FaultConfig {
  double camera_transient_probability = 0;  // per capture call
  double camera_timeout_probability = 0;    // per capture call: a timeout (transient)
  double timeout_s = 0.05;                  // how long a simulated timeout blocks
  double head_transient_probability = 0;    // per move
  int camera_disconnect_after_frames = -1;  // persistent failure after this many captures
  int head_disconnect_after_moves = -1;     // persistent failure after this many moves
  uint64_t seed = 7;
};

struct CaptureDefaults {
  double from_deg = 0, to_deg = 20, step_deg = 0.5;
  std::vector<double> exposures_s{0.25, 1, 4};
  // The light exposures (acquisition/capture.h): more exposures in each bracket, the shortest
  // short enough that the light's own image does not clip, merged apart from the frames; they
  // measure the light's flux and peak (flarekit metrics) and its stability. Empty = none. The
  // rig key light_exposure_s takes one time or a list (0 = none).
  std::vector<double> light_exposures_s;
  // The attenuation of a neutral-density filter the light exposure is taken through (declared,
  // ≥ 1; 10^density): its values are multiplied by it. 1 = no filter.
  double light_nd_factor = 1;
  // Light exposures of the light check, at its start and at its end (1–256).
  int light_check_repeats = 16;
  int dark_frames = 0;
  double iso = 100;
  double f_number = 8;
  int max_retries = 3;
  double retry_delay_s = 0.5;
};

struct Rig {
  std::filesystem::path file;
  std::string name;
  std::string description;
  std::string light;  // description of the light source (metadata)
  // Illuminance the light gives at the lens, lux, as measured with a lux meter at the camera's
  // position (0 = not measured). Recorded in the manifest and the flare model: it is l_F·α_F of
  // Walch 2018 Eq. 2, the reference prediction scales each scene light's flare against.
  double light_illuminance_lux = 0;
  HeadDriver head_driver = HeadDriver::kSimulated;
  CameraDriver camera_driver = CameraDriver::kSimulated;
  SimulatedHeadConfig simulated_head;
  HeadSettleConfig settle;  // [head] settle_s, every driver
  GpioStepperConfig gpio;
  TicConfig tic;
  Gphoto2Config gphoto2;
  SensorConfig sensor;
  LensConfig lens;              // only for a real camera
  SimulationConfig simulation;  // only for camera driver "simulated"
  FaultConfig faults;
  CaptureDefaults capture;

  bool simulated() const {
    return head_driver == HeadDriver::kSimulated && camera_driver == CameraDriver::kSimulated;
  }
};

// Loads and validates a rig file. InputError "<file>: <key>: <problem>" on any problem.
Rig loadRig(const std::filesystem::path& path);
// Resolves a rig argument: an existing path, or a name in rigs/ ("sim-heliar"). The default rig
// is "sim-heliar". Searches the working folder, the folder of the running program's source tree
// (FLAREKIT_SOURCE_DIR at build time) and $FLAREKIT_RIGS.
std::filesystem::path findRig(const std::string& name_or_path);
// Resolves a lens path of a simulated rig (rig folder, its parent, working folder).
std::filesystem::path resolveLensPath(const Rig& rig);

struct RigDevices {
  std::unique_ptr<RotationHead> head;
  std::unique_ptr<Camera> camera;
};
// Opens the rig's devices. DeviceError when hardware is missing (what to do in the message).
RigDevices openRig(const Rig& rig);

// What `flarekit rig-check` reports: one line per check; `ok` false when something is missing.
struct RigCheckReport {
  bool ok = true;
  std::vector<std::string> lines;
};
RigCheckReport checkRig(const Rig& rig);

}  // namespace flarekit::acquisition
