#include "common/exr_header_check.h"

#include <algorithm>
#include <cstdint>
#include <fstream>
#include <limits>
#include <map>
#include <string>

#include "common/error.h"
#include "common/exr.h"

namespace flarekit::detail {
namespace {

// Attribute types OpenEXR 3 reads with a fixed number of bytes, whatever size the file declares.
const std::map<std::string, int>& fixedSizes() {
  static const std::map<std::string, int> sizes = {
      {"box2i", 16},   {"box2f", 16},   {"chromaticities", 32}, {"compression", 1}, {"deepImageState", 1},
      {"double", 8},   {"envmap", 1},   {"float", 4},           {"int", 4},         {"keycode", 28},
      {"lineOrder", 1}, {"m33f", 36},   {"m33d", 72},           {"m44f", 64},       {"m44d", 128},
      {"rational", 8}, {"tiledesc", 9}, {"timecode", 8},        {"v2i", 8},         {"v2f", 8},
      {"v2d", 16},     {"v3i", 12},     {"v3f", 12},            {"v3d", 24}};
  return sizes;
}

// A name from a damaged header, fit for a one-line message.
std::string printable(const std::string& name) {
  std::string out;
  for (char c : name.substr(0, 40)) out += (c >= 0x20 && c < 0x7f) ? c : '?';
  return name.size() > 40 ? out + "..." : out;
}

class HeaderReader {
 public:
  HeaderReader(const std::filesystem::path& path, std::uintmax_t file_bytes)
      : path_(path), in_(path, std::ios::binary), file_bytes_(static_cast<std::int64_t>(file_bytes)) {}

  bool ok() const { return static_cast<bool>(in_); }
  std::int64_t left() { return file_bytes_ - static_cast<std::int64_t>(in_.tellg()); }

  // A NUL-terminated name as OpenEXR reads it (at most 255 characters before the NUL).
  bool text(std::string& out) {
    out.clear();
    for (char c; in_.get(c);) {
      if (c == '\0') return true;
      if (out.size() == 255) return false;
      out += c;
    }
    return false;
  }
  bool int32(std::int64_t& out) {
    unsigned char b[4];
    if (!in_.read(reinterpret_cast<char*>(b), 4)) return false;
    out = static_cast<std::int32_t>(std::uint32_t(b[0]) | std::uint32_t(b[1]) << 8 |
                                    std::uint32_t(b[2]) << 16 | std::uint32_t(b[3]) << 24);
    return true;
  }
  // Skips `bytes` after checking that the file holds them.
  void skip(std::int64_t bytes, const std::string& what) {
    if (bytes < 0 || bytes > left())
      throw InputError(path_.string(), "truncated or corrupt header: " + what + " claims " +
                                           std::to_string(bytes) + " bytes, more than the file holds");
    in_.seekg(bytes, std::ios::cur);
  }

 private:
  const std::filesystem::path& path_;
  std::ifstream in_;
  std::int64_t file_bytes_;
};

}  // namespace

void checkExrHeaderSizes(const std::filesystem::path& path, std::uintmax_t file_bytes) {
  HeaderReader r(path, file_bytes);
  r.skip(4, "the magic number");
  std::int64_t flags = 0;
  if (!r.int32(flags)) return;
  const bool multipart = (flags & 0x1000) != 0;
  for (;;) {  // headers: one, or until an empty one in a multi-part file
    int attributes = 0;
    std::int64_t pixel_bytes = 0, width = 0, height = 0;
    for (std::string name, type;; ++attributes) {
      if (!r.text(name)) return;
      if (name.empty()) break;
      std::int64_t size = 0;
      if (!r.text(type) || !r.int32(size)) return;
      const std::string what = "attribute '" + printable(name) + "'";
      if (name == "dataWindow" && type == "box2i") {
        std::int64_t min_x = 0, min_y = 0, max_x = 0, max_y = 0;
        if (!r.int32(min_x) || !r.int32(min_y) || !r.int32(max_x) || !r.int32(max_y)) return;
        width = max_x - min_x + 1;
        height = max_y - min_y + 1;
      } else if (const auto fixed = fixedSizes().find(type); fixed != fixedSizes().end()) {
        r.skip(fixed->second, what);
      } else if (type == "chlist") {  // channel records until an empty name; the size is not used
        for (std::string channel; r.text(channel) && !channel.empty();) {
          std::int64_t pixel_type = 0;
          if (!r.int32(pixel_type)) return;
          pixel_bytes += pixel_type == 1 ? 2 : 4;  // HALF, else UINT or FLOAT
          r.skip(12, what);
        }
      } else if (type == "preview") {  // width, height, then 4 bytes per pixel
        std::int64_t width = 0, height = 0;
        if (!r.int32(width) || !r.int32(height)) return;
        // OpenEXR reads both as unsigned: up to (2³² − 1)² pixels, which only unsigned 64 bits hold.
        const std::uint64_t pixels = std::uint64_t(std::uint32_t(width)) * std::uint32_t(height);
        const std::uint64_t most = std::numeric_limits<std::int64_t>::max() / 4;
        r.skip(static_cast<std::int64_t>(std::min(pixels, most) * 4), what + "'s preview");
      } else if (type == "stringvector") {  // length-prefixed strings filling `size`
        for (std::int64_t read = 0; read < size;) {
          std::int64_t length = 0;
          if (!r.int32(length)) return;
          r.skip(length, what + "'s string");
          read += 4 + length;
        }
      } else if (type == "floatvector") {  // as many whole floats as `size` holds
        r.skip(size / 4 * 4, what);
      } else {  // string, idmanifest and types OpenEXR does not know: `size` bytes
        r.skip(size, what);
      }
      if (!r.ok()) return;
    }
    if (double(width) * double(height) * double(pixel_bytes) > double(file_bytes) * kMaxExrCompressionRatio)
      throw InputError(path.string(), "corrupt header: its data window (" + std::to_string(width) + " x " +
                                          std::to_string(height) + " pixels) cannot fit in a file of " +
                                          std::to_string(file_bytes) + " bytes");
    if (!multipart || attributes == 0) return;
  }
}

}  // namespace flarekit::detail
