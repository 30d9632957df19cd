#include "acquisition/raw_decode.h"

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include <libraw/libraw.h>
#include <opencv2/imgcodecs.hpp>

#include "common/error.h"
#include "common/input_file.h"

namespace flarekit::acquisition {
namespace {

// Owner of a LibRaw processor (large: kept on the heap); recycle() frees its buffers.
struct LibRawDeleter {
  void operator()(LibRaw* p) const {
    p->recycle();
    delete p;
  }
};
using LibRawPtr = std::unique_ptr<LibRaw, LibRawDeleter>;

Cfa cfaFromLibRaw(LibRaw& raw) {
  char pattern[5] = {};
  for (int i = 0; i < 4; ++i) {
    const int c = raw.COLOR(i / 2, i % 2);
    pattern[i] = c == 0 ? 'R' : (c == 2 ? 'B' : 'G');
  }
  Cfa cfa;
  if (!parseCfa(pattern, &cfa) || cfa == Cfa::kMono) return Cfa::kMono;
  return cfa;
}

}  // namespace

RawFrame decodeRawBuffer(const void* data, size_t size, const std::string& name) {
  LibRawPtr raw(new LibRaw(LIBRAW_OPTIONS_NONE));
  raw->imgdata.params.adjust_maximum_thr = 0.0f;  // keep the real white level
  int rc = raw->open_buffer(const_cast<void*>(data), size);
  if (rc != LIBRAW_SUCCESS)
    throw InputError(name, std::string("not a RAW file LibRaw can read (") + libraw_strerror(rc) + ")");
  rc = raw->unpack();
  if (rc != LIBRAW_SUCCESS)
    throw InputError(name, std::string("cannot decode the RAW data (") + libraw_strerror(rc) + ")");
  const auto& sizes = raw->imgdata.sizes;
  const auto& rd = raw->imgdata.rawdata;
  const bool mono = raw->imgdata.idata.colors == 1 || raw->imgdata.idata.filters == 0;
  if (!rd.raw_image || (raw->imgdata.idata.filters == 0 && raw->imgdata.idata.colors != 1))
    throw InputError(name, "not a single-channel mosaic RAW (already demosaiced or unsupported "
                           "layout); give the camera's own RAW file");
  if (raw->imgdata.idata.filters != 0 && raw->imgdata.idata.filters < 1000)
    throw InputError(name, "non-Bayer colour filter (X-Trans or similar) is not supported");
  const int rows = sizes.height, cols = sizes.width;
  RawFrame f;
  f.cfa = mono ? Cfa::kMono : cfaFromLibRaw(*raw);
  f.data.create(rows, cols, CV_16UC1);
  const auto& color = raw->imgdata.color;
  // Per-channel black (cblack[0..3]) plus a repeating pattern (cblack[4] × cblack[5] values from
  // cblack[6]); fold the part above the smallest channel black into the data.
  unsigned base_black = color.black;
  unsigned channel_black[4];
  for (int c = 0; c < 4; ++c) channel_black[c] = color.cblack[c];
  const unsigned min_channel = *std::min_element(channel_black, channel_black + 4);
  const unsigned pat_rows = color.cblack[4], pat_cols = color.cblack[5];
  const size_t pitch = rd.sizes.raw_pitch / 2;
  for (int y = 0; y < rows; ++y) {
    const uint16_t* src = rd.raw_image + static_cast<size_t>(y + sizes.top_margin) * pitch + sizes.left_margin;
    uint16_t* dst = f.data.ptr<uint16_t>(y);
    for (int x = 0; x < cols; ++x) {
      unsigned extra = channel_black[mono ? 0 : raw->COLOR(y, x)] - min_channel;
      if (pat_rows && pat_cols && pat_rows * pat_cols <= LIBRAW_CBLACK_SIZE - 6)
        extra += color.cblack[6 + (y % pat_rows) * pat_cols + (x % pat_cols)];
      dst[x] = static_cast<uint16_t>(src[x] > extra ? src[x] - extra : 0);
    }
  }
  f.black_level = base_black + min_channel;
  f.white_level = color.maximum > 0 ? color.maximum : 65535;
  if (!(f.white_level > f.black_level))
    throw InputError(name, "white level " + std::to_string(f.white_level) +
                               " is not above the black level " + std::to_string(f.black_level));
  f.exposure_s = raw->imgdata.other.shutter;
  f.iso = raw->imgdata.other.iso_speed;
  f.f_number = raw->imgdata.other.aperture;
  f.focal_length_mm = raw->imgdata.other.focal_len;
  f.capture_time = static_cast<int64_t>(raw->imgdata.other.timestamp);
  f.camera = std::string(raw->imgdata.idata.make) + " " + raw->imgdata.idata.model;
  return f;
}

RawFrame decodeRawFile(const std::filesystem::path& path) {
  const std::string bytes = readInputFile(path, kMaxRawFileBytes);
  if (bytes.empty()) throw InputError(path.string(), "the file is empty");
  return decodeRawBuffer(bytes.data(), bytes.size(), path.string());
}

bool isLinearImageFile(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".tif" || ext == ".tiff" || ext == ".png";
}

namespace {

// OpenCV's imread tries every decoder it has (DICOM, GDAL, …) on what it does not recognize; only
// PNG and TIFF hold linear 16-bit frames, so other content is refused before it reaches them. A
// PNG's header size is held to what zlib (at most about 1032:1) can have packed into the file.
void checkPngOrTiff(const std::filesystem::path& path, const std::string& bytes) {
  static const std::string png("\x89PNG\r\n\x1a\n", 8);
  const std::string head = bytes.substr(0, 8);
  if (head.rfind(png, 0) == 0) {
    if (bytes.size() < 24) throw InputError(path.string(), "truncated PNG header");
    auto be32 = [&](size_t at) {
      return std::uint32_t(std::uint8_t(bytes[at])) << 24 | std::uint32_t(std::uint8_t(bytes[at + 1])) << 16 |
             std::uint32_t(std::uint8_t(bytes[at + 2])) << 8 | std::uint32_t(std::uint8_t(bytes[at + 3]));
    };
    const double pixels = double(be32(16)) * double(be32(20));
    if (pixels * 8 > double(bytes.size()) * 1032)  // 8 bytes: the widest PNG pixel (16-bit RGBA)
      throw InputError(path.string(), "corrupt PNG header: " + std::to_string(be32(16)) + " x " +
                                          std::to_string(be32(20)) + " pixels cannot fit in a file of " +
                                          std::to_string(bytes.size()) + " bytes");
    return;
  }
  for (const char* tiff : {"II*\0", "MM\0*", "II+\0", "MM\0+"})
    if (head.compare(0, 4, std::string(tiff, 4)) == 0) return;
  throw InputError(path.string(), "not a PNG or TIFF file");
}

}  // namespace

RawFrame loadLinearImage(const std::filesystem::path& path, double exposure_s, double black_level,
                         double white_level, Cfa cfa) {
  const std::string bytes = readInputFile(path, kMaxRawFileBytes);
  checkPngOrTiff(path, bytes);
  cv::Mat m = cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data())),
                           cv::IMREAD_UNCHANGED);
  if (m.empty()) throw InputError(path.string(), "not an image OpenCV can read");
  if (m.depth() != CV_16U)
    throw InputError(path.string(), "must hold 16-bit linear values (this one is " +
                                        std::string(m.depth() == CV_8U ? "8-bit" : "not 16-bit") +
                                        "); 8-bit images are gamma-encoded and cannot be merged");
  if (m.channels() != 1)
    throw InputError(path.string(), "must have one channel of photosite values (this one has " +
                                        std::to_string(m.channels()) + ")");
  RawFrame f;
  f.data = m;
  f.cfa = cfa;
  f.black_level = black_level;
  f.white_level = white_level;
  f.exposure_s = exposure_s;
  return f;
}

}  // namespace flarekit::acquisition
