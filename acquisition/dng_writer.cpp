#include "acquisition/dng_writer.h"

#include <tiffio.h>

#include <cmath>
#include <cstdint>
#include <ctime>

#include "common/atomic_file.h"

namespace flarekit::acquisition {

namespace {

// "YYYY:MM:DD HH:MM:SS" in local time, the TIFF/EXIF date format.
std::string exifDateTime(int64_t unix_s) {
  const std::time_t t = static_cast<std::time_t>(unix_s);
  std::tm local{};
  localtime_r(&t, &local);
  char text[32];
  std::strftime(text, sizeof text, "%Y:%m:%d %H:%M:%S", &local);
  return text;
}

}  // namespace

void writeDng(const std::filesystem::path& path, const RawFrame& frame, const std::string& model) {
  DngMetadata meta;
  meta.model = model;
  writeDng(path, frame, meta);
}

void writeDng(const std::filesystem::path& path, const RawFrame& frame, const DngMetadata& meta) {
  const std::string& model = meta.model;
  const int64_t taken = meta.capture_time   ? meta.capture_time
                        : frame.capture_time ? frame.capture_time
                                             : static_cast<int64_t>(std::time(nullptr));
  const std::string date = exifDateTime(taken);
  const double focal_mm = meta.focal_length_mm > 0 ? meta.focal_length_mm : frame.focal_length_mm;
  if (frame.cfa == Cfa::kMono)
    throw InputError(path.string(), "monochrome frames are not written as DNG (use PNG)");
  if (frame.data.type() != CV_16UC1 || frame.data.empty())
    throw InputError(path.string(), "DNG needs 16-bit single-channel photosite data");
  writeFileAtomically(path, [&](const std::filesystem::path& tmp) {
    TIFF* tif = TIFFOpen(tmp.c_str(), "w");
    if (!tif) throw RuntimeError(tmp.string() + ": cannot create the DNG file");
    const uint8_t dng_version[4] = {1, 4, 0, 0};
    TIFFSetField(tif, TIFFTAG_SUBFILETYPE, 0);
    TIFFSetField(tif, TIFFTAG_IMAGEWIDTH, frame.data.cols);
    TIFFSetField(tif, TIFFTAG_IMAGELENGTH, frame.data.rows);
    TIFFSetField(tif, TIFFTAG_BITSPERSAMPLE, 16);
    TIFFSetField(tif, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(tif, TIFFTAG_COMPRESSION, COMPRESSION_NONE);
    TIFFSetField(tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(tif, TIFFTAG_ROWSPERSTRIP, frame.data.rows);
    TIFFSetField(tif, TIFFTAG_MAKE, "FlareKit");
    TIFFSetField(tif, TIFFTAG_MODEL, model.c_str());
    TIFFSetField(tif, TIFFTAG_DNGVERSION, dng_version);
    TIFFSetField(tif, TIFFTAG_UNIQUECAMERAMODEL, model.c_str());
    TIFFSetField(tif, TIFFTAG_DATETIME, date.c_str());
    const uint16_t dim[2] = {2, 2};
    // CFAPattern colours: 0 red, 1 green, 2 blue, for the 2×2 block read row by row.
    uint8_t pattern[4];
    for (int i = 0; i < 4; ++i) pattern[i] = static_cast<uint8_t>(cfaColor(frame.cfa, i / 2, i % 2));
    TIFFSetField(tif, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_CFA);
    TIFFSetField(tif, TIFFTAG_CFAREPEATPATTERNDIM, dim);
    TIFFSetField(tif, TIFFTAG_CFAPATTERN, 4, pattern);
    const float black = static_cast<float>(frame.black_level);
    TIFFSetField(tif, TIFFTAG_BLACKLEVEL, 1, &black);
    const uint32_t white = static_cast<uint32_t>(std::lround(frame.white_level));
    TIFFSetField(tif, TIFFTAG_WHITELEVEL, 1, &white);
    const float identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
    TIFFSetField(tif, TIFFTAG_COLORMATRIX1, 9, identity);
    TIFFSetField(tif, TIFFTAG_EXIFIFD, uint64_t{0});  // patched once the EXIF IFD is written
    bool ok = true;
    for (int y = 0; y < frame.data.rows && ok; ++y)
      ok = TIFFWriteScanline(tif, const_cast<uint16_t*>(frame.data.ptr<uint16_t>(y)),
                             static_cast<uint32_t>(y), 0) >= 0;
    ok = ok && TIFFWriteDirectory(tif);
    // EXIF IFD with the exposure, then point the main IFD at it.
    uint64_t exif_offset = 0;
    if (ok) {
      TIFFCreateEXIFDirectory(tif);
      if (frame.exposure_s > 0) TIFFSetField(tif, EXIFTAG_EXPOSURETIME, frame.exposure_s);
      if (frame.f_number > 0) TIFFSetField(tif, EXIFTAG_FNUMBER, frame.f_number);
      const uint16_t iso[1] = {static_cast<uint16_t>(std::lround(std::max(frame.iso, 0.0)))};
      if (frame.iso > 0) TIFFSetField(tif, EXIFTAG_ISOSPEEDRATINGS, 1, iso);
      if (focal_mm > 0) TIFFSetField(tif, EXIFTAG_FOCALLENGTH, focal_mm);
      TIFFSetField(tif, EXIFTAG_DATETIMEORIGINAL, date.c_str());
      ok = TIFFWriteCustomDirectory(tif, &exif_offset) != 0;
    }
    ok = ok && TIFFSetDirectory(tif, 0) && TIFFSetField(tif, TIFFTAG_EXIFIFD, exif_offset) &&
         TIFFRewriteDirectory(tif);
    TIFFClose(tif);
    if (!ok) throw RuntimeError(tmp.string() + ": writing the DNG file failed");
  });
}

}  // namespace flarekit::acquisition
