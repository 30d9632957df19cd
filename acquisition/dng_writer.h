#pragma once
// Writes RAW frames as DNG 1.4 (libtiff): uncompressed CFA data with its black and white levels
// and the exposure time, f-number, ISO, focal length and capture time in an EXIF IFD, so that any RAW tool and
// `flarekit merge` (through LibRaw) read them back with their metadata. Used for --keep-raw of
// Bayer captures and by the tests. Monochrome frames cannot be written as DNG that LibRaw 0.20
// reads back (it rejects single-channel LinearRaw DNGs): InputError for Cfa::kMono.

#include <cstdint>
#include <filesystem>
#include <string>

#include "acquisition/device.h"

namespace flarekit::acquisition {

// What a DNG records beside the photosites and the frame's own exposure, ISO and f-number.
struct DngMetadata {
  std::string model = "FlareKit";  // camera model (TIFF Model and UniqueCameraModel)
  // When the frame was taken, Unix seconds, written as local time (TIFF DateTime, EXIF
  // DateTimeOriginal) as cameras do; 0 = the frame's capture_time, or now when that is 0 too.
  int64_t capture_time = 0;
  // Lens focal length in mm (EXIF FocalLength); 0 = the frame's focal_length_mm (not written
  // when that is 0 too).
  double focal_length_mm = 0;
};

// Writes `frame` (CV_16UC1 photosites, Bayer layout) atomically.
void writeDng(const std::filesystem::path& path, const RawFrame& frame, const DngMetadata& meta);
// The same with only the camera model given.
void writeDng(const std::filesystem::path& path, const RawFrame& frame,
              const std::string& model = "FlareKit");

}  // namespace flarekit::acquisition
