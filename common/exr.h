#pragma once
// OpenEXR images with typed metadata and layers (docs/design.md, Conventions).
//
// Images are cv::Mat CV_32FC1 (luminance) or CV_32FC3 (linear R,G,B in memory order). A file holds
// layers: the main layer "" with channels "Y" or "R","G","B", and named layers such as "ghost.3"
// with "ghost.3.Y" or "ghost.3.R/G/B". A channel with no dot that is not Y/R/G/B (the merge's
// "saturated" mask, or "A") reads as a one-channel layer of its own name. Attributes are typed
// (int, float, double, string, float and string vectors, 2-/3-vectors); FlareKit's own attributes
// are named "flarekit.<key>".
//
// Every read error is an InputError naming the file and the problem; writes are atomic.

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "common/atomic_file.h"

namespace flarekit {

using ExrAttribute = std::variant<int, float, double, std::string, std::vector<float>,
                                  std::vector<std::string>, cv::Vec2i, cv::Vec2f, cv::Vec2d,
                                  cv::Vec3f, cv::Vec3d>;
using ExrAttributes = std::map<std::string, ExrAttribute>;

// A number stored as int, float or double; nullopt when absent or of another type.
std::optional<double> numericAttribute(const ExrAttributes& attributes, const std::string& name);
std::optional<std::string> stringAttribute(const ExrAttributes& attributes, const std::string& name);

struct ExrLayer {
  std::string name;  // "" for the main layer, else e.g. "ghost.3" or "saturated"
  cv::Mat image;     // CV_32FC1 or CV_32FC3, the same size as every other layer of the file
};

struct ExrImage {
  std::vector<ExrLayer> layers;  // the main layer (if any) first, then the others in file order
  ExrAttributes attributes;      // user attributes; the standard header fields are left out

  // The layer of that name, or nullptr.
  const ExrLayer* find(const std::string& name) const;
  // The main layer's image; throws std::logic_error when there is none.
  const cv::Mat& main() const;
};

enum class ExrPixelType { kFloat, kHalf };

struct ExrWriteOptions {
  // Storage of every channel. Half keeps ~3 significant digits and overflows to inf past 65504:
  // fine for previews and ground-truth layers of normalised images, not for raw HDR radiance.
  ExrPixelType pixel_type = ExrPixelType::kFloat;
  // Zip compression (lossless); false writes uncompressed scan lines.
  bool compress = true;
  // zlib's level for it, 1 (fastest) to 9 (smallest); 0 = OpenEXR's default.
  int zip_level = 0;
  // When the file reaches the disk (common/atomic_file.h); kFlushed: before writeExr returns.
  Durability durability = Durability::kFlushed;

  bool IsValid(std::string* error) const;
};

// Writes `image` atomically. Throws InputError for images FlareKit cannot store (wrong type,
// layers of different sizes, empty names, duplicate layers), RuntimeError on I/O failure.
void writeExr(const std::filesystem::path& path, const ExrImage& image,
              const ExrWriteOptions& options = {});
// Writes one image as the main layer.
void writeExr(const std::filesystem::path& path, const cv::Mat& image,
              const ExrAttributes& attributes = {}, const ExrWriteOptions& options = {});

struct ExrReadOptions {
  // When false, a NaN or infinity in any layer read is an error that names the layer and pixel.
  bool allow_nonfinite = true;
};

// A file whose pixels would take more than this many times its size is refused as corrupt before
// anything is allocated. No lossless EXR codec comes near it (zlib's limit is about 1032:1).
inline constexpr double kMaxExrCompressionRatio = 4096;

// Reads every layer. Errors (InputError): missing file or not a regular file, not an EXR file,
// truncated file, a data window larger than the file can hold (kMaxExrCompressionRatio) or not
// starting at (0, 0), unsupported pixel type (UINT) or channel layout, non-finite values when
// forbidden, deep data.
ExrImage readExr(const std::filesystem::path& path, const ExrReadOptions& options = {});
// Reads one layer ("" = the main layer); InputError naming the available layers when absent.
cv::Mat readExrLayer(const std::filesystem::path& path, const std::string& layer,
                     const ExrReadOptions& options = {});
// Names of the layers in the file ("" for the main layer).
std::vector<std::string> listExrLayers(const std::filesystem::path& path);
// The typed user attributes, without reading pixels.
ExrAttributes readExrAttributes(const std::filesystem::path& path);

// What `flarekit exr-info` shows: every channel with statistics, every attribute as text.
struct ExrChannelInfo {
  std::string name;
  std::string pixel_type;  // "half", "float" or "uint"
  double min = 0, max = 0, mean = 0;  // over finite values
  long long finite_count = 0;
  long long nonfinite_count = 0;
};
struct ExrAttributeInfo {
  std::string name, type, value;
};
struct ExrFileInfo {
  std::string path;
  int width = 0, height = 0;
  std::string compression;
  std::vector<std::string> layers;
  std::vector<ExrChannelInfo> channels;
  std::vector<ExrAttributeInfo> attributes;  // all of them, standard ones included
};
struct ExrDescribeOptions {
  // Describe only this layer ("" = main); InputError when the file has no such layer.
  std::optional<std::string> layer;
  // Treat NaN or infinity in the described channels as an error (InputError naming the pixel).
  bool require_finite = false;
};
ExrFileInfo describeExr(const std::filesystem::path& path, const ExrDescribeOptions& options = {});
nlohmann::json toJson(const ExrFileInfo& info);
std::string toText(const ExrFileInfo& info);

}  // namespace flarekit
