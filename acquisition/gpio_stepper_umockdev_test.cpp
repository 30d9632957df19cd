// The real libgpiod 1.6 code path of GpioStepperHead against a fake gpiochip in a umockdev
// testbed. The fake answers the chip ioctls (chip and line info, line-handle and line-event
// requests), counts STEP rising edges with the DIR level at each, tracks the head's position and
// presses a home switch at a chosen position, which the driver reads as a falling edge event.
//
// Line handles and event requests return new file descriptors in the kernel; here they are
// descriptors of the same emulated node that the test opened beforehand and tagged (a
// GPIO_GET_CHIPINFO_IOCTL carrying a marker), so that ioctls and reads on them reach the fake.
// gpiod_line_event_wait cannot be used under umockdev (no poll); the driver reads events without
// blocking, which is what this test exercises.
#include "acquisition/gpio_stepper_head.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <linux/gpio.h>
#include <linux/ioctl.h>
#include <sys/ioctl.h>
#include <umockdev.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <string>

namespace flarekit::acquisition {
namespace {

constexpr int kStep = 3, kDir = 4, kEnable = 5, kHome = 6, kLines = 16;
constexpr const char* kMarker = "flarekit-fd:";

struct FakeChip {
  std::mutex mutex;
  int level[kLines] = {};
  bool requested[kLines] = {};
  bool output[kLines] = {};
  long long rising_steps = 0;
  long long position = 0;  // +1 per STEP edge with DIR high, −1 with DIR low
  long long steps_dir_high = 0, steps_dir_low = 0;
  long long switch_at = -1000000;  // the switch closes (line low) at or below this position
  std::deque<gpioevent_data> events;
  bool enable_seen_active = false;

  void stepped() {
    ++rising_steps;
    if (level[kDir]) {
      ++position;
      ++steps_dir_high;
    } else {
      --position;
      ++steps_dir_low;
    }
    const int before = level[kHome];
    level[kHome] = position <= switch_at ? 0 : 1;  // pull-up: high when open
    if (before == 1 && level[kHome] == 0) {
      gpioevent_data e{};
      e.timestamp = static_cast<uint64_t>(rising_steps);
      e.id = GPIOEVENT_EVENT_FALLING_EDGE;
      events.push_back(e);
    }
  }
};

class GpioBench : public ::testing::Test {
 protected:
  void SetUp() override {
    testbed_ = umockdev_testbed_new();
    handler_ = umockdev_ioctl_base_new();
    g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(&GpioBench::onIoctl), this);
    g_signal_connect(handler_, "handle-read", G_CALLBACK(&GpioBench::onRead), this);
    GError* error = nullptr;
    ASSERT_TRUE(umockdev_testbed_attach_ioctl(testbed_, "/dev/gpiochip0", handler_, &error));
    ASSERT_TRUE(umockdev_testbed_add_from_string(testbed_,
                                                 "P: /devices/platform/gpio-fake.0/gpiochip0\n"
                                                 "N: gpiochip0\n"
                                                 "E: SUBSYSTEM=gpio\n"
                                                 "E: DEVNAME=/dev/gpiochip0\n"
                                                 "A: dev=254:0\\n\n",
                                                 &error))
        << (error ? error->message : "");
    chip.level[kHome] = 1;
    // Descriptors the fake hands out for line requests (see the file comment).
    for (int k = 0; k < 6; ++k) {
      const int fd = ::open("/dev/gpiochip0", O_RDWR | O_CLOEXEC);
      ASSERT_GE(fd, 0) << std::strerror(errno);
      gpiochip_info tag{};
      std::snprintf(tag.name, sizeof tag.name, "%s%d", kMarker, fd);
      ASSERT_EQ(::ioctl(fd, GPIO_GET_CHIPINFO_IOCTL, &tag), 0);
      spare_fds_.push_back(fd);
    }
  }
  void TearDown() override {
    // Descriptors handed to libgpiod were closed by it when the head released its lines.
    for (int fd : spare_fds_)
      if (!role_.count(fd)) ::close(fd);
    g_clear_object(&handler_);
    g_clear_object(&testbed_);
  }

  static GpioStepperConfig config() {
    GpioStepperConfig c;
    c.chip = "gpiochip0";
    c.step_line = kStep;
    c.dir_line = kDir;
    c.enable_line = kEnable;
    c.home_line = kHome;
    c.step_pulse_us = 2;
    c.geometry.full_steps_per_rev = 200;
    c.geometry.microsteps = 2;
    c.geometry.gear_ratio = 1;  // 400 microsteps per turn: 0.9° each
    c.geometry.max_speed_deg_s = 3600;
    c.geometry.accel_deg_s2 = 36000;
    c.geometry.backlash_deg = 1.8;  // 2 microsteps
    c.geometry.approach_sign = +1;
    c.geometry.min_deg = -360;
    c.geometry.max_deg = 360;
    c.geometry.home_direction = -1;
    c.geometry.home_speed_deg_s = 3600;
    c.geometry.home_search_deg = 90;  // 100 microsteps
    c.geometry.home_backoff_deg = 0.9;
    return c;
  }

  static gboolean onIoctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, GpioBench* self) {
    return self->handleIoctl(client);
  }
  static gboolean onRead(UMockdevIoctlBase*, UMockdevIoctlClient* client, GpioBench* self) {
    return self->handleRead(client);
  }

  // The descriptor a client connection stands for (-1: libgpiod's own chip descriptor).
  int fdOf(UMockdevIoctlClient* client) {
    auto it = client_fd_.find(client);
    return it == client_fd_.end() ? -1 : it->second;
  }

  int takeSpareFd(int role_line, bool events) {
    for (int fd : spare_fds_)
      if (!role_.count(fd)) {
        role_[fd] = {role_line, events};
        return fd;
      }
    return -1;
  }

  gboolean handleIoctl(UMockdevIoctlClient* client) {
    const gulong request = umockdev_ioctl_client_get_request(client);
    UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
    std::lock_guard<std::mutex> lock(chip.mutex);
    if (request == GPIO_GET_CHIPINFO_IOCTL) {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(gpiochip_info), nullptr);
      auto* info = reinterpret_cast<gpiochip_info*>(d->data);
      if (std::strncmp(info->name, kMarker, std::strlen(kMarker)) == 0)
        client_fd_[client] = std::atoi(info->name + std::strlen(kMarker));
      std::memset(info, 0, sizeof *info);
      std::strcpy(info->name, "gpiochip0");
      std::strcpy(info->label, "flarekit-fake");
      info->lines = kLines;
      umockdev_ioctl_data_unref(d);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    if (request == GPIO_GET_LINEINFO_IOCTL) {
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(gpioline_info), nullptr);
      auto* info = reinterpret_cast<gpioline_info*>(d->data);
      const unsigned offset = info->line_offset;
      if (offset >= kLines) {
        umockdev_ioctl_data_unref(d);
        umockdev_ioctl_client_complete(client, -1, EINVAL);
        return TRUE;
      }
      info->flags = (chip.requested[offset] ? GPIOLINE_FLAG_KERNEL : 0) |
                    (chip.output[offset] ? GPIOLINE_FLAG_IS_OUT : 0);
      std::snprintf(info->name, sizeof info->name, "GPIO%u", offset);
      std::strcpy(info->consumer, chip.requested[offset] ? "flarekit" : "");
      umockdev_ioctl_data_unref(d);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    if (request == GPIO_GET_LINEHANDLE_IOCTL) {
      UMockdevIoctlData* d =
          umockdev_ioctl_data_resolve(arg, 0, sizeof(gpiohandle_request), nullptr);
      auto* req = reinterpret_cast<gpiohandle_request*>(d->data);
      const int line = static_cast<int>(req->lineoffsets[0]);
      const int fd = req->lines == 1 ? takeSpareFd(line, false) : -1;
      if (fd < 0 || line >= kLines || chip.requested[line]) {
        umockdev_ioctl_data_unref(d);
        umockdev_ioctl_client_complete(client, -1, EBUSY);
        return TRUE;
      }
      chip.requested[line] = true;
      chip.output[line] = (req->flags & GPIOHANDLE_REQUEST_OUTPUT) != 0;
      if (chip.output[line]) chip.level[line] = req->default_values[0];
      active_low_[line] = (req->flags & GPIOHANDLE_REQUEST_ACTIVE_LOW) != 0;
      req->fd = fd;
      umockdev_ioctl_data_unref(d);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    if (request == GPIO_GET_LINEEVENT_IOCTL) {
      UMockdevIoctlData* d =
          umockdev_ioctl_data_resolve(arg, 0, sizeof(gpioevent_request), nullptr);
      auto* req = reinterpret_cast<gpioevent_request*>(d->data);
      const int line = static_cast<int>(req->lineoffset);
      falling_requested_ = (req->eventflags & GPIOEVENT_REQUEST_FALLING_EDGE) != 0;
      pull_up_requested_ = (req->handleflags & GPIOHANDLE_REQUEST_BIAS_PULL_UP) != 0;
      const int fd = takeSpareFd(line, true);
      chip.requested[line] = true;
      req->fd = fd;
      umockdev_ioctl_data_unref(d);
      umockdev_ioctl_client_complete(client, fd < 0 ? -1 : 0, fd < 0 ? EBUSY : 0);
      return TRUE;
    }
    if (request == GPIOHANDLE_SET_LINE_VALUES_IOCTL || request == GPIOHANDLE_GET_LINE_VALUES_IOCTL) {
      const int fd = fdOf(client);
      auto role = role_.find(fd);
      if (role == role_.end()) {
        umockdev_ioctl_client_complete(client, -1, EINVAL);
        return TRUE;
      }
      const int line = role->second.first;
      UMockdevIoctlData* d = umockdev_ioctl_data_resolve(arg, 0, sizeof(gpiohandle_data), nullptr);
      auto* data = reinterpret_cast<gpiohandle_data*>(d->data);
      if (request == GPIOHANDLE_SET_LINE_VALUES_IOCTL) {
        // Logical values; ACTIVE_LOW lines drive the pin inverted.
        const int pin = active_low_[line] ? !data->values[0] : data->values[0];
        const int before = chip.level[line];
        chip.level[line] = pin;
        if (line == kStep && before == 0 && pin == 1) chip.stepped();
        if (line == kEnable && pin == 0) chip.enable_seen_active = true;  // active low
      } else {
        data->values[0] = static_cast<uint8_t>(chip.level[line]);
      }
      umockdev_ioctl_data_unref(d);
      umockdev_ioctl_client_complete(client, 0, 0);
      return TRUE;
    }
    return FALSE;
  }

  gboolean handleRead(UMockdevIoctlClient* client) {
    std::lock_guard<std::mutex> lock(chip.mutex);
    UMockdevIoctlData* arg = umockdev_ioctl_client_get_arg(client);
    auto role = role_.find(fdOf(client));
    if (role == role_.end() || !role->second.second || chip.events.empty() ||
        arg->data_len < static_cast<int>(sizeof(gpioevent_data))) {
      umockdev_ioctl_client_complete(client, -1, EAGAIN);
      return TRUE;
    }
    std::memcpy(arg->data, &chip.events.front(), sizeof(gpioevent_data));
    chip.events.pop_front();
    umockdev_ioctl_client_complete(client, sizeof(gpioevent_data), 0);
    return TRUE;
  }

  UMockdevTestbed* testbed_ = nullptr;
  UMockdevIoctlBase* handler_ = nullptr;
  std::vector<int> spare_fds_;
  std::map<UMockdevIoctlClient*, int> client_fd_;
  std::map<int, std::pair<int, bool>> role_;  // fd → (line, events)
  std::map<int, bool> active_low_;
  bool falling_requested_ = false, pull_up_requested_ = false;
  FakeChip chip;
};

TEST_F(GpioBench, MoveGivesTheRightStepCountAndDirection) {
  GpioStepperHead head(config(), "gpio-test.toml");
  EXPECT_NE(head.describe().find("gpiochip0"), std::string::npos);
  head.moveTo(90);  // 100 microsteps forward, DIR high (dir_high_is_positive)
  {
    std::lock_guard<std::mutex> lock(chip.mutex);
    EXPECT_EQ(chip.rising_steps, 100);
    EXPECT_EQ(chip.steps_dir_high, 100);
    EXPECT_EQ(chip.steps_dir_low, 0);
    EXPECT_EQ(chip.level[kDir], 1);
    EXPECT_TRUE(chip.enable_seen_active);
    EXPECT_EQ(chip.level[kStep], 0);  // pulses end low
  }
  EXPECT_EQ(head.positionMicrosteps(), 100);
  EXPECT_DOUBLE_EQ(head.angleDeg(), 90);
  // Backwards to 45°: DIR low past the target by the backlash (2 microsteps), then DIR high.
  head.moveTo(45);
  std::lock_guard<std::mutex> lock(chip.mutex);
  EXPECT_EQ(chip.steps_dir_low, 52);
  EXPECT_EQ(chip.steps_dir_high, 102);
  EXPECT_EQ(chip.position, 50);
  EXPECT_EQ(chip.level[kDir], 1);  // arrived moving in the approach direction
  EXPECT_EQ(head.lastMove().steps, 54);
}

TEST_F(GpioBench, HomingStopsAtTheSwitchEdge) {
  {
    std::lock_guard<std::mutex> lock(chip.mutex);
    chip.switch_at = -37;  // the switch closes 37 microsteps below the start position
  }
  GpioStepperHead head(config(), "gpio-test.toml");
  head.home();
  std::lock_guard<std::mutex> lock(chip.mutex);
  EXPECT_TRUE(falling_requested_);
  EXPECT_TRUE(pull_up_requested_);
  // It went down to the switch (37 steps, DIR low), stopped at the edge, and backed off by one
  // microstep (0.9°) approaching from the positive side: no overshoot past the switch.
  EXPECT_EQ(chip.steps_dir_low, 37);
  EXPECT_EQ(chip.position, -36);
  EXPECT_EQ(head.positionMicrosteps(), 1);
  EXPECT_DOUBLE_EQ(head.angleDeg(), 0.9);
}

TEST_F(GpioBench, HomingWithoutASwitchEdgeFailsClearly) {
  GpioStepperHead head(config(), "gpio-test.toml");  // switch never reached
  try {
    head.home();
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("no home switch edge"), std::string::npos) << e.what();
  }
  std::lock_guard<std::mutex> lock(chip.mutex);
  EXPECT_EQ(chip.rising_steps, 100);  // gave up after home_search_deg
}

TEST_F(GpioBench, RejectsAnglesOffTheMicrostepGridAndOutsideLimits) {
  GpioStepperHead head(config(), "gpio-test.toml");
  EXPECT_THROW(head.moveTo(1.0), InputError);  // 1.11 microsteps
  EXPECT_THROW(head.moveTo(400), InputError);  // soft limit
  std::lock_guard<std::mutex> lock(chip.mutex);
  EXPECT_EQ(chip.rising_steps, 0);
}

TEST_F(GpioBench, MissingLineSaysWhatToCheck) {
  GpioStepperConfig c = config();
  c.step_line = 40;  // the chip has 16 lines
  try {
    GpioStepperHead head(c, "gpio-test.toml");
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("no line 40"), std::string::npos) << e.what();
  }
  c = config();
  c.chip = "gpiochip7";
  EXPECT_THROW(GpioStepperHead head(c, "gpio-test.toml"), DeviceError);
}

}  // namespace
}  // namespace flarekit::acquisition
