#pragma once
// A rotation head driven by a Pololu Tic stepper controller over USB (libusb control transfers;
// protocol as in Pololu's Tic user's guide). Commands: energize, exit safe start, set target
// position, poll the current position until it is reached while resetting the command timeout,
// halt and set position; errors read from the error-status variable into clear messages; homing
// with the Tic's own "go home" (its limit/home switch configuration made with ticgui).
//
// Moves share the GPIO stepper's rules (acquisition/stepper_motion.h): whole microsteps, soft
// limits, backlash taken up by always arriving in the approach direction.
//
// Failures: DeviceError — persistent for a missing controller or a controller error that needs a
// person (motor driver error, low VIN, kill switch), transient for a failed transfer.

#include <memory>
#include <string>
#include <vector>

#include "acquisition/device.h"
#include "acquisition/rig.h"

namespace flarekit::acquisition {

inline constexpr uint16_t kPololuVendorId = 0x1FFB;
// Tic T825, T834, T500, N825, T249, 36v4.
inline constexpr uint16_t kTicProductIds[] = {0x00B3, 0x00B5, 0x00BD, 0x00C3, 0x00C9, 0x00CB};

// The Tic's error status bits as words.
std::string ticErrorText(uint16_t error_status);

class TicHead : public RotationHead {
 public:
  // Finds and opens the controller (the first, or the one with config.serial). DeviceError when
  // none is connected or it cannot be opened (the message mentions the udev rule).
  explicit TicHead(const TicConfig& config, std::string rig_file = "");
  ~TicHead() override;
  TicHead(TicHead&&) noexcept;
  TicHead& operator=(TicHead&&) noexcept;

  std::string describe() const override;
  void home() override;
  void moveTo(double angle_deg) override;
  double angleDeg() const override;
  void reconnect() override;

  // The controller's current position in microsteps (reads the variable).
  int32_t readPosition();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// rig-check: lists the Tic controllers on the USB bus; false when the configured one is missing.
bool probeTic(const TicConfig& config, std::vector<std::string>* lines);

}  // namespace flarekit::acquisition
