#include "acquisition/testing/ptpip_camera.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>

#include <opencv2/imgcodecs.hpp>

#include "acquisition/dng_writer.h"
#include "common/error.h"

namespace flarekit::testing {
namespace {

namespace fs = std::filesystem;
using acquisition::DngMetadata;
using acquisition::writeDng;

// PTP/IP packet types (CIPA DC-005 §2.3).
enum PacketType : uint32_t {
  kInitCommandRequest = 1,
  kInitCommandAck = 2,
  kInitEventRequest = 3,
  kInitEventAck = 4,
  kCommandRequest = 6,
  kCommandResponse = 7,
  kEvent = 8,
  kStartData = 9,
  kData = 10,
  kEndData = 12,
};

// PTP operation, response, event and property codes (PIMA 15740).
constexpr uint16_t kGetDeviceInfo = 0x1001, kOpenSession = 0x1002, kCloseSession = 0x1003,
                   kGetStorageIds = 0x1004, kGetStorageInfo = 0x1005, kGetObjectHandles = 0x1007,
                   kGetObjectInfo = 0x1008, kGetObject = 0x1009, kDeleteObject = 0x100B,
                   kInitiateCapture = 0x100E, kGetDevicePropDesc = 0x1014,
                   kGetDevicePropValue = 0x1015, kSetDevicePropValue = 0x1016;
constexpr uint16_t kOk = 0x2001, kSessionNotOpen = 0x2003,
                   kOperationNotSupported = 0x2005, kInvalidStorageId = 0x2008,
                   kInvalidObjectHandle = 0x2009, kDevicePropNotSupported = 0x200A,
                   kDeviceBusy = 0x2019, kInvalidDevicePropValue = 0x201C;
constexpr uint16_t kObjectAdded = 0x4002, kCaptureComplete = 0x400D;
constexpr uint16_t kFNumber = 0x5007, kExposureTime = 0x500D, kExposureIndex = 0x500F;
constexpr uint16_t kUint16 = 0x0004, kUint32 = 0x0006;
constexpr uint16_t kFormatJpeg = 0x3801, kFormatDng = 0x3811;
constexpr uint32_t kStorageId = 0x00010001;
// The largest packet the camera accepts from a client (its requests are tiny).
constexpr uint32_t kMaxRequestBytes = 1 << 20;
// Data packets are sent in pieces of this size, as cameras do.
constexpr size_t kDataChunkBytes = 64 * 1024;

// Little-endian PTP dataset builder.
class Writer {
 public:
  Writer& u8(uint8_t v) { return bytes(&v, 1); }
  Writer& u16(uint16_t v) { return le(v, 2); }
  Writer& u32(uint32_t v) { return le(v, 4); }
  Writer& u64(uint64_t v) { return le(v, 8); }
  // PTP string: length in UCS-2 characters including the terminator, then UCS-2LE.
  Writer& str(const std::string& s) {
    if (s.empty()) return u8(0);
    u8(static_cast<uint8_t>(s.size() + 1));
    for (unsigned char c : s) u16(c);
    return u16(0);
  }
  Writer& array16(const std::vector<uint16_t>& v) {
    u32(static_cast<uint32_t>(v.size()));
    for (uint16_t x : v) u16(x);
    return *this;
  }
  Writer& array32(const std::vector<uint32_t>& v) {
    u32(static_cast<uint32_t>(v.size()));
    for (uint32_t x : v) u32(x);
    return *this;
  }
  Writer& bytes(const void* p, size_t n) {
    data_.append(static_cast<const char*>(p), n);
    return *this;
  }
  const std::string& data() const { return data_; }

 private:
  Writer& le(uint64_t v, int n) {
    for (int i = 0; i < n; ++i) data_.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
    return *this;
  }
  std::string data_;
};

uint32_t le32(const std::string& b, size_t at) {
  if (at + 4 > b.size()) return 0;
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = v << 8 | static_cast<uint8_t>(b[at + i]);
  return v;
}
uint16_t le16(const std::string& b, size_t at) {
  if (at + 2 > b.size()) return 0;
  return static_cast<uint16_t>(static_cast<uint8_t>(b[at]) | static_cast<uint8_t>(b[at + 1]) << 8);
}

// A socket owned by the camera.
class Socket {
 public:
  Socket() = default;
  explicit Socket(int fd) : fd_(fd) {}
  ~Socket() { reset(); }
  Socket(Socket&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }
  Socket& operator=(Socket&& o) noexcept {
    if (this != &o) {
      reset();
      fd_ = o.fd_;
      o.fd_ = -1;
    }
    return *this;
  }
  int get() const { return fd_; }
  explicit operator bool() const { return fd_ >= 0; }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_ = -1;
};

// Waits until `fd` is readable (or writable); false on timeout or error.
bool waitFor(int fd, short events, double timeout_s) {
  pollfd p{fd, events, 0};
  int rc;
  do {
    rc = ::poll(&p, 1, static_cast<int>(timeout_s * 1000));
  } while (rc < 0 && errno == EINTR);
  return rc == 1;
}

struct Packet {
  uint32_t type = 0;
  std::string payload;
};

struct Request {
  uint32_t data_phase = 0;  // 1 = none or camera to host, 2 = host to camera
  uint16_t code = 0;
  uint32_t transaction = 0;
  std::vector<uint32_t> params;
  std::string data;  // what the host sent in its data phase
};

struct Object {
  uint16_t format = kFormatDng;
  std::string filename;
  std::string bytes;
  int width = 0, height = 0;
  std::string capture_date;  // "YYYYMMDDThhmmss"
};

// Properties with their enumerated choices, in the property's raw units.
struct Property {
  uint16_t code;
  uint16_t type;
  std::vector<uint32_t> choices;
  uint32_t value;
};

std::vector<uint32_t> rawChoices(const std::vector<double>& values, double scale) {
  std::vector<uint32_t> out;
  for (double v : values) out.push_back(static_cast<uint32_t>(std::lround(v * scale)));
  return out;
}

}  // namespace

const std::vector<double>& ptpIpCameraExposureTimes() {
  static const std::vector<double> times = {
      1.0 / 1000, 1.0 / 800, 1.0 / 640, 1.0 / 500, 1.0 / 400, 1.0 / 320, 1.0 / 250, 1.0 / 200,
      1.0 / 160,  1.0 / 125, 1.0 / 100, 1.0 / 80,  1.0 / 60,  1.0 / 50,  1.0 / 40,  1.0 / 30,
      1.0 / 25,   1.0 / 20,  1.0 / 15,  1.0 / 13,  1.0 / 10,  1.0 / 8,   1.0 / 6,   1.0 / 5,
      0.25,       0.3,       0.4,       0.5,       0.6,       0.8,       1,         1.3,
      1.6,        2,         2.5,       3.2,       4,         5,         6,         8,
      10,         13,        15,        20,        25,        30};
  return times;
}

const std::vector<int>& ptpIpCameraIsos() {
  static const std::vector<int> isos = {100,  125,  160,  200,  250,  320,  400,  500,  640,
                                        800,  1000, 1250, 1600, 2000, 2500, 3200, 4000, 5000,
                                        6400};
  return isos;
}

const std::vector<double>& ptpIpCameraFNumbers() {
  static const std::vector<double> f = {1.4, 2, 2.8, 4, 5.6, 8, 11, 16, 22};
  return f;
}

struct PtpIpCamera::Impl {
  FrameSource source;
  PtpIpCameraOptions options;
  Socket listener;
  int port = 0;
  fs::path scratch;  // where DNGs are written before they are served
  std::thread thread;
  std::atomic<bool> stop{false};

  mutable std::mutex mutex;  // guards faults, counters, properties, objects
  PtpIpFaults faults;
  PtpIpCameraCounters counters;
  std::map<uint16_t, Property> properties;
  std::map<uint32_t, Object> objects;
  uint32_t next_handle = 1;
  bool session_open = false;

  // ── socket I/O, each call bounded by options.io_timeout_s ───────────────────────────────
  bool readAll(int fd, void* buffer, size_t n) {
    char* p = static_cast<char*>(buffer);
    while (n > 0) {
      if (!waitFor(fd, POLLIN, options.io_timeout_s)) return false;
      const ssize_t r = ::recv(fd, p, n, 0);
      if (r <= 0) {
        if (r < 0 && errno == EINTR) continue;
        return false;
      }
      p += r;
      n -= static_cast<size_t>(r);
    }
    return true;
  }
  bool writeAll(int fd, const std::string& bytes) {
    size_t done = 0;
    while (done < bytes.size()) {
      if (!waitFor(fd, POLLOUT, options.io_timeout_s)) return false;
      const ssize_t w = ::send(fd, bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
      if (w <= 0) {
        if (w < 0 && errno == EINTR) continue;
        return false;
      }
      done += static_cast<size_t>(w);
    }
    return true;
  }
  std::optional<Packet> readPacket(int fd) {
    unsigned char header[8];
    if (!readAll(fd, header, sizeof header)) return std::nullopt;
    const std::string h(reinterpret_cast<char*>(header), sizeof header);
    const uint32_t length = le32(h, 0);
    if (length < 8 || length > kMaxRequestBytes) return std::nullopt;
    Packet p;
    p.type = le32(h, 4);
    p.payload.resize(length - 8);
    if (!p.payload.empty() && !readAll(fd, p.payload.data(), p.payload.size())) return std::nullopt;
    return p;
  }
  bool writePacket(int fd, uint32_t type, const std::string& payload) {
    Writer w;
    w.u32(static_cast<uint32_t>(payload.size() + 8)).u32(type).bytes(payload.data(), payload.size());
    return writeAll(fd, w.data());
  }
  bool respond(int fd, uint16_t code, uint32_t transaction, std::vector<uint32_t> params = {}) {
    Writer w;
    w.u16(code).u32(transaction);
    for (uint32_t p : params) w.u32(p);
    return writePacket(fd, kCommandResponse, w.data());
  }
  bool sendEvent(int fd, uint16_t code, uint32_t transaction, std::vector<uint32_t> params = {}) {
    Writer w;
    w.u16(code).u32(transaction);
    for (uint32_t p : params) w.u32(p);
    return writePacket(fd, kEvent, w.data());
  }
  // The data phase of a transaction: StartData with the total, Data pieces, EndData. With
  // `announce` > data.size() the transfer stops after `data` (the connection is then dropped).
  bool sendData(int fd, uint32_t transaction, const std::string& data, uint64_t announce) {
    Writer start;
    start.u32(transaction).u64(announce);
    if (!writePacket(fd, kStartData, start.data())) return false;
    size_t at = 0;
    do {
      const size_t n = std::min(kDataChunkBytes, data.size() - at);
      const bool last = at + n == data.size() && announce == data.size();
      Writer piece;
      piece.u32(transaction).bytes(data.data() + at, n);
      if (!writePacket(fd, last ? kEndData : kData, piece.data())) return false;
      at += n;
    } while (at < data.size());
    return true;
  }

  // ── datasets ────────────────────────────────────────────────────────────────────────────
  std::string deviceInfo() const {
    Writer w;
    w.u16(100).u32(0).u16(0).str("").u16(0);  // PTP 1.00, generic (no vendor extension)
    w.array16({kGetDeviceInfo, kOpenSession, kCloseSession, kGetStorageIds, kGetStorageInfo,
               kGetObjectHandles, kGetObjectInfo, kGetObject, kDeleteObject, kInitiateCapture,
               kGetDevicePropDesc, kGetDevicePropValue, kSetDevicePropValue});
    w.array16({kObjectAdded, kCaptureComplete});
    w.array16({kFNumber, kExposureTime, kExposureIndex});
    w.array16({kFormatDng});                // capture formats
    w.array16({kFormatDng, kFormatJpeg});  // image formats
    w.str(options.manufacturer).str(options.model).str("1.0").str("0001");
    return w.data();
  }
  static void value(Writer& w, uint16_t type, uint32_t v) {
    if (type == kUint16)
      w.u16(static_cast<uint16_t>(v));
    else
      w.u32(v);
  }
  static std::string propDesc(const Property& p) {
    Writer w;
    w.u16(p.code).u16(p.type).u8(1);  // get/set
    value(w, p.type, p.choices.front());
    value(w, p.type, p.value);
    w.u8(2).u16(static_cast<uint16_t>(p.choices.size()));  // enumeration form
    for (uint32_t c : p.choices) value(w, p.type, c);
    return w.data();
  }
  static std::string objectInfo(const Object& o) {
    Writer w;
    w.u32(kStorageId).u16(o.format).u16(0).u32(static_cast<uint32_t>(o.bytes.size()));
    w.u16(0).u32(0).u32(0).u32(0);  // no thumbnail
    w.u32(static_cast<uint32_t>(o.width)).u32(static_cast<uint32_t>(o.height)).u32(16);
    w.u32(0).u16(0).u32(0).u32(0);  // parent: the storage's root; no association
    w.str(o.filename).str(o.capture_date).str(o.capture_date).str("");
    return w.data();
  }
  static std::string storageInfo() {
    Writer w;
    w.u16(4).u16(2).u16(0);  // removable RAM, generic hierarchical, read-write
    w.u64(uint64_t{32} << 30).u64(uint64_t{31} << 30).u32(9999);
    w.str("SD").str("FLAREKIT");
    return w.data();
  }

  ExposureSettings settingsLocked() const {
    ExposureSettings s;
    s.exposure_s = properties.at(kExposureTime).value / 10000.0;
    s.iso = properties.at(kExposureIndex).value;
    s.f_number = properties.at(kFNumber).value / 100.0;
    return s;
  }

  // Takes a frame with the current settings and stores it as a new object.
  uint32_t takePicture(bool jpeg) {
    ExposureSettings settings;
    {
      std::lock_guard<std::mutex> lock(mutex);
      settings = settingsLocked();
    }
    RawFrame frame = source(settings);
    const std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    char date[32];
    std::strftime(date, sizeof date, "%Y%m%dT%H%M%S", &local);
    Object o;
    o.width = frame.data.cols;
    o.height = frame.data.rows;
    o.capture_date = date;
    uint32_t handle;
    {
      std::lock_guard<std::mutex> lock(mutex);
      handle = next_handle++;
    }
    char name[32];
    std::snprintf(name, sizeof name, "FK_%04u.%s", handle % 10000, jpeg ? "JPG" : "DNG");
    o.filename = name;
    if (jpeg) {
      cv::Mat eight;
      frame.data.convertTo(eight, CV_8U, 1.0 / 256);
      std::vector<uchar> buffer;
      cv::imencode(".jpg", eight, buffer);
      o.format = kFormatJpeg;
      o.bytes.assign(buffer.begin(), buffer.end());
    } else {
      DngMetadata meta;
      meta.model = options.model;
      meta.capture_time = now;
      meta.focal_length_mm = options.focal_length_mm;
      const fs::path file = scratch / name;
      writeDng(file, frame, meta);
      std::ifstream in(file, std::ios::binary);
      o.bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
      std::error_code ec;
      fs::remove(file, ec);
    }
    std::lock_guard<std::mutex> lock(mutex);
    objects[handle] = std::move(o);
    ++counters.captures;
    ++counters.objects_on_card;
    return handle;
  }

  // Takes one fault of a counted kind; true when it is to happen now.
  bool takeFault(int PtpIpFaults::*which) {
    std::lock_guard<std::mutex> lock(mutex);
    int& n = faults.*which;
    if (n == 0) return false;
    if (n > 0) --n;
    return true;
  }

  // ── one client ──────────────────────────────────────────────────────────────────────────
  // Serves one command + event connection pair until the client goes or a fault drops it.
  void serveClient(Socket command) {
    const auto hello = readPacket(command.get());
    if (!hello || hello->type != kInitCommandRequest) return;
    bool garbage;
    {
      std::lock_guard<std::mutex> lock(mutex);
      garbage = faults.garbage_handshake;
      ++counters.connections;
      session_open = false;
    }
    if (garbage) {
      writeAll(command.get(),
               "HTTP/1.1 400 Bad Request\r\nContent-Type: text/html\r\nContent-Length: 0\r\n\r\n");
      return;
    }
    Writer ack;
    ack.u32(1);  // connection number
    const unsigned char guid[16] = {'F', 'L', 'A', 'R', 'E', 'K', 'I', 'T', 0, 1, 2, 3, 4, 5, 6, 7};
    ack.bytes(guid, sizeof guid);
    for (unsigned char c : options.friendly_name) ack.u16(c);
    ack.u16(0).u32(0x00010000);  // protocol version 1.0
    if (!writePacket(command.get(), kInitCommandAck, ack.data())) return;
    if (!waitFor(listener.get(), POLLIN, options.io_timeout_s)) return;
    Socket events(::accept(listener.get(), nullptr, nullptr));
    if (!events) return;
    const auto event_hello = readPacket(events.get());
    if (!event_hello || event_hello->type != kInitEventRequest) return;
    if (!writePacket(events.get(), kInitEventAck, "")) return;

    while (!stop) {
      if (!waitFor(command.get(), POLLIN, 0.1)) {
        pollfd p{command.get(), POLLIN, 0};
        if (::poll(&p, 1, 0) == 1 && (p.revents & (POLLHUP | POLLERR))) return;
        continue;
      }
      const auto packet = readPacket(command.get());
      if (!packet) return;  // the client went away
      if (packet->type != kCommandRequest || packet->payload.size() < 10) continue;
      Request r;
      r.data_phase = le32(packet->payload, 0);
      r.code = le16(packet->payload, 4);
      r.transaction = le32(packet->payload, 6);
      for (size_t at = 10; at + 4 <= packet->payload.size(); at += 4)
        r.params.push_back(le32(packet->payload, at));
      if (r.data_phase == 2) {
        const auto start = readPacket(command.get());
        if (!start || start->type != kStartData) return;
        for (;;) {
          const auto piece = readPacket(command.get());
          if (!piece || (piece->type != kData && piece->type != kEndData)) return;
          r.data.append(piece->payload, std::min<size_t>(4, piece->payload.size()), std::string::npos);
          if (piece->type == kEndData) break;
        }
      }
      if (!handle(command.get(), events.get(), r)) return;
    }
  }

  uint32_t param(const Request& r, size_t i) const { return i < r.params.size() ? r.params[i] : 0; }

  // Answers one operation; false when the connection is to be dropped.
  bool handle(int cmd, int evt, const Request& r) {
    const uint32_t t = r.transaction;
    switch (r.code) {
      case kGetDeviceInfo: {
        const std::string info = deviceInfo();
        return sendData(cmd, t, info, info.size()) && respond(cmd, kOk, t);
      }
      case kOpenSession: {
        std::lock_guard<std::mutex> lock(mutex);
        session_open = true;
        return respond(cmd, kOk, t);
      }
      case kCloseSession: {
        std::lock_guard<std::mutex> lock(mutex);
        session_open = false;
        return respond(cmd, kOk, t);
      }
      default:
        break;
    }
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (!session_open) return respond(cmd, kSessionNotOpen, t);
    }
    switch (r.code) {
      case kGetStorageIds: {
        Writer w;
        w.array32({kStorageId});
        return sendData(cmd, t, w.data(), w.data().size()) && respond(cmd, kOk, t);
      }
      case kGetStorageInfo: {
        if (param(r, 0) != kStorageId) return respond(cmd, kInvalidStorageId, t);
        const std::string info = storageInfo();
        return sendData(cmd, t, info, info.size()) && respond(cmd, kOk, t);
      }
      case kGetObjectHandles: {
        const uint32_t storage = param(r, 0), parent = param(r, 2);
        std::vector<uint32_t> handles;
        {
          std::lock_guard<std::mutex> lock(mutex);
          if (storage == kStorageId || storage == 0xffffffff)
            if (parent == 0 || parent == 0xffffffff)
              for (const auto& [h, o] : objects) handles.push_back(h);
        }
        Writer w;
        w.array32(handles);
        return sendData(cmd, t, w.data(), w.data().size()) && respond(cmd, kOk, t);
      }
      case kGetObjectInfo: {
        std::string info;
        {
          std::lock_guard<std::mutex> lock(mutex);
          const auto it = objects.find(param(r, 0));
          if (it == objects.end()) return respond(cmd, kInvalidObjectHandle, t);
          info = objectInfo(it->second);
        }
        return sendData(cmd, t, info, info.size()) && respond(cmd, kOk, t);
      }
      case kGetObject: {
        std::string bytes;
        {
          std::lock_guard<std::mutex> lock(mutex);
          const auto it = objects.find(param(r, 0));
          if (it == objects.end()) return respond(cmd, kInvalidObjectHandle, t);
          bytes = it->second.bytes;
        }
        if (takeFault(&PtpIpFaults::downloads_dropped)) {
          sendData(cmd, t, bytes.substr(0, bytes.size() / 2), bytes.size());
          return false;
        }
        if (takeFault(&PtpIpFaults::objects_truncated)) bytes.resize(bytes.size() / 2);
        if (!sendData(cmd, t, bytes, bytes.size()) || !respond(cmd, kOk, t)) return false;
        std::lock_guard<std::mutex> lock(mutex);
        ++counters.downloads;
        return true;
      }
      case kDeleteObject: {
        std::lock_guard<std::mutex> lock(mutex);
        if (!objects.erase(param(r, 0))) return respond(cmd, kInvalidObjectHandle, t);
        ++counters.deletes;
        --counters.objects_on_card;
        return respond(cmd, kOk, t);
      }
      case kInitiateCapture: {
        if (takeFault(&PtpIpFaults::busy_captures)) return respond(cmd, kDeviceBusy, t);
        if (!respond(cmd, kOk, t)) return false;
        if (takeFault(&PtpIpFaults::captures_never_completing)) return true;
        bool jpeg;
        {
          std::lock_guard<std::mutex> lock(mutex);
          jpeg = faults.jpeg_objects;
        }
        uint32_t handle;
        try {
          handle = takePicture(jpeg);
        } catch (const std::exception&) {
          return sendEvent(evt, kCaptureComplete, t);  // a camera that failed to save
        }
        return sendEvent(evt, kObjectAdded, t, {handle}) && sendEvent(evt, kCaptureComplete, t);
      }
      case kGetDevicePropDesc:
      case kGetDevicePropValue: {
        std::string data;
        {
          std::lock_guard<std::mutex> lock(mutex);
          const auto it = properties.find(static_cast<uint16_t>(param(r, 0)));
          if (it == properties.end()) return respond(cmd, kDevicePropNotSupported, t);
          if (r.code == kGetDevicePropDesc) {
            data = propDesc(it->second);
          } else {
            Writer w;
            value(w, it->second.type, it->second.value);
            data = w.data();
          }
        }
        return sendData(cmd, t, data, data.size()) && respond(cmd, kOk, t);
      }
      case kSetDevicePropValue: {
        if (takeFault(&PtpIpFaults::property_sets_refused))
          return respond(cmd, kInvalidDevicePropValue, t);
        std::lock_guard<std::mutex> lock(mutex);
        const auto it = properties.find(static_cast<uint16_t>(param(r, 0)));
        if (it == properties.end()) return respond(cmd, kDevicePropNotSupported, t);
        Property& p = it->second;
        const uint32_t v = p.type == kUint16 ? le16(r.data, 0) : le32(r.data, 0);
        if (r.data.size() != (p.type == kUint16 ? 2u : 4u) ||
            std::find(p.choices.begin(), p.choices.end(), v) == p.choices.end())
          return respond(cmd, kInvalidDevicePropValue, t);
        p.value = v;
        return respond(cmd, kOk, t);
      }
      default:
        return respond(cmd, kOperationNotSupported, t);
    }
  }

  void serve() {
    while (!stop) {
      if (!waitFor(listener.get(), POLLIN, 0.1)) continue;
      Socket command(::accept(listener.get(), nullptr, nullptr));
      if (!command) continue;
      try {
        serveClient(std::move(command));
      } catch (const std::exception&) {
        // A camera that fails drops the connection; the client sees it and reconnects.
      }
    }
  }
};

PtpIpCamera::PtpIpCamera(FrameSource source, PtpIpCameraOptions options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.source = std::move(source);
  m.options = std::move(options);
  m.properties[kExposureTime] = {kExposureTime, kUint32, rawChoices(ptpIpCameraExposureTimes(), 1e4),
                                 80};  // 1/125 s
  std::vector<double> isos(ptpIpCameraIsos().begin(), ptpIpCameraIsos().end());
  m.properties[kExposureIndex] = {kExposureIndex, kUint16, rawChoices(isos, 1), 100};
  m.properties[kFNumber] = {kFNumber, kUint16, rawChoices(ptpIpCameraFNumbers(), 100), 800};

  m.listener = Socket(::socket(AF_INET, SOCK_STREAM, 0));
  if (!m.listener) throw RuntimeError("PTP/IP test camera: cannot create a socket");
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  address.sin_port = 0;  // any free port
  socklen_t length = sizeof address;
  if (::bind(m.listener.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0 ||
      ::listen(m.listener.get(), 4) != 0 ||
      ::getsockname(m.listener.get(), reinterpret_cast<sockaddr*>(&address), &length) != 0)
    throw RuntimeError("PTP/IP test camera: cannot listen on 127.0.0.1");
  m.port = ntohs(address.sin_port);
  m.scratch = fs::temp_directory_path() /
              ("flarekit-ptpip-" + std::to_string(::getpid()) + "-" + std::to_string(m.port));
  fs::create_directories(m.scratch);
  m.thread = std::thread([&m] { m.serve(); });
}

PtpIpCamera::~PtpIpCamera() {
  impl_->stop = true;
  if (impl_->thread.joinable()) impl_->thread.join();
  std::error_code ec;
  fs::remove_all(impl_->scratch, ec);
}

int PtpIpCamera::port() const { return impl_->port; }

std::string PtpIpCamera::gphoto2Port() const {
  return "ptpip:127.0.0.1:" + std::to_string(impl_->port);
}

void PtpIpCamera::setFaults(const PtpIpFaults& faults) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->faults = faults;
}

PtpIpFaults PtpIpCamera::faults() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->faults;
}

PtpIpCameraCounters PtpIpCamera::counters() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->counters;
}

ExposureSettings PtpIpCamera::settings() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->settingsLocked();
}

}  // namespace flarekit::testing
