#include "acquisition/tic_head.h"

#include <libusb.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <sstream>
#include <thread>

#include "acquisition/stepper_motion.h"
#include "common/log.h"

namespace flarekit::acquisition {
namespace {

// Commands (bRequest of vendor OUT control transfers).
enum TicCommand : uint8_t {
  kSetTargetPosition = 0xE0,
  kHaltAndSetPosition = 0xEC,
  kHaltAndHold = 0x89,
  kGoHome = 0x97,
  kResetCommandTimeout = 0x8C,
  kEnergize = 0x85,
  kDeenergize = 0x86,
  kExitSafeStart = 0x83,
  kSetMaxSpeed = 0xE6,
  kSetStartingSpeed = 0xE5,
  kSetMaxAcceleration = 0xEA,
  kSetMaxDeceleration = 0xE9,
  kGetVariable = 0xA1,
  kGetVariableAndClearErrors = 0xA2,
};
// Variable offsets.
constexpr uint16_t kOperationState = 0x00, kMiscFlags = 0x01, kErrorStatus = 0x02,
                   kTargetPosition = 0x0A, kCurrentPosition = 0x22;
constexpr int kVariablesLength = 0x26;  // through the current position
constexpr unsigned kTimeoutMs = 500;
// Misc flags bits.
constexpr uint8_t kFlagEnergized = 1 << 0, kFlagPositionUncertain = 1 << 1, kFlagHomingActive = 1 << 4;
// Errors that a person must clear (everything but "intentionally de-energized", "safe start
// violation" and "command timeout", which the driver clears itself).
constexpr uint16_t kSeriousErrors = (1 << 1) | (1 << 2) | (1 << 3) | (1 << 4) | (1 << 8);

struct ContextDeleter {
  void operator()(libusb_context* c) const { libusb_exit(c); }
};
struct HandleDeleter {
  void operator()(libusb_device_handle* h) const { libusb_close(h); }
};
struct DeviceListDeleter {
  void operator()(libusb_device** l) const { libusb_free_device_list(l, 1); }
};
// Owners of the libusb handles.
using ContextPtr = std::unique_ptr<libusb_context, ContextDeleter>;
using HandlePtr = std::unique_ptr<libusb_device_handle, HandleDeleter>;
using DeviceListPtr = std::unique_ptr<libusb_device*, DeviceListDeleter>;

bool isTic(const libusb_device_descriptor& d) {
  if (d.idVendor != kPololuVendorId) return false;
  for (uint16_t p : kTicProductIds)
    if (d.idProduct == p) return true;
  return false;
}

std::string productName(uint16_t pid) {
  switch (pid) {
    case 0x00B3: return "Tic T825";
    case 0x00B5: return "Tic T834";
    case 0x00BD: return "Tic T500";
    case 0x00C3: return "Tic N825";
    case 0x00C9: return "Tic T249";
    case 0x00CB: return "Tic 36v4";
  }
  return "Tic";
}

std::string serialOf(libusb_device_handle* h, const libusb_device_descriptor& d) {
  if (!d.iSerialNumber) return "";
  unsigned char buf[64] = {};
  int n = libusb_get_string_descriptor_ascii(h, d.iSerialNumber, buf, sizeof buf - 1);
  return n > 0 ? std::string(reinterpret_cast<char*>(buf), static_cast<size_t>(n)) : "";
}

ContextPtr makeContext() {
  libusb_context* ctx = nullptr;
  const int rc = libusb_init(&ctx);
  if (rc != 0)
    throw DeviceError(std::string("cannot initialise libusb (") + libusb_error_name(rc) + ")", false);
  return ContextPtr(ctx);
}

}  // namespace

std::string ticErrorText(uint16_t e) {
  static const char* names[] = {"intentionally de-energized", "motor driver error",
                                "low VIN (motor supply)", "kill switch active",
                                "required input invalid", "serial error",
                                "command timeout", "safe start violation", "ERR line high"};
  std::string out;
  for (int bit = 0; bit < 9; ++bit)
    if (e & (1u << bit)) {
      if (!out.empty()) out += ", ";
      out += names[bit];
    }
  return out.empty() ? "no error" : out;
}

struct TicHead::Impl {
  TicConfig config;
  std::string where;
  ContextPtr ctx;
  HandlePtr handle;
  std::string serial, product;
  bool homed = false;
  double commanded_angle = 0;

  const StepperGeometry& g() const { return config.geometry; }

  void open() {
    ctx = makeContext();
    libusb_device** raw = nullptr;
    const ssize_t n = libusb_get_device_list(ctx.get(), &raw);
    if (n < 0) throw DeviceError("cannot list USB devices", true);
    DeviceListPtr list(raw);
    std::vector<std::string> seen;
    for (ssize_t i = 0; i < n; ++i) {
      libusb_device_descriptor d;
      if (libusb_get_device_descriptor(list.get()[i], &d) != 0 || !isTic(d)) continue;
      libusb_device_handle* h = nullptr;
      const int rc = libusb_open(list.get()[i], &h);
      if (rc != 0) {
        throw DeviceError(
            "found a Pololu " + productName(d.idProduct) + " but cannot open it (" +
                libusb_error_name(rc) +
                "): add the udev rule SUBSYSTEM==\"usb\", ATTRS{idVendor}==\"1ffb\", MODE=\"0666\" "
                "to /etc/udev/rules.d/99-pololu.rules and plug it in again",
            false);
      }
      HandlePtr candidate(h);
      const std::string s = serialOf(h, d);
      seen.push_back(s);
      if (!config.serial.empty() && s != config.serial) continue;
      handle = std::move(candidate);
      serial = s;
      product = productName(d.idProduct);
      return;
    }
    std::string message = config.serial.empty()
                              ? "no Pololu Tic stepper controller on the USB bus"
                              : "no Pololu Tic with serial number " + config.serial +
                                    " on the USB bus";
    if (!seen.empty()) {
      message += " (found:";
      for (const auto& s : seen) message += " " + s;
      message += ")";
    }
    throw DeviceError(message + ": check the USB cable and the controller's power, and head.serial in " +
                          where,
                      false);
  }

  void command(uint8_t request, uint32_t value = 0) {
    const int rc = libusb_control_transfer(handle.get(), 0x40, request,
                                           static_cast<uint16_t>(value & 0xFFFF),
                                           static_cast<uint16_t>(value >> 16), nullptr, 0, kTimeoutMs);
    if (rc < 0) {
      const bool gone = rc == LIBUSB_ERROR_NO_DEVICE;
      throw DeviceError("Tic " + serial + ": command 0x" + hex(request) + " failed (" +
                            libusb_error_name(rc) + ")" +
                            (gone ? ": the controller was disconnected" : ""),
                        /*transient=*/!gone);
    }
  }

  std::vector<uint8_t> variables(bool clear_errors = false) {
    std::vector<uint8_t> buf(kVariablesLength);
    const int rc = libusb_control_transfer(
        handle.get(), 0xC0, clear_errors ? kGetVariableAndClearErrors : kGetVariable, 0, 0,
        buf.data(), static_cast<uint16_t>(buf.size()), kTimeoutMs);
    if (rc < 0) {
      const bool gone = rc == LIBUSB_ERROR_NO_DEVICE;
      throw DeviceError("Tic " + serial + ": reading its variables failed (" +
                            libusb_error_name(rc) + ")" +
                            (gone ? ": the controller was disconnected" : ""),
                        !gone);
    }
    if (rc < kVariablesLength)
      throw DeviceError("Tic " + serial + ": short variable read (" + std::to_string(rc) +
                            " bytes)",
                        true);
    return buf;
  }

  static int32_t i32(const std::vector<uint8_t>& b, int offset) {
    uint32_t v = static_cast<uint32_t>(b[offset]) | static_cast<uint32_t>(b[offset + 1]) << 8 |
                 static_cast<uint32_t>(b[offset + 2]) << 16 | static_cast<uint32_t>(b[offset + 3]) << 24;
    return static_cast<int32_t>(v);
  }
  static uint16_t u16(const std::vector<uint8_t>& b, int offset) {
    return static_cast<uint16_t>(b[offset] | b[offset + 1] << 8);
  }
  static std::string hex(unsigned v) {
    std::ostringstream s;
    s << std::hex << std::uppercase << v;
    return s.str();
  }

  void checkErrors(const std::vector<uint8_t>& v) {
    const uint16_t errors = u16(v, kErrorStatus);
    if (errors & kSeriousErrors)
      throw DeviceError("Tic " + serial + " reports: " + ticErrorText(errors) +
                            " (operation state " + std::to_string(v[kOperationState]) +
                            "): fix the cause (motor power, wiring, kill switch), then resume",
                        false);
  }

  void configureMotion() {
    const double per_deg = g().microstepsPerDeg();
    // Speeds in microsteps per 10 000 s, accelerations in microsteps per 100 s².
    command(kSetMaxSpeed, static_cast<uint32_t>(std::llround(g().max_speed_deg_s * per_deg * 1e4)));
    command(kSetStartingSpeed, 0);
    command(kSetMaxAcceleration, static_cast<uint32_t>(std::llround(g().accel_deg_s2 * per_deg * 100)));
    command(kSetMaxDeceleration, static_cast<uint32_t>(std::llround(g().accel_deg_s2 * per_deg * 100)));
  }

  void start() {
    variables(/*clear_errors=*/true);
    command(kEnergize);
    command(kExitSafeStart);
  }

  // Waits until `done(variables)` while resetting the command timeout; DeviceError on controller
  // errors or after the move timeout.
  template <class Done>
  void waitFor(const Done& done, const std::string& what) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::duration<double>(config.move_timeout_s);
    const auto poll = std::chrono::duration<double>(std::min(0.02, config.command_timeout_s / 4));
    for (;;) {
      command(kResetCommandTimeout);
      std::vector<uint8_t> v = variables();
      checkErrors(v);
      if (done(v)) return;
      if (std::chrono::steady_clock::now() > deadline) {
        command(kHaltAndHold);
        throw DeviceError("Tic " + serial + ": " + what + " did not finish within " +
                              std::to_string(config.move_timeout_s) +
                              " s (position " + std::to_string(i32(v, kCurrentPosition)) +
                              ", target " + std::to_string(i32(v, kTargetPosition)) +
                              "): is the motor stalled or blocked?",
                          false);
      }
      std::this_thread::sleep_for(poll);
    }
  }

  void moveToMicrosteps(int32_t target) {
    start();
    command(kSetTargetPosition, static_cast<uint32_t>(target));
    waitFor([&](const std::vector<uint8_t>& v) { return i32(v, kCurrentPosition) == target; },
            "the move to " + std::to_string(target));
  }
};

TicHead::TicHead(const TicConfig& config, std::string rig_file) : impl_(std::make_unique<Impl>()) {
  impl_->config = config;
  impl_->where = rig_file.empty() ? "the rig file" : rig_file;
  impl_->open();
  impl_->configureMotion();
}
TicHead::~TicHead() {
  if (impl_ && impl_->handle) {
    try {
      impl_->command(kDeenergize);
    } catch (const DeviceError&) {
    }
  }
}
TicHead::TicHead(TicHead&&) noexcept = default;
TicHead& TicHead::operator=(TicHead&&) noexcept = default;

std::string TicHead::describe() const {
  return "Pololu " + impl_->product + " (serial " + impl_->serial + ")";
}

void TicHead::home() {
  Impl& m = *impl_;
  m.start();
  // The Tic's homing procedure (limit/home switch configured in the controller's settings).
  m.command(kGoHome, m.g().home_direction > 0 ? 1 : 0);
  m.waitFor(
      [](const std::vector<uint8_t>& v) {
        return !(v[kMiscFlags] & kFlagHomingActive) && !(v[kMiscFlags] & kFlagPositionUncertain);
      },
      "homing");
  // The home position is the reference for home_angle_deg.
  m.command(kHaltAndSetPosition, 0);
  m.homed = true;
  m.commanded_angle = m.g().home_angle_deg;
}

void TicHead::moveTo(double angle_deg) {
  Impl& m = *impl_;
  checkSoftLimits(m.g(), angle_deg, m.where);
  const long long target = microstepsForAngle(m.g(), angle_deg, m.where);
  const long long current = m.i32(m.variables(), kCurrentPosition);
  const long long backlash = std::llround(m.g().backlash_deg * m.g().microstepsPerDeg());
  for (long long w : approachWaypoints(current, target, m.g().approach_sign, backlash))
    m.moveToMicrosteps(static_cast<int32_t>(w));
  m.commanded_angle = angle_deg;
}

double TicHead::angleDeg() const { return impl_->commanded_angle; }

int32_t TicHead::readPosition() { return impl_->i32(impl_->variables(), kCurrentPosition); }

void TicHead::reconnect() {
  impl_->handle.reset();
  impl_->open();
  impl_->configureMotion();
}

bool probeTic(const TicConfig& config, std::vector<std::string>* lines) {
  ContextPtr ctx = makeContext();
  libusb_device** raw = nullptr;
  const ssize_t n = libusb_get_device_list(ctx.get(), &raw);
  if (n < 0) {
    lines->push_back("MISSING: cannot list USB devices");
    return false;
  }
  DeviceListPtr list(raw);
  bool found = false;
  for (ssize_t i = 0; i < n; ++i) {
    libusb_device_descriptor d;
    if (libusb_get_device_descriptor(list.get()[i], &d) != 0 || !isTic(d)) continue;
    libusb_device_handle* h = nullptr;
    const int rc = libusb_open(list.get()[i], &h);
    if (rc != 0) {
      lines->push_back("found a Pololu " + productName(d.idProduct) + " but cannot open it (" +
                       libusb_error_name(rc) + "): install the udev rule for vendor 1ffb");
      continue;
    }
    HandlePtr handle(h);
    const std::string s = serialOf(h, d);
    const bool match = config.serial.empty() || s == config.serial;
    lines->push_back("found Pololu " + productName(d.idProduct) + " serial " + s +
                     (match ? " (used)" : " (not the configured serial)"));
    found = found || match;
  }
  if (!found)
    lines->push_back(config.serial.empty() ? "MISSING: no Pololu Tic on the USB bus"
                                           : "MISSING: no Pololu Tic with serial " + config.serial);
  return found;
}

}  // namespace flarekit::acquisition
