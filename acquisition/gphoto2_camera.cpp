#include "acquisition/gphoto2_camera.h"

#include <gphoto2/gphoto2.h>

#include <cmath>
#include <cstdlib>
#include <sstream>

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
// Owners of the gphoto2 handles.
using ContextPtr = std::unique_ptr<GPContext, ContextDeleter>;
using CameraPtr = std::unique_ptr<::Camera, CameraDeleter>;
using FilePtr = std::unique_ptr<CameraFile, FileDeleter>;
using WidgetPtr = std::unique_ptr<CameraWidget, WidgetDeleter>;
using ListPtr = std::unique_ptr<CameraList, ListDeleter>;

bool transient(int rc) {
  return rc == GP_ERROR_CAMERA_BUSY || rc == GP_ERROR_TIMEOUT || rc == GP_ERROR_IO ||
         rc == GP_ERROR_IO_READ || rc == GP_ERROR_IO_WRITE || rc == GP_ERROR_IO_USB_CLEAR_HALT;
}

void check(int rc, const std::string& what) {
  if (rc < GP_OK)
    throw DeviceError("camera: " + what + " failed (" + gp_result_as_string(rc) + ")" +
                          (rc == GP_ERROR_IO_USB_CLAIM
                               ? ": another program holds the camera (gvfs-gphoto2-volume-monitor?)"
                               : ""),
                      transient(rc));
}

ListPtr autodetect(GPContext* ctx) {
  CameraList* list = nullptr;
  check(gp_list_new(&list), "listing cameras");
  ListPtr owner(list);
  check(gp_camera_autodetect(list, ctx), "detecting cameras");
  return owner;
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
  ContextPtr ctx;
  CameraPtr camera;
  std::string model;

  void open() {
    ctx.reset(gp_context_new());
    ListPtr list = autodetect(ctx.get());
    const int count = gp_list_count(list.get());
    std::string port;
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
    ::Camera* cam = nullptr;
    check(gp_camera_new(&cam), "creating the camera");
    camera.reset(cam);
    CameraAbilitiesList* abilities = nullptr;
    GPPortInfoList* ports = nullptr;
    check(gp_abilities_list_new(&abilities), "loading camera drivers");
    gp_abilities_list_load(abilities, ctx.get());
    CameraAbilities a;
    const int idx = gp_abilities_list_lookup_model(abilities, model.c_str());
    if (idx >= 0 && gp_abilities_list_get_abilities(abilities, idx, &a) == GP_OK)
      gp_camera_set_abilities(cam, a);
    gp_abilities_list_free(abilities);
    check(gp_port_info_list_new(&ports), "listing ports");
    gp_port_info_list_load(ports);
    const int p = gp_port_info_list_lookup_path(ports, port.c_str());
    GPPortInfo info;
    if (p >= 0 && gp_port_info_list_get_info(ports, p, &info) == GP_OK) gp_camera_set_port_info(cam, info);
    gp_port_info_list_free(ports);
    check(gp_camera_init(cam, ctx.get()), "connecting to " + model);
    setText("imageformat", config.imageformat);
  }

  WidgetPtr widget(const std::string& name, CameraWidget** w) {
    check(gp_camera_get_single_config(camera.get(), name.c_str(), w, ctx.get()),
          "reading setting " + name);
    return WidgetPtr(*w);
  }

  std::vector<std::string> choices(CameraWidget* w) {
    std::vector<std::string> out;
    const int n = gp_widget_count_choices(w);
    for (int i = 0; i < n; ++i) {
      const char* c = nullptr;
      if (gp_widget_get_choice(w, i, &c) == GP_OK && c) out.emplace_back(c);
    }
    return out;
  }

  void setText(const std::string& name, const std::string& value) {
    CameraWidget* w = nullptr;
    WidgetPtr owner = widget(name, &w);
    check(gp_widget_set_value(w, value.c_str()), "setting " + name + " to " + value);
    check(gp_camera_set_single_config(camera.get(), name.c_str(), w, ctx.get()),
          "setting " + name + " to " + value + " (is the camera in M mode?)");
  }

  // Sets a numeric setting to the choice nearest `value` (log scale); returns the text used.
  std::string setNearest(const std::string& name, double value,
                         double (*parse)(const std::string&)) {
    CameraWidget* w = nullptr;
    WidgetPtr owner = widget(name, &w);
    std::string best;
    double best_err = 1e300;
    for (const auto& c : choices(w)) {
      const double v = parse(c);
      if (!(v > 0)) continue;
      const double err = std::abs(std::log(v / value));
      if (err < best_err) {
        best_err = err;
        best = c;
      }
    }
    if (best.empty())
      throw DeviceError("camera " + model + " offers no usable " + name + " values", false);
    if (best_err > 0.1)
      logWarning("camera: " + name + " " + std::to_string(value) + " is not offered; using " + best);
    check(gp_widget_set_value(w, best.c_str()), "setting " + name);
    check(gp_camera_set_single_config(camera.get(), name.c_str(), w, ctx.get()),
          "setting " + name + " to " + best);
    return best;
  }
};

Gphoto2Camera::Gphoto2Camera(const Gphoto2Config& config) : impl_(std::make_unique<Impl>()) {
  impl_->config = config;
  impl_->open();
}
Gphoto2Camera::~Gphoto2Camera() {
  if (impl_ && impl_->camera) gp_camera_exit(impl_->camera.get(), impl_->ctx.get());
}
Gphoto2Camera::Gphoto2Camera(Gphoto2Camera&&) noexcept = default;
Gphoto2Camera& Gphoto2Camera::operator=(Gphoto2Camera&&) noexcept = default;

std::string Gphoto2Camera::describe() const { return impl_->model + " (gphoto2)"; }

void Gphoto2Camera::setExposure(double exposure_s) {
  impl_->setNearest("shutterspeed", exposure_s,
                    [](const std::string& s) { return parseShutterSpeed(s); });
}
void Gphoto2Camera::setIso(double iso) {
  impl_->setNearest("iso", iso, [](const std::string& s) { return std::strtod(s.c_str(), nullptr); });
}
void Gphoto2Camera::setAperture(double f_number) {
  impl_->setNearest("aperture", f_number, [](const std::string& s) {
    const std::string t = !s.empty() && (s[0] == 'f' || s[0] == 'F') ? s.substr(s.find_first_of("0123456789")) : s;
    return std::strtod(t.c_str(), nullptr);
  });
}

RawFrame Gphoto2Camera::capture() {
  Impl& m = *impl_;
  CameraFilePath path;
  check(gp_camera_capture(m.camera.get(), GP_CAPTURE_IMAGE, &path, m.ctx.get()), "capture");
  CameraFile* file = nullptr;
  check(gp_file_new(&file), "allocating a file");
  FilePtr owner(file);
  check(gp_camera_file_get(m.camera.get(), path.folder, path.name, GP_FILE_TYPE_NORMAL, file,
                           m.ctx.get()),
        std::string("downloading ") + path.name);
  const char* data = nullptr;
  unsigned long size = 0;
  check(gp_file_get_data_and_size(file, &data, &size), "reading the downloaded file");
  RawFrame frame = decodeRawBuffer(data, size, path.name);
  // Keep the card/RAM clean; a failed delete is not worth failing the frame for.
  if (gp_camera_file_delete(m.camera.get(), path.folder, path.name, m.ctx.get()) < GP_OK)
    logWarning(std::string("camera: could not delete ") + path.folder + "/" + path.name);
  frame.camera = m.model;
  return frame;
}

RawFrame Gphoto2Camera::captureDark() {
  throw InputError(
      "dark frames with a gphoto2 camera: the program cannot block the light; capture them "
      "yourself with the lens cap on (same exposures) and pass them to flarekit merge --dark, or "
      "capture without --dark-frames (the black level is subtracted)");
}

void Gphoto2Camera::reconnect() {
  impl_->camera.reset();
  impl_->open();
}

bool probeGphoto2(const Gphoto2Config& config, std::vector<std::string>* lines) {
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
