#pragma once
// An emulated Pololu Tic T834 (serial "00314159", USB bus 1 device 2) in a umockdev testbed: a
// behavioural model of the controller answers the USB control transfers TicHead sends
// (USBDEVFS_SUBMITURB / REAPURB), moves its position toward the target while energized, reports
// its variables, and can raise errors or stall. For tests of the real libusb code path.
//
// The testbed sets UMOCKDEV_DIR; a process sees the device when it runs with
// libumockdev-preload (umockdev-wrapper), whether it is this process or a child it starts: the
// model answers from umockdev's worker thread in this process either way.

#include <cstdint>
#include <deque>
#include <mutex>

#include <umockdev.h>

namespace flarekit::testing {

// What a Tic T834 does with the commands FlareKit sends (Pololu's Tic user's guide). Lock
// `mutex` to read or change it while a driver may be talking to it.
struct TicModel {
  std::mutex mutex;
  int32_t position = 0, target = 0;
  bool energized = false, safe_start = true, homing = false, uncertain = true;
  uint16_t errors = 1;  // "intentionally de-energized" at power-up
  int32_t speed = 40;   // microsteps per variable read while moving
  bool stall = false;   // the motor does not move
  int fail_after_reads = -1;  // raise "motor driver error" after this many variable reads
  int reads = 0, timeout_resets = 0, targets_set = 0, exit_safe_starts = 0;
  int32_t max_speed = 0, max_accel = 0;
  int32_t home_switch_at = -300;  // where the switch is, in microsteps from power-up

  // A command (vendor OUT request) with its 32-bit value.
  void command(uint8_t request, uint32_t value);
  // Advances the motion by one step of time, then serialises the variables into `out`.
  void variables(uint8_t* out, size_t length, bool clear);
};

class EmulatedTic {
 public:
  // An empty testbed (no devices yet); the model is reachable through model().
  EmulatedTic();
  ~EmulatedTic();
  EmulatedTic(const EmulatedTic&) = delete;
  EmulatedTic& operator=(const EmulatedTic&) = delete;

  // Connects the controller (false with a message on stderr when umockdev refuses).
  bool plugIn();
  TicModel& model() { return model_; }

 private:
  static gboolean onIoctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, EmulatedTic* self);
  gboolean handle(UMockdevIoctlClient* client);

  UMockdevTestbed* testbed_ = nullptr;
  UMockdevIoctlBase* handler_ = nullptr;
  std::mutex urbs_mutex_;
  std::deque<UMockdevIoctlData*> done_;  // submitted URBs, reaped in order
  TicModel model_;
};

}  // namespace flarekit::testing
