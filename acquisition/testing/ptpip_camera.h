#pragma once
// A PTP/IP camera for tests (CIPA DC-005 over TCP, as libgphoto2's ptp2 driver speaks it through
// its `ptpip:HOST:PORT` port): the command and event connections, a session, GetDeviceInfo, the
// standard device properties a tethered capture sets (ExposureTime 0x500D, ExposureIndex 0x500F,
// FNumber 0x5007, each with an enumerated list of choices as a real camera reports them),
// InitiateCapture answered by ObjectAdded and CaptureComplete events, GetObjectInfo, GetObject
// and DeleteObject. Every captured object is a DNG (acquisition/dng_writer.h) of the frame a
// FrameSource returns for the current settings, so downloads carry real photosites and EXIF.
//
// It speaks the generic PTP profile (VendorExtensionID 0): libgphoto2 then names the settings
// `shutterspeed`, `iso` and `f-number`, and has no `imageformat` for it.
//
// Faults (PtpIpFaults) make it misbehave as tethered cameras do, so that the gphoto2 backend's
// watchdog, retries and error messages can be tested without hardware.
//
// Threading: one server thread serves one client at a time (a reconnecting client is served
// once its previous connection is gone). The public methods may be called from any thread.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "acquisition/device.h"

namespace flarekit::testing {

using acquisition::RawFrame;

// What the camera is set to when it takes a frame.
struct ExposureSettings {
  double exposure_s = 0;
  double iso = 0;
  double f_number = 0;
};
// Takes one frame (Bayer CV_16UC1, with its levels) at the given settings.
using FrameSource = std::function<RawFrame(const ExposureSettings&)>;

struct PtpIpCameraOptions {
  std::string manufacturer = "FlareKit";           // DeviceInfo Manufacturer
  std::string model = "FlareKit PTP/IP test camera";  // DeviceInfo Model (also the DNG's)
  std::string friendly_name = "flarekit-test";     // name in the PTP/IP handshake
  double focal_length_mm = 0;  // written to each DNG's EXIF (0 = not written)
  // Socket timeout of the camera's own reads and writes, seconds (default 10): a client that
  // stops talking mid-packet is dropped after it.
  double io_timeout_s = 10;
};

// Misbehaviour, each counted down as it happens; -1 = for ever, 0 = never (the defaults).
struct PtpIpFaults {
  int captures_never_completing = 0;   // InitiateCapture answered OK, then no events at all
  int downloads_dropped = 0;           // GetObject: half the data, then both connections closed
  int busy_captures = 0;               // InitiateCapture answered DeviceBusy (0x2019)
  int property_sets_refused = 0;       // SetDevicePropValue answered InvalidDevicePropValue
  int objects_truncated = 0;           // GetObject delivers half of what GetObjectInfo announced
  bool garbage_handshake = false;      // answers the PTP/IP init request with an HTTP error page
  bool jpeg_objects = false;           // captures JPEG files instead of RAW
};

// What the camera saw, for tests to check.
struct PtpIpCameraCounters {
  int connections = 0;      // command connections accepted
  int captures = 0;         // objects created by InitiateCapture
  int downloads = 0;        // complete GetObject transfers
  int deletes = 0;          // objects deleted
  int objects_on_card = 0;  // objects created and not deleted
};

class PtpIpCamera {
 public:
  // Listens on 127.0.0.1 at a free port (see port()) and serves from a thread until destroyed.
  // RuntimeError when no socket can be opened.
  PtpIpCamera(FrameSource source, PtpIpCameraOptions options = {});
  ~PtpIpCamera();
  PtpIpCamera(const PtpIpCamera&) = delete;
  PtpIpCamera& operator=(const PtpIpCamera&) = delete;

  int port() const;
  // "ptpip:127.0.0.1:PORT", the gphoto2 port of this camera.
  std::string gphoto2Port() const;

  void setFaults(const PtpIpFaults& faults);
  PtpIpFaults faults() const;
  PtpIpCameraCounters counters() const;
  // The settings the camera holds now.
  ExposureSettings settings() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The exposure times (s) and ISOs the camera offers, a third of a stop apart (1/1000 s to 30 s,
// ISO 100 to 6400), and its f-numbers, a stop apart (f/1.4 to f/22).
const std::vector<double>& ptpIpCameraExposureTimes();
const std::vector<int>& ptpIpCameraIsos();
const std::vector<double>& ptpIpCameraFNumbers();

}  // namespace flarekit::testing
