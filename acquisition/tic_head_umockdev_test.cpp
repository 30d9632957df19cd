// The real libusb code path of TicHead against a behavioural model of a Pololu Tic behind a
// umockdev USB device: the model answers the control transfers (USBDEVFS_SUBMITURB / REAPURB),
// moves its position toward the target while energized, reports variables, and can raise errors
// or stall.
#include "acquisition/tic_head.h"

#include <gtest/gtest.h>
#include <linux/ioctl.h>
#include <linux/usbdevice_fs.h>
#include <umockdev.h>

#include <cerrno>
#include <cstring>
#include <deque>
#include <mutex>
#include <string>

namespace flarekit::acquisition {
namespace {

// What a Tic T834 does with the commands FlareKit sends (Pololu's Tic user's guide).
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

  void command(uint8_t request, uint32_t value) {
    switch (request) {
      case 0xE0: target = static_cast<int32_t>(value); ++targets_set; break;
      case 0xEC: position = target = static_cast<int32_t>(value); uncertain = false; break;
      case 0x89: target = position; break;
      case 0x97: homing = true; target = home_switch_at; break;
      case 0x8C: ++timeout_resets; break;
      case 0x85: energized = true; errors &= ~1u; break;
      case 0x86: energized = false; errors |= 1; break;
      case 0x83: safe_start = false; ++exit_safe_starts; break;
      case 0xE6: max_speed = static_cast<int32_t>(value); break;
      case 0xEA: max_accel = static_cast<int32_t>(value); break;
      default: break;
    }
  }
  // Advances the motion by one step of time, then serialises the variables.
  void variables(uint8_t* out, size_t length, bool clear) {
    ++reads;
    if (fail_after_reads >= 0 && reads > fail_after_reads) errors |= 1 << 1;
    const bool can_move = energized && !safe_start && !(errors & ~1u) && !stall;
    if (can_move && position != target) {
      const int32_t d = target - position;
      position += std::max(-speed, std::min(speed, d));
    }
    if (homing && position == target) {
      homing = false;
      uncertain = false;
      position = target = 0;  // the Tic sets its position to 0 at the home switch
    }
    uint8_t v[0x26] = {};
    v[0x00] = errors & ~1u ? 4 : (energized ? 10 : 2);
    v[0x01] = static_cast<uint8_t>((energized ? 1 : 0) | (uncertain ? 2 : 0) | (homing ? 16 : 0));
    v[0x02] = static_cast<uint8_t>(errors & 0xFF);
    v[0x03] = static_cast<uint8_t>(errors >> 8);
    std::memcpy(v + 0x0A, &target, 4);
    std::memcpy(v + 0x22, &position, 4);
    std::memcpy(out, v, std::min(length, sizeof v));
    if (clear) errors &= 1;  // "get variables and clear errors occurred"
  }
};

// One connected T834 with serial "00314159" on bus 1, device 2.
constexpr const char* kTicDevice =
    "P: /devices/pci0000:00/0000:00:14.0/usb1/1-1\n"
    "N: bus/usb/001/002\n"
    "E: SUBSYSTEM=usb\n"
    "E: DEVTYPE=usb_device\n"
    "E: BUSNUM=001\n"
    "E: DEVNUM=002\n"
    "E: DEVNAME=/dev/bus/usb/001/002\n"
    "A: busnum=1\\n\n"
    "A: devnum=2\\n\n"
    "A: speed=12\\n\n"
    "A: bConfigurationValue=1\\n\n"
    // Device descriptor (VID 1ffb, PID 00b5, strings 1/2/3, one configuration), then a
    // configuration with one vendor-specific interface.
    "H: descriptors=12010002ef000040fb1fb500000101020301"
    "09021200010100c032"
    "090400000000ff0000\n";

class TicBench : public ::testing::Test {
 protected:
  void SetUp() override {
    testbed_ = umockdev_testbed_new();
    handler_ = umockdev_ioctl_base_new();
    g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(&TicBench::onIoctl), this);
  }
  void TearDown() override {
    for (UMockdevIoctlData* d : done_) umockdev_ioctl_data_unref(d);
    done_.clear();
    g_clear_object(&handler_);
    g_clear_object(&testbed_);
  }
  void plugIn() {
    GError* error = nullptr;
    ASSERT_TRUE(umockdev_testbed_attach_ioctl(testbed_, "/dev/bus/usb/001/002", handler_, &error));
    ASSERT_TRUE(umockdev_testbed_add_from_string(testbed_, kTicDevice, &error));
  }
  static TicConfig config() {
    TicConfig c;
    c.geometry.full_steps_per_rev = 200;
    c.geometry.microsteps = 8;
    c.geometry.gear_ratio = 1;  // 4.44 microsteps per degree: 0.225° per microstep
    c.geometry.backlash_deg = 0.9;
    c.geometry.min_deg = -90;
    c.geometry.max_deg = 90;
    c.move_timeout_s = 2;
    return c;
  }

  static gboolean onIoctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, TicBench* self) {
    return self->handle(client);
  }

  gboolean handle(UMockdevIoctlClient* client) {
    const gulong request = umockdev_ioctl_client_get_request(client);
    UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
    switch (request) {
      case USBDEVFS_GET_CAPABILITIES: {
        UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(guint32), nullptr);
        *reinterpret_cast<guint32*>(d->data) = USBDEVFS_CAP_NO_PACKET_SIZE_LIM;
        umockdev_ioctl_data_unref(d);
        umockdev_ioctl_client_complete(client, 0, 0);
        return TRUE;
      }
      case USBDEVFS_CLAIMINTERFACE:
      case USBDEVFS_RELEASEINTERFACE:
        umockdev_ioctl_client_complete(client, 0, 0);
        return TRUE;
      case USBDEVFS_SUBMITURB: {
        UMockdevIoctlData* urb_data =
            umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr);
        auto* urb = reinterpret_cast<usbdevfs_urb*>(urb_data->data);
        UMockdevIoctlData* buffer = umockdev_ioctl_data_resolve(
            urb_data, G_STRUCT_OFFSET(usbdevfs_urb, buffer), urb->buffer_length, nullptr);
        answer(urb, buffer->data);
        umockdev_ioctl_data_unref(buffer);
        {
          std::lock_guard<std::mutex> lock(urbs_mutex_);
          done_.push_back(urb_data);  // reaped next
        }
        umockdev_ioctl_client_complete(client, 0, 0);
        return TRUE;
      }
      case USBDEVFS_REAPURB:
      case USBDEVFS_REAPURBNDELAY: {
        UMockdevIoctlData* urb_data = nullptr;
        {
          std::lock_guard<std::mutex> lock(urbs_mutex_);
          if (!done_.empty()) {
            urb_data = done_.front();
            done_.pop_front();
          }
        }
        if (!urb_data) {
          umockdev_ioctl_client_complete(client, -1, EAGAIN);
          return TRUE;
        }
        UMockdevIoctlData* ptr = umockdev_ioctl_data_resolve(arg, 0, sizeof(gpointer), nullptr);
        umockdev_ioctl_data_set_ptr(ptr, 0, urb_data);
        umockdev_ioctl_data_unref(ptr);
        umockdev_ioctl_data_unref(urb_data);
        umockdev_ioctl_client_complete(client, 0, 0);
        return TRUE;
      }
      default:
        return FALSE;
    }
  }

  // Interprets one control transfer (8-byte setup packet, then the data stage).
  void answer(usbdevfs_urb* urb, uint8_t* buf) {
    const uint8_t type = buf[0], request = buf[1];
    const uint16_t value = static_cast<uint16_t>(buf[2] | buf[3] << 8);
    const uint16_t index = static_cast<uint16_t>(buf[4] | buf[5] << 8);
    const uint16_t length = static_cast<uint16_t>(buf[6] | buf[7] << 8);
    uint8_t* data = buf + 8;
    urb->status = 0;
    urb->actual_length = 0;
    std::lock_guard<std::mutex> lock(tic.mutex);
    if (type == 0x40) {
      tic.command(request, static_cast<uint32_t>(value) | static_cast<uint32_t>(index) << 16);
    } else if (type == 0xC0 && (request == 0xA1 || request == 0xA2)) {
      std::vector<uint8_t> all(128);
      tic.variables(all.data(), all.size(), request == 0xA2);
      const size_t n = std::min<size_t>(length, all.size() - index);
      std::memcpy(data, all.data() + index, n);
      urb->actual_length = static_cast<int>(n);
    } else if (type == 0x80 && request == 6 && (value >> 8) == 3) {
      // String descriptors: language list, then UTF-16LE strings.
      std::string s = (value & 0xFF) == 3 ? "00314159" : "Pololu";
      std::vector<uint8_t> d;
      if ((value & 0xFF) == 0) {
        d = {4, 3, 0x09, 0x04};
      } else {
        d = {static_cast<uint8_t>(2 + 2 * s.size()), 3};
        for (char c : s) d.insert(d.end(), {static_cast<uint8_t>(c), 0});
      }
      const size_t n = std::min<size_t>(length, d.size());
      std::memcpy(data, d.data(), n);
      urb->actual_length = static_cast<int>(n);
    } else {
      urb->status = -EPIPE;  // stall: unsupported request
    }
  }

  UMockdevTestbed* testbed_ = nullptr;
  UMockdevIoctlBase* handler_ = nullptr;
  std::mutex urbs_mutex_;
  std::deque<UMockdevIoctlData*> done_;
  TicModel tic;
};

TEST_F(TicBench, MovesToTargetsFromOneSideAndReportsPositions) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  EXPECT_NE(head.describe().find("00314159"), std::string::npos) << head.describe();
  head.home();
  EXPECT_EQ(head.readPosition(), 0);
  head.moveTo(45);  // 200 microsteps
  EXPECT_EQ(head.readPosition(), 200);
  EXPECT_DOUBLE_EQ(head.angleDeg(), 45);
  head.moveTo(22.5);  // backwards: overshoot by 4 microsteps of backlash, come back
  EXPECT_EQ(head.readPosition(), 100);
  std::lock_guard<std::mutex> lock(tic.mutex);
  EXPECT_TRUE(tic.energized);
  EXPECT_FALSE(tic.safe_start);
  EXPECT_EQ(tic.targets_set, 3);  // 200, then 96 (overshoot) and 100
  EXPECT_GT(tic.timeout_resets, 5);  // command timeout reset while waiting
  // Speed 10°/s × 4.44 microsteps/° × 10⁴, acceleration 20°/s² × 4.44 × 100.
  EXPECT_EQ(tic.max_speed, 444444);
  EXPECT_EQ(tic.max_accel, 8889);
}

TEST_F(TicBench, RejectsAnglesThatAreNotWholeMicrosteps) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  head.home();
  try {
    head.moveTo(0.2);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("0.225"), std::string::npos) << e.what();
  }
}

TEST_F(TicBench, ControllerErrorsBecomeClearMessages) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  head.home();
  {
    std::lock_guard<std::mutex> lock(tic.mutex);
    tic.fail_after_reads = tic.reads + 2;
  }
  try {
    head.moveTo(90);
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("motor driver error"), std::string::npos) << e.what();
    EXPECT_FALSE(e.transient());
  }
}

TEST_F(TicBench, StallTimesOutWithAClearError) {
  plugIn();
  TicConfig c = config();
  c.move_timeout_s = 0.3;
  TicHead head(c, "tic-test.toml");
  head.home();
  {
    std::lock_guard<std::mutex> lock(tic.mutex);
    tic.stall = true;
  }
  try {
    head.moveTo(10 * 0.225);
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("stalled"), std::string::npos) << e.what();
  }
}

TEST_F(TicBench, MissingControllerSaysWhatToCheck) {
  try {
    TicHead head(config(), "tic-test.toml");
    FAIL();
  } catch (const DeviceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("no Pololu Tic"), std::string::npos) << m;
    EXPECT_NE(m.find("tic-test.toml"), std::string::npos) << m;
  }
  std::vector<std::string> lines;
  EXPECT_FALSE(probeTic(config(), &lines));
}

TEST_F(TicBench, WrongSerialIsNotUsed) {
  plugIn();
  TicConfig c = config();
  c.serial = "99999999";
  EXPECT_THROW(TicHead head(c, "tic-test.toml"), DeviceError);
  std::vector<std::string> lines;
  c.serial = "00314159";
  EXPECT_TRUE(probeTic(c, &lines));
}

}  // namespace
}  // namespace flarekit::acquisition
