#pragma once
// Test helper (not part of the library): writes small DNG files with libtiff, so that LibRaw
// decoding and `flarekit merge` are tested on real RAW files without shipping any.

#include <tiffio.h>

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>

namespace flarekit::testing {

struct DngSpec {
  bool bayer = true;        // RGGB CFA, else a monochrome LinearRaw DNG (LibRaw 0.20 rejects it)
  double exposure_s = 1.0;  // EXIF ExposureTime
  double f_number = 8;      // EXIF FNumber
  int iso = 100;            // EXIF ISOSpeedRatings
  int black_level = 256;
  int white_level = 16383;
  std::string model = "FlareKit Test Camera";
};

// Writes `raw` (CV_16UC1 photosite values) as an uncompressed DNG 1.4.
inline void writeDng(const std::filesystem::path& path, const cv::Mat& raw, const DngSpec& spec) {
  TIFF* tif = TIFFOpen(path.c_str(), "w");
  if (!tif) throw std::runtime_error("cannot create " + path.string());
  const uint8_t dng_version[4] = {1, 4, 0, 0};
  TIFFSetField(tif, TIFFTAG_SUBFILETYPE, 0);
  TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, raw.cols);
  TIFFSetField(tif, TIFFTAG_IMAGELENGTH, raw.rows);
  TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 16);
  TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
  TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_NONE);
  TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, raw.rows);
  TIFFSetField(tif, TIFFTAG_MAKE, "FlareKit");
  TIFFSetField(tif, TIFFTAG_MODEL, spec.model.c_str());
  TIFFSetField(tif, TIFFTAG_DNGVERSION, dng_version);
  TIFFSetField(tif, TIFFTAG_UNIQUECAMERAMODEL, spec.model.c_str());
  if (spec.bayer) {
    const uint16_t dim[2] = {2, 2};
    const uint8_t pattern[4] = {0, 1, 1, 2};  // R G / G B
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_CFA);
    TIFFSetField(tif, TIFFTAG_CFAREPEATPATTERNDIM, dim);
    TIFFSetField(tif, TIFFTAG_CFAPATTERN, 4, pattern);
  } else {
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, 34892);  // LinearRaw
  }
  const float black = static_cast<float>(spec.black_level);
  TIFFSetField(tif, TIFFTAG_BLACKLEVEL, 1, &black);
  const uint32_t white = static_cast<uint32_t>(spec.white_level);
  TIFFSetField(tif, TIFFTAG_WHITELEVEL, 1, &white);
  const float matrix[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  TIFFSetField(tif, TIFFTAG_COLORMATRIX1, spec.bayer ? 9 : 3, matrix);
  const uint16_t iso = static_cast<uint16_t>(spec.iso);
  TIFFSetField(tif, TIFFTAG_EXIFIFD, uint64_t{0});  // patched below
  for (int y = 0; y < raw.rows; ++y)
    if (TIFFWriteScanline(tif, const_cast<uint16_t*>(raw.ptr<uint16_t>(y)), y, 0) < 0) {
      TIFFClose(tif);
      throw std::runtime_error("cannot write " + path.string());
    }
  TIFFWriteDirectory(tif);
  // EXIF IFD with the exposure (where readers look for ISO), then point the main IFD at it.
  TIFFCreateEXIFDirectory(tif);
  TIFFSetField(tif, EXIFTAG_EXPOSURETIME, spec.exposure_s);
  TIFFSetField(tif, EXIFTAG_FNUMBER, spec.f_number);
  const uint16_t iso_array[1] = {iso};
  TIFFSetField(tif, EXIFTAG_ISOSPEEDRATINGS, 1, iso_array);
  uint64_t exif_offset = 0;
  TIFFWriteCustomDirectory(tif, &exif_offset);
  TIFFSetDirectory(tif, 0);
  TIFFSetField(tif, TIFFTAG_EXIFIFD, exif_offset);
  TIFFRewriteDirectory(tif);
  TIFFClose(tif);
}

}  // namespace flarekit::testing
