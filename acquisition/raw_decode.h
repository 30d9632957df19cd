#pragma once
// Decoding RAW files to linear photosite values (LibRaw), and reading linear 16-bit TIFF/PNG
// frames, for the HDR merge.

#include <cstddef>
#include <filesystem>
#include <string>

#include "acquisition/device.h"

namespace flarekit::acquisition {

// Decodes a camera RAW file (CR2, CR3, NEF, ARW, DNG, ...) held in memory, as gphoto2 delivers
// it. Returns the visible area's photosites (no scaling, no demosaicing), the Bayer layout, the
// black level (per-channel black offsets folded into the data so that one level applies), the
// white level (LibRaw's maximum with adjust_maximum_thr = 0) and the EXIF exposure time, ISO,
// f-number, focal length and capture time. `name` is used in messages. InputError when LibRaw cannot read it or when it is not a
// single-channel mosaic (e.g. an already demosaiced linear DNG).
RawFrame decodeRawBuffer(const void* data, size_t size, const std::string& name);
RawFrame decodeRawFile(const std::filesystem::path& path);

// True when the extension names a linear image format read by loadLinearImage (.tif, .tiff,
// .png), else the file is handed to LibRaw.
bool isLinearImageFile(const std::filesystem::path& path);

// Reads a single-channel 16-bit TIFF or PNG holding linear photosite values. The caller supplies
// what the file cannot say: exposure time, black and white levels, colour filter layout.
RawFrame loadLinearImage(const std::filesystem::path& path, double exposure_s, double black_level,
                         double white_level, Cfa cfa);

}  // namespace flarekit::acquisition
