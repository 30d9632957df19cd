#include "acquisition/gphoto2_camera.h"

#include <gphoto2/gphoto2.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "acquisition/raw_decode.h"
#include "common/log.h"

namespace flarekit::acquisition {
namespace {

struct ContextDeleter {
  void operator()(GPContext* c) const { gp_context_unref(c); }
};
struct CameraDeleter {
  void operator()(::Camera* c) const { gp_camera_unref(c); }  // also exits it
};
struct FileDeleter {
  void operator()(CameraFile* f) const { gp_file_unref(f); }
};
struct WidgetDeleter {
  void operator()(CameraWidget* w) const { gp_widget_free(w); }
};
struct ListDeleter {
  void operator()(CameraList* l) const { gp_list_free(l); }
};
struct AbilitiesListDeleter {
  void operator()(CameraAbilitiesList* l) const { gp_abilities_list_free(l); }
};
struct PortInfoListDeleter {
  void operator()(GPPortInfoList* l) const { gp_port_info_list_free(l); }
};
// Owners of the gphoto2 handles.
using ContextPtr = std::unique_ptr<GPContext, ContextDeleter>;
using CameraPtr = std::unique_ptr<::Camera, CameraDeleter>;
using FilePtr = std::unique_ptr<CameraFile, FileDeleter>;
using WidgetPtr = std::unique_ptr<CameraWidget, WidgetDeleter>;
using ListPtr = std::unique_ptr<CameraList, ListDeleter>;
using AbilitiesListPtr = std::unique_ptr<CameraAbilitiesList, AbilitiesListDeleter>;
using PortInfoListPtr = std::unique_ptr<GPPortInfoList, PortInfoListDeleter>;

bool transient(int rc) {
  return rc == GP_ERROR_CAMERA_BUSY || rc == GP_ERROR_TIMEOUT || rc == GP_ERROR_IO ||
         rc == GP_ERROR_IO_READ || rc == GP_ERROR_IO_WRITE || rc == GP_ERROR_IO_USB_CLEAR_HALT;
}

bool isNetworkPort(const std::string& port) { return port.rfind("ptpip:", 0) == 0; }

// libgphoto2's PTP/IP port writes to its sockets with write(2): a camera that drops the
// connection would end the process with SIGPIPE instead of failing the write. Ignored (unless
// the program set its own handler) once a network camera is opened.
void ignoreSigpipe() {
  struct sigaction current {};
  if (sigaction(SIGPIPE, nullptr, &current) == 0 && current.sa_handler == SIG_DFL)
    signal(SIGPIPE, SIG_IGN);
}

// libgphoto2 2.5.30's PTP/IP driver closes fd 0 whenever it disconnects (its unused `jpgfd`
// is 0, not -1), taking stdin or whatever socket or file has that number by then. Held across
// the calls that may disconnect (init, exit, unref), it puts fd 0 back as it was.
class FdZeroGuard {
 public:
  FdZeroGuard() : saved_(::dup(0)) {}
  ~FdZeroGuard() {
    if (saved_ < 0) return;
    ::dup2(saved_, 0);
    ::close(saved_);
  }
  FdZeroGuard(const FdZeroGuard&) = delete;
  FdZeroGuard& operator=(const FdZeroGuard&) = delete;

 private:
  int saved_;
};

// The port path libgphoto2 is given for a rig's port. Its PTP/IP driver (2.5.30) connects the
// event channel to 15740 unless the path names an event port after the command port
// ("ptpip:HOST:PORT:EVENTPORT"); PTP/IP puts both on one port, so that port is repeated.
std::string gphoto2PortPath(const std::string& port) {
  if (!isNetworkPort(port)) return port;
  const auto colons = std::count(port.begin(), port.end(), ':');
  return colons == 2 ? port + port.substr(port.rfind(':')) : port;
}

// libgphoto2's own name for a camera on a PTP/IP port without a model in the rig file.
constexpr const char* kGenericPtpIpModel = "PTP/IP Camera";

ListPtr autodetect(GPContext* ctx) {
  CameraList* list = nullptr;
  if (gp_list_new(&list) < GP_OK) throw DeviceError("gphoto2: cannot allocate a list", false);
  ListPtr owner(list);
  const int rc = gp_camera_autodetect(list, ctx);
  if (rc < GP_OK)
    throw DeviceError(std::string("gphoto2: detecting cameras failed (") + gp_result_as_string(rc) + ")",
                      transient(rc));
  return owner;
}

// The driver abilities of `model`, loaded once per process (loading every camera driver takes
// a while, and a reconnect needs them again). False when libgphoto2 knows no such model.
bool abilitiesFor(const std::string& model, GPContext* ctx, CameraAbilities* out) {
  static std::mutex mutex;
  static std::map<std::string, CameraAbilities> known;
  std::lock_guard<std::mutex> lock(mutex);
  const auto it = known.find(model);
  if (it != known.end()) {
    *out = it->second;
    return true;
  }
  CameraAbilitiesList* raw = nullptr;
  if (gp_abilities_list_new(&raw) < GP_OK) return false;
  AbilitiesListPtr list(raw);
  if (gp_abilities_list_load(raw, ctx) < GP_OK) return false;
  const int index = gp_abilities_list_lookup_model(raw, model.c_str());
  if (index < 0 || gp_abilities_list_get_abilities(raw, index, out) < GP_OK) return false;
  known[model] = *out;
  return true;
}

// One connection to a camera: its context (collecting libgphoto2's error messages) and handle.
struct Connection {
  std::string model;  // as libgphoto2 names it
  std::string port;   // resolved port path
  ContextPtr ctx;
  CameraPtr camera;
  std::string errors;  // what libgphoto2 reported through the context since clearErrors()

  std::string name() const { return model + " on " + port; }
  void clearErrors() { errors.clear(); }

  [[noreturn]] void fail(int rc, const std::string& what, bool is_transient,
                         const std::string& hint = "") const {
    std::string message = "camera " + name() + ": " + what + " failed (" + gp_result_as_string(rc);
    if (!errors.empty()) message += ": " + errors;
    message += ")";
    if (rc == GP_ERROR_IO_USB_CLAIM)
      message += ": another program holds the camera (gvfs-gphoto2-volume-monitor?)";
    else if (!hint.empty())
      message += ": " + hint;
    throw DeviceError(message, is_transient);
  }
  void check(int rc, const std::string& what, const std::string& hint = "") const {
    if (rc < GP_OK) fail(rc, what, transient(rc), hint);
  }

  static void onError(GPContext*, const char* text, void* data) {
    auto* self = static_cast<Connection*>(data);
    if (!self->errors.empty()) self->errors += "; ";
    self->errors += text;
  }

  // Finds the camera (autodetection for USB; the port as given for PTP/IP, which autodetection
  // cannot list) and opens it. InputError for a model or port libgphoto2 does not know.
  void open(const Gphoto2Config& config) {
    close();
    ctx.reset(gp_context_new());
    gp_context_set_error_func(ctx.get(), &Connection::onError, this);
    if (isNetworkPort(config.port)) {
      ignoreSigpipe();
      model = config.model.empty() ? kGenericPtpIpModel : config.model;
      port = config.port;
    } else {
      ListPtr list = autodetect(ctx.get());
      const int count = gp_list_count(list.get());
      model.clear();
      for (int i = 0; i < count; ++i) {
        const char* name = nullptr;
        const char* value = nullptr;
        gp_list_get_name(list.get(), i, &name);
        gp_list_get_value(list.get(), i, &value);
        if ((!config.model.empty() && config.model != name) ||
            (!config.port.empty() && config.port != value))
          continue;
        model = name;
        port = value;
        break;
      }
      if (model.empty())
        throw DeviceError(std::string(count ? "the configured camera" : "no camera") +
                              " found by gphoto2: connect it by USB, switch it on, and check "
                              "camera.model/camera.port (`gphoto2 --auto-detect`)",
                          false);
    }
    CameraAbilities abilities;
    if (!abilitiesFor(model, ctx.get(), &abilities))
      throw InputError("camera.model: libgphoto2 has no camera named \"" + model +
                       "\" (`gphoto2 --list-cameras`; for PTP/IP \"" + kGenericPtpIpModel + "\")");
    GPPortInfoList* raw_ports = nullptr;
    if (gp_port_info_list_new(&raw_ports) < GP_OK)
      throw DeviceError("gphoto2: cannot list ports", false);
    PortInfoListPtr ports(raw_ports);
    gp_port_info_list_load(raw_ports);
    const std::string path = gphoto2PortPath(port);
    const int p = gp_port_info_list_lookup_path(raw_ports, path.c_str());
    GPPortInfo info;
    if (p < 0 || gp_port_info_list_get_info(raw_ports, p, &info) < GP_OK)
      throw InputError("camera.port: libgphoto2 has no port \"" + port + "\" (`gphoto2 --list-ports`)");
    ::Camera* cam = nullptr;
    check(gp_camera_new(&cam), "creating the camera");
    camera.reset(cam);
    check(gp_camera_set_abilities(cam, abilities), "choosing the driver");
    check(gp_camera_set_port_info(cam, info), "choosing the port");
    clearErrors();
    FdZeroGuard fd_zero;
    const int rc = gp_camera_init(cam, ctx.get());
    if (rc < GP_OK) {
      camera.reset();
      // PTP/IP: an I/O error is a refused or timed-out connection; other errors mean that what
      // answered did not complete the PTP/IP handshake and session.
      const bool nothing_there = rc == GP_ERROR_IO || rc == GP_ERROR_TIMEOUT;
      fail(rc, "connecting", true,
           !isNetworkPort(port) ? "check the cable and that the camera is on and awake"
           : nothing_there
               ? "nothing answers there as a PTP/IP camera: check that the camera is on, in its "
                 "PC-connection (Wi-Fi/LAN remote) mode and at that address, and camera.port"
               : "what answers there is not a PTP/IP camera (another service on that port?): "
                 "check camera.port");
    }
  }

  void close() {
    FdZeroGuard fd_zero;
    if (camera) gp_camera_exit(camera.get(), ctx.get());
    camera.reset();
  }

  // The camera's own model name (PTP DeviceInfo), from the driver's summary; "" if none.
  std::string deviceModel() {
    CameraText text;
    if (gp_camera_get_summary(camera.get(), &text, ctx.get()) < GP_OK) return "";
    std::istringstream lines(text.text);
    std::string line;
    while (std::getline(lines, line))
      if (line.rfind("Model:", 0) == 0) {
        const auto start = line.find_first_not_of(' ', 6);
        return start == std::string::npos ? "" : line.substr(start);
      }
    return "";
  }
};

std::vector<std::string> widgetChoices(CameraWidget* w) {
  std::vector<std::string> out;
  const int n = gp_widget_count_choices(w);
  for (int i = 0; i < n; ++i) {
    const char* c = nullptr;
    if (gp_widget_get_choice(w, i, &c) == GP_OK && c) out.emplace_back(c);
  }
  return out;
}

double parseNumber(const std::string& s) {
  const auto digit = s.find_first_of("0123456789.");
  return digit == std::string::npos ? 0 : std::strtod(s.c_str() + digit, nullptr);
}

}  // namespace

double parseShutterSpeed(const std::string& text) {
  std::string t = text;
  while (!t.empty() && (t.back() == '"' || t.back() == 's')) t.pop_back();
  const auto slash = t.find('/');
  char* end = nullptr;
  if (slash != std::string::npos) {
    const double num = std::strtod(t.substr(0, slash).c_str(), &end);
    const double den = std::strtod(t.substr(slash + 1).c_str(), &end);
    return den > 0 ? num / den : 0;
  }
  const double v = std::strtod(t.c_str(), &end);
  return end && end != t.c_str() ? v : 0;
}

std::string nearestShutterSpeed(const std::vector<std::string>& choices, double exposure_s) {
  std::string best;
  double best_err = 1e300;
  for (const auto& c : choices) {
    const double v = parseShutterSpeed(c);
    if (!(v > 0)) continue;
    const double err = std::abs(std::log(v / exposure_s));
    if (err < best_err) {
      best_err = err;
      best = c;
    }
  }
  return best;
}

struct Gphoto2Camera::Impl {
  Gphoto2Config config;
  Connection link;
  std::string device_model;  // the camera's own model name, for frames and logs
  double exposure_s = 0;     // the shutter speed last set, seconds
  bool warned_no_image_format = false;

  void open() {
    link.open(config);
    device_model = link.deviceModel();
    setImageFormat();
  }
  void ensureOpen() {
    if (!link.camera) open();
  }

  // The first of `names` the camera has (drivers name one setting differently per vendor:
  // `aperture` for Canon and Nikon, `f-number` for generic PTP and Sony). Null when none.
  WidgetPtr findWidget(const std::vector<std::string>& names, std::string* found) {
    for (const auto& name : names) {
      CameraWidget* w = nullptr;
      link.clearErrors();
      const int rc = gp_camera_get_single_config(link.camera.get(), name.c_str(), &w, link.ctx.get());
      if (rc >= GP_OK && w) {
        *found = name;
        return WidgetPtr(w);
      }
      if (transient(rc)) link.fail(rc, "reading setting " + name, true);
    }
    return nullptr;
  }

  void setWidget(const std::string& name, CameraWidget* w, const std::string& value) {
    if (gp_widget_set_value(w, value.c_str()) < GP_OK)
      throw DeviceError("camera " + link.name() + ": setting " + name + " to " + value +
                            " is not possible", false);
    link.clearErrors();
    const int rc = gp_camera_set_single_config(link.camera.get(), name.c_str(), w, link.ctx.get());
    // libgphoto2 2.5.30 reports a refused SetDevicePropValue (busy, not allowed in this mode) as
    // "not found": a refused set is retried, and the message says what the camera answered.
    if (rc < GP_OK)
      link.fail(rc, "setting " + name + " to " + value, true,
                "is the camera in M mode, and is the value allowed there?");
  }

  void setImageFormat() {
    if (config.imageformat.empty()) return;
    std::string name;
    WidgetPtr w = findWidget({"imageformat", "imagequality"}, &name);
    if (!w) {
      if (!warned_no_image_format)  // once, not at every reconnect
        logWarning("camera " + link.name() + " has no image format setting: set it to save RAW "
                   "only yourself (frames that are not RAW stop the capture)");
      warned_no_image_format = true;
      return;
    }
    const auto choices = widgetChoices(w.get());
    bool offered = false;
    std::string list;
    for (const auto& c : choices) {
      offered = offered || c == config.imageformat;
      list += (list.empty() ? "" : ", ") + ("\"" + c + "\"");
    }
    if (!offered)
      throw DeviceError("camera " + link.name() + ": its " + name + " setting offers " + list +
                            ", not \"" + config.imageformat +
                            "\": set camera.imageformat in the rig file to the RAW-only one",
                        false);
    setWidget(name, w.get(), config.imageformat);
  }

  // Sets a numeric setting to the choice nearest `value` (log scale); returns the value set.
  double setNearest(const std::vector<std::string>& names, double value,
                    double (*parse)(const std::string&)) {
    ensureOpen();
    std::string name;
    WidgetPtr w = findWidget(names, &name);
    if (!w)
      throw DeviceError("camera " + link.name() + " has no " + names.front() +
                            " setting: is it in M mode with a lens that reports its aperture?",
                        false);
    std::string best;
    double best_value = 0, best_err = 1e300;
    for (const auto& c : widgetChoices(w.get())) {
      const double v = parse(c);
      if (!(v > 0)) continue;
      const double err = std::abs(std::log(v / value));
      if (err < best_err) {
        best_err = err;
        best = c;
        best_value = v;
      }
    }
    if (best.empty())
      throw DeviceError("camera " + link.name() + " offers no usable " + name + " values", false);
    if (best_err > 0.1)
      logWarning("camera: " + name + " " + std::to_string(value) + " is not offered; using " + best);
    setWidget(name, w.get(), best);
    return best_value;
  }

  // Reads events until none is pending (left from an earlier capture), at most 100.
  void drainEvents() {
    for (int i = 0; i < 100; ++i) {
      CameraEventType type = GP_EVENT_TIMEOUT;
      void* data = nullptr;
      // 10 ms, not 0: a USB port takes a timeout of 0 as "wait for ever".
      const int rc = gp_camera_wait_for_event(link.camera.get(), 10, &type, &data, link.ctx.get());
      std::free(data);
      if (rc < GP_OK) link.fail(rc, "reading the camera's events", true);
      if (type == GP_EVENT_TIMEOUT) return;
    }
  }

  // Triggers a capture and waits for the file it adds: the watchdog gives up after the exposure
  // plus config.capture_timeout_s (libgphoto2's gp_camera_capture would wait for ever on a
  // PTP camera that never reports the new object).
  CameraFilePath triggerAndWait() {
    using Clock = std::chrono::steady_clock;
    drainEvents();
    // A camera still saving the last frame answers DeviceBusy: asked again every 0.1 s for up to
    // capture_timeout_s before the session's retry (which reconnects) takes over.
    const auto busy_until = Clock::now() + std::chrono::duration<double>(config.capture_timeout_s);
    int rc;
    for (;;) {
      link.clearErrors();
      rc = gp_camera_trigger_capture(link.camera.get(), link.ctx.get());
      if (rc != GP_ERROR_CAMERA_BUSY || Clock::now() >= busy_until) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    if (rc < GP_OK)
      link.fail(rc, "triggering the capture", true,
                rc == GP_ERROR_CAMERA_BUSY ? "the camera stayed busy" : "");
    const double limit_s = exposure_s + config.capture_timeout_s;
    const auto deadline = Clock::now() + std::chrono::duration<double>(limit_s);
    for (;;) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      if (left.count() <= 0)
        throw DeviceError("camera " + link.name() + ": the capture did not complete within " +
                              std::to_string(static_cast<int>(std::ceil(limit_s))) +
                              " s (no new file reported); reconnecting (camera.capture_timeout_s)",
                          true);
      CameraEventType type = GP_EVENT_TIMEOUT;
      void* data = nullptr;
      const int wait_rc = gp_camera_wait_for_event(
          link.camera.get(), static_cast<int>(std::min<long long>(left.count(), 1000)), &type,
          &data, link.ctx.get());
      if (wait_rc < GP_OK) {
        std::free(data);
        link.fail(wait_rc, "waiting for the capture", true);
      }
      if (type == GP_EVENT_FILE_ADDED && data) {
        const CameraFilePath path = *static_cast<CameraFilePath*>(data);
        std::free(data);
        return path;
      }
      std::free(data);
    }
  }

  RawFrame download(const CameraFilePath& path) {
    const std::string file = std::string(path.folder) + "/" + path.name;
    // The size the camera announced (PTP ObjectInfo), to check the download against; drivers
    // that cannot say (virtual files of some vendors) skip the check.
    CameraFileInfo info{};
    if (gp_camera_file_get_info(link.camera.get(), path.folder, path.name, &info,
                                link.ctx.get()) < GP_OK)
      info.file.fields = GP_FILE_INFO_NONE;
    CameraFile* raw_file = nullptr;
    link.check(gp_file_new(&raw_file), "allocating a file");
    FilePtr owner(raw_file);
    link.clearErrors();
    const int rc = gp_camera_file_get(link.camera.get(), path.folder, path.name,
                                      GP_FILE_TYPE_NORMAL, raw_file, link.ctx.get());
    if (rc < GP_OK) link.fail(rc, "downloading " + file, true);
    const char* data = nullptr;
    unsigned long size = 0;
    link.check(gp_file_get_data_and_size(raw_file, &data, &size), "reading the downloaded file");
    auto remove = [&] {
      // Keep the card clean; a failed delete is not worth failing the frame for.
      if (gp_camera_file_delete(link.camera.get(), path.folder, path.name, link.ctx.get()) < GP_OK)
        logWarning("camera " + link.name() + ": could not delete " + file);
    };
    // libgphoto2 hands over whatever GetObject delivered: a short transfer is caught here.
    if ((info.file.fields & GP_FILE_INFO_SIZE) && size != info.file.size) {
      remove();
      throw DeviceError("camera " + link.name() + ": downloaded " + std::to_string(size) + " of " +
                            std::to_string(info.file.size) + " bytes of " + file + " (truncated)",
                        true);
    }
    RawFrame frame;
    try {
      frame = decodeRawBuffer(data, size, file);
    } catch (const InputError& e) {
      remove();
      throw DeviceError("camera " + link.name() + ": " + path.name +
                            " is not a RAW file (" + e.what() +
                            "): set the camera to save RAW only (rig camera.imageformat)",
                        false);
    }
    remove();
    return frame;
  }
};

Gphoto2Camera::Gphoto2Camera(const Gphoto2Config& config) : impl_(std::make_unique<Impl>()) {
  impl_->config = config;
  impl_->open();
}
Gphoto2Camera::~Gphoto2Camera() {
  if (impl_) impl_->link.close();
}
Gphoto2Camera::Gphoto2Camera(Gphoto2Camera&&) noexcept = default;
Gphoto2Camera& Gphoto2Camera::operator=(Gphoto2Camera&&) noexcept = default;

std::string Gphoto2Camera::describe() const {
  const Impl& m = *impl_;
  std::string d = m.device_model.empty() ? m.link.model : m.device_model;
  return d + " (gphoto2, " + m.link.port + ")";
}

void Gphoto2Camera::setExposure(double exposure_s) {
  impl_->exposure_s = impl_->setNearest({"shutterspeed"}, exposure_s,
                                        [](const std::string& s) { return parseShutterSpeed(s); });
}
void Gphoto2Camera::setIso(double iso) {
  impl_->setNearest({"iso"}, iso, [](const std::string& s) { return std::strtod(s.c_str(), nullptr); });
}
void Gphoto2Camera::setAperture(double f_number) {
  impl_->setNearest({"aperture", "f-number"}, f_number, parseNumber);
}

RawFrame Gphoto2Camera::capture() {
  Impl& m = *impl_;
  m.ensureOpen();
  const CameraFilePath path = m.triggerAndWait();
  RawFrame frame = m.download(path);
  if (frame.camera.find_first_not_of(' ') == std::string::npos)
    frame.camera = m.device_model.empty() ? m.link.model : m.device_model;
  return frame;
}

RawFrame Gphoto2Camera::captureDark() {
  throw InputError(
      "dark frames with a gphoto2 camera: the program cannot block the light; capture them "
      "yourself with the lens cap on (same exposures) and pass them to flarekit merge --dark, or "
      "capture without --dark-frames (the black level is subtracted)");
}

void Gphoto2Camera::reconnect() {
  impl_->link.close();
  impl_->open();
}

bool probeGphoto2(const Gphoto2Config& config, std::vector<std::string>* lines) {
  if (isNetworkPort(config.port)) {
    // Autodetection does not list network cameras: open the port as given.
    Connection link;
    try {
      link.open(config);
    } catch (const DeviceError& e) {
      lines->push_back(std::string("MISSING: ") + e.what());
      return false;
    }
    const std::string model = link.deviceModel();
    lines->push_back("found camera " + link.model + " on " + link.port +
                     (model.empty() ? "" : " (" + model + ")") + " (used)");
    link.close();
    return true;
  }
  ContextPtr ctx(gp_context_new());
  ListPtr list = autodetect(ctx.get());
  const int count = gp_list_count(list.get());
  bool found = false;
  for (int i = 0; i < count; ++i) {
    const char* name = nullptr;
    const char* value = nullptr;
    gp_list_get_name(list.get(), i, &name);
    gp_list_get_value(list.get(), i, &value);
    const bool match = (config.model.empty() || config.model == name) &&
                       (config.port.empty() || config.port == value);
    lines->push_back(std::string("found camera ") + name + " on " + value +
                     (match && !found ? " (used)" : ""));
    found = found || match;
  }
  if (!found)
    lines->push_back("MISSING: " + std::string(config.model.empty() ? "no camera" : config.model) +
                     " detected by gphoto2: connect it by USB, switch it on, and close programs "
                     "that grab it (file managers)");
  return found;
}

}  // namespace flarekit::acquisition
