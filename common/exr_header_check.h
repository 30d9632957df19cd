#pragma once
// A walk over an OpenEXR file's headers that reads every size OpenEXR would allocate from (an
// attribute's declared size, a string vector's string lengths, a preview's width × height) and
// refuses one larger than what follows in the file; then refuses a data window whose pixels would
// take more than kMaxExrCompressionRatio times the file's size. OpenEXR allocates, and for some
// types fills, such buffers while opening (attributes, a compressor's line buffers), so a damaged
// size would otherwise cost gigabytes before any error.
// Used by common/exr.cpp before the file goes to Imf::InputFile.

#include <cstdint>
#include <filesystem>

namespace flarekit::detail {

// Throws InputError "<path>: truncated or corrupt header: ..." on a size the file cannot hold.
// A header it cannot follow (OpenEXR then names the problem) passes.
void checkExrHeaderSizes(const std::filesystem::path& path, std::uintmax_t file_bytes);

}  // namespace flarekit::detail
