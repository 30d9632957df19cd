#pragma once
// Writes RAW frames as DNG 1.4 (libtiff): uncompressed CFA data with its black and white levels
// and the exposure time, f-number and ISO in an EXIF IFD, so that any RAW tool and
// `flarekit merge` (through LibRaw) read them back with their metadata. Used for --keep-raw of
// Bayer captures and by the tests. Monochrome frames cannot be written as DNG that LibRaw 0.20
// reads back (it rejects single-channel LinearRaw DNGs): InputError for Cfa::kMono.

#include <filesystem>
#include <string>

#include "acquisition/device.h"

namespace flarekit::acquisition {

// Writes `frame` (CV_16UC1 photosites, Bayer layout) atomically. `model` names the camera.
void writeDng(const std::filesystem::path& path, const RawFrame& frame,
              const std::string& model = "FlareKit");

}  // namespace flarekit::acquisition
