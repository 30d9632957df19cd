#include "acquisition/testing/tic_emulator.h"

#include <linux/ioctl.h>
#include <linux/usbdevice_fs.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace flarekit::testing {
namespace {

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

// Interprets one control transfer (8-byte setup packet, then the data stage).
void answer(TicModel& tic, usbdevfs_urb* urb, uint8_t* buf) {
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

}  // namespace

void TicModel::command(uint8_t request, uint32_t value) {
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

void TicModel::variables(uint8_t* out, size_t length, bool clear) {
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

EmulatedTic::EmulatedTic() {
  testbed_ = umockdev_testbed_new();
  handler_ = umockdev_ioctl_base_new();
  g_signal_connect(handler_, "handle-ioctl", G_CALLBACK(&EmulatedTic::onIoctl), this);
}

EmulatedTic::~EmulatedTic() {
  for (UMockdevIoctlData* d : done_) umockdev_ioctl_data_unref(d);
  done_.clear();
  g_clear_object(&handler_);
  g_clear_object(&testbed_);  // removes the testbed
}

bool EmulatedTic::plugIn() {
  GError* error = nullptr;
  if (!umockdev_testbed_attach_ioctl(testbed_, "/dev/bus/usb/001/002", handler_, &error) ||
      !umockdev_testbed_add_from_string(testbed_, kTicDevice, &error)) {
    std::fprintf(stderr, "umockdev: %s\n", error ? error->message : "cannot add the Tic");
    g_clear_error(&error);
    return false;
  }
  return true;
}

gboolean EmulatedTic::onIoctl(UMockdevIoctlBase*, UMockdevIoctlClient* client, EmulatedTic* self) {
  return self->handle(client);
}

gboolean EmulatedTic::handle(UMockdevIoctlClient* client) {
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
      UMockdevIoctlData* urb_data = umockdev_ioctl_data_resolve(arg, 0, sizeof(usbdevfs_urb), nullptr);
      auto* urb = reinterpret_cast<usbdevfs_urb*>(urb_data->data);
      UMockdevIoctlData* buffer = umockdev_ioctl_data_resolve(
          urb_data, G_STRUCT_OFFSET(usbdevfs_urb, buffer), urb->buffer_length, nullptr);
      answer(model_, urb, buffer->data);
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

}  // namespace flarekit::testing
