#pragma once
// A rotation head driven by a STEP/DIR stepper driver (A4988, DRV8825, TMC2209) on GPIO lines,
// through libgpiod 1.6 (v1 API, as Debian 12 packages it).
//
// Moves: whole microsteps only (InputError naming the nearest reachable angle otherwise), inside
// the soft limits, always arriving in the rig's approach direction (backlash), with a
// constant-acceleration ramp whose step edges are scheduled against absolute deadlines
// (clock_nanosleep TIMER_ABSTIME on CLOCK_MONOTONIC), so user-space jitter delays single edges
// but never accumulates. Homing steps towards the switch at the homing speed and stops at the
// first switch edge, read with non-blocking reads of the line's event fd between steps (no
// blocking wait: it works the same on hardware and under umockdev, whose gpiochip emulation does
// not support poll). Without a home switch, home() declares the current position home.
//
// Threading: one thread at a time. Failures: DeviceError (persistent for a missing chip or
// line, transient for a failed line write).

#include <memory>
#include <string>

#include "acquisition/device.h"
#include "acquisition/rig.h"

namespace flarekit::acquisition {

struct GpioMoveStats {
  long long steps = 0;          // STEP pulses of the last move (all legs)
  double late_max_us = 0;       // the latest a STEP edge came after its deadline
  double duration_s = 0;
};

class GpioStepperHead : public RotationHead {
 public:
  // Opens the chip and requests the lines. DeviceError when the chip or a line is missing or
  // busy (the message names them and says what to check).
  explicit GpioStepperHead(const GpioStepperConfig& config, std::string rig_file = "");
  ~GpioStepperHead() override;
  GpioStepperHead(GpioStepperHead&&) noexcept;
  GpioStepperHead& operator=(GpioStepperHead&&) noexcept;

  std::string describe() const override;
  void home() override;
  void moveTo(double angle_deg) override;
  double angleDeg() const override;

  long long positionMicrosteps() const;
  const GpioMoveStats& lastMove() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// rig-check: whether the chip and lines exist and are free; one line per finding.
bool probeGpio(const GpioStepperConfig& config, std::vector<std::string>* lines);

}  // namespace flarekit::acquisition
