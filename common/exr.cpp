#include "common/exr.h"

#include <ImathBox.h>
#include <ImathVec.h>
#include <OpenEXR/ImfBoxAttribute.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfChannelListAttribute.h>
#include <OpenEXR/ImfChromaticitiesAttribute.h>
#include <OpenEXR/ImfCompressionAttribute.h>
#include <OpenEXR/ImfDoubleAttribute.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFloatVectorAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfLineOrderAttribute.h>
#include <OpenEXR/ImfMatrixAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfRationalAttribute.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfStringVectorAttribute.h>
#include <OpenEXR/ImfTestFile.h>
#include <OpenEXR/ImfVecAttribute.h>
#include <half.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/atomic_file.h"
#include "common/error.h"
#include "common/exr_header_check.h"
#include "common/input_file.h"

namespace flarekit {
namespace {

namespace fs = std::filesystem;

// Header fields every EXR file has; they are not user attributes.
const std::set<std::string>& standardAttributeNames() {
  static const std::set<std::string> names = {
      "channels",         "compression",        "dataWindow",        "displayWindow",
      "lineOrder",        "pixelAspectRatio",   "screenWindowCenter", "screenWindowWidth",
      "tiles",            "type",               "name",              "version",
      "chunkCount",       "view"};
  return names;
}

bool isMainChannel(const std::string& c) { return c == "R" || c == "G" || c == "B" || c == "Y"; }

// One channel of a layer: its suffix within the layer ("Y", "R", ...; "" for a bare channel that
// is a layer of its own) and its full name in the file.
struct ChannelRef {
  std::string suffix, full;
  Imf::PixelType type;
};
struct LayerLayout {
  std::string name;
  std::vector<ChannelRef> read;  // 1 or 3 channels, in R,G,B order
};

std::string pixelTypeName(Imf::PixelType t) {
  switch (t) {
    case Imf::HALF: return "half";
    case Imf::FLOAT: return "float";
    case Imf::UINT: return "uint";
    default: return "unknown";
  }
}

std::string layerLabel(const std::string& name) { return name.empty() ? "main layer" : "layer '" + name + "'"; }

// Groups the file's channels into layers (see exr.h for the rules).
std::vector<LayerLayout> layoutOf(const fs::path& path, const Imf::ChannelList& channels) {
  std::vector<std::string> order;
  std::map<std::string, std::vector<ChannelRef>> byLayer;
  for (auto it = channels.begin(); it != channels.end(); ++it) {
    std::string full = it.name();
    std::string layer, suffix;
    auto dot = full.rfind('.');
    if (dot == std::string::npos) {
      if (isMainChannel(full)) {
        suffix = full;
      } else {
        layer = full;
      }
    } else {
      layer = full.substr(0, dot);
      suffix = full.substr(dot + 1);
    }
    if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
      throw InputError(path.string(), "channel '" + full + "' is subsampled; FlareKit reads full-resolution channels only");
    if (!byLayer.count(layer)) order.push_back(layer);
    byLayer[layer].push_back({suffix, full, it.channel().type});
  }
  // The main layer first.
  std::stable_partition(order.begin(), order.end(), [](const std::string& s) { return s.empty(); });

  std::vector<LayerLayout> layouts;
  for (const auto& name : order) {
    const auto& chans = byLayer[name];
    auto find = [&](const std::string& s) -> const ChannelRef* {
      for (const auto& c : chans)
        if (c.suffix == s) return &c;
      return nullptr;
    };
    LayerLayout layout{name, {}};
    if (find("R") && find("G") && find("B")) {
      layout.read = {*find("R"), *find("G"), *find("B")};
    } else if (chans.size() == 1) {
      layout.read = {chans[0]};
    } else if (find("Y")) {
      layout.read = {*find("Y")};
    } else {
      std::string list;
      for (const auto& c : chans) list += (list.empty() ? "" : ", ") + c.full;
      throw InputError(path.string(), layerLabel(name) + " has channels (" + list +
                                          "); FlareKit reads Y, R/G/B, or a single channel");
    }
    layouts.push_back(std::move(layout));
  }
  return layouts;
}

// Opens an EXR file for reading with every check that does not need the pixels.
std::unique_ptr<Imf::InputFile> openExr(const fs::path& path) {
  const std::uintmax_t file_bytes = checkInputFile(path);
  bool tiled = false, deep = false, multipart = false;
  if (!Imf::isOpenExrFile(path.c_str(), tiled, deep, multipart))
    throw InputError(path.string(), "not an OpenEXR file (no EXR magic number)");
  if (deep) throw InputError(path.string(), "holds deep data; FlareKit reads flat images only");
  detail::checkExrHeaderSizes(path, file_bytes);
  std::unique_ptr<Imf::InputFile> file;
  try {
    file = std::make_unique<Imf::InputFile>(path.c_str());
  } catch (const std::exception& e) {
    throw InputError(path.string(), std::string("unreadable EXR header (truncated or corrupt): ") + e.what());
  }
  const Imath::Box2i& dw = file->header().dataWindow();
  if (dw.min.x != 0 || dw.min.y != 0)
    throw InputError(path.string(), "data window starts at (" + std::to_string(dw.min.x) + ", " +
                                        std::to_string(dw.min.y) + "); FlareKit needs it at (0, 0)");
  if (!file->isComplete())
    throw InputError(path.string(), "truncated: the file ends before all pixel data");
  return file;
}

cv::Size sizeOf(const Imf::Header& h) {
  const Imath::Box2i& dw = h.dataWindow();
  return {dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1};
}

void checkFinite(const fs::path& path, const std::string& layer, const cv::Mat& m) {
  const int nch = m.channels();
  for (int y = 0; y < m.rows; ++y) {
    const float* row = m.ptr<float>(y);
    for (int x = 0; x < m.cols * nch; ++x) {
      if (!std::isfinite(row[x])) {
        throw InputError(path.string(), layerLabel(layer) + " has a non-finite value at pixel (" +
                                            std::to_string(x / nch) + ", " + std::to_string(y) + ")");
      }
    }
  }
}

// Reads the given layers in one pass.
std::vector<ExrLayer> readLayers(const fs::path& path, Imf::InputFile& file,
                                 const std::vector<LayerLayout>& layouts,
                                 const ExrReadOptions& options) {
  cv::Size size = sizeOf(file.header());
  std::vector<ExrLayer> layers;
  layers.reserve(layouts.size());
  Imf::FrameBuffer fb;
  for (const auto& layout : layouts) {
    const int nch = static_cast<int>(layout.read.size());
    for (const auto& c : layout.read)
      if (c.type != Imf::HALF && c.type != Imf::FLOAT)
        throw InputError(path.string(), "channel '" + c.full + "' has pixel type " +
                                            pixelTypeName(c.type) + "; FlareKit reads half or float");
    ExrLayer layer{layout.name, cv::Mat(size, CV_MAKETYPE(CV_32F, nch), cv::Scalar::all(0))};
    char* base = reinterpret_cast<char*>(layer.image.data);
    const size_t xs = sizeof(float) * nch, ys = layer.image.step[0];
    for (int c = 0; c < nch; ++c)
      fb.insert(layout.read[c].full, Imf::Slice(Imf::FLOAT, base + c * sizeof(float), xs, ys));
    layers.push_back(std::move(layer));
  }
  try {
    file.setFrameBuffer(fb);
    const Imath::Box2i& dw = file.header().dataWindow();
    file.readPixels(dw.min.y, dw.max.y);
  } catch (const std::exception& e) {
    throw InputError(path.string(), std::string("truncated or corrupt pixel data: ") + e.what());
  }
  if (!options.allow_nonfinite)
    for (const auto& l : layers) checkFinite(path, l.name, l.image);
  return layers;
}

template <typename A>
const A* as(const Imf::Attribute& a) {
  return dynamic_cast<const A*>(&a);
}

std::optional<ExrAttribute> typedValue(const Imf::Attribute& a) {
  if (auto* v = as<Imf::IntAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::FloatAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::DoubleAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::StringAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::FloatVectorAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::StringVectorAttribute>(a)) return ExrAttribute{v->value()};
  if (auto* v = as<Imf::V2iAttribute>(a)) return ExrAttribute{cv::Vec2i(v->value().x, v->value().y)};
  if (auto* v = as<Imf::V2fAttribute>(a)) return ExrAttribute{cv::Vec2f(v->value().x, v->value().y)};
  if (auto* v = as<Imf::V2dAttribute>(a)) return ExrAttribute{cv::Vec2d(v->value().x, v->value().y)};
  if (auto* v = as<Imf::V3fAttribute>(a))
    return ExrAttribute{cv::Vec3f(v->value().x, v->value().y, v->value().z)};
  if (auto* v = as<Imf::V3dAttribute>(a))
    return ExrAttribute{cv::Vec3d(v->value().x, v->value().y, v->value().z)};
  return std::nullopt;
}

std::string compressionName(Imf::Compression c) {
  switch (c) {
    case Imf::NO_COMPRESSION: return "none";
    case Imf::RLE_COMPRESSION: return "rle";
    case Imf::ZIPS_COMPRESSION: return "zips";
    case Imf::ZIP_COMPRESSION: return "zip";
    case Imf::PIZ_COMPRESSION: return "piz";
    case Imf::PXR24_COMPRESSION: return "pxr24";
    case Imf::B44_COMPRESSION: return "b44";
    case Imf::B44A_COMPRESSION: return "b44a";
    case Imf::DWAA_COMPRESSION: return "dwaa";
    case Imf::DWAB_COMPRESSION: return "dwab";
    default: return "unknown";
  }
}

struct AttributeText {
  std::string operator()(int v) const { return std::to_string(v); }
  std::string operator()(float v) const { return numberText(v); }
  std::string operator()(double v) const { return numberText(v); }
  std::string operator()(const std::string& v) const { return "\"" + v + "\""; }
  std::string operator()(const std::vector<float>& v) const {
    std::string s = "[";
    for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + numberText(v[i]);
    return s + "]";
  }
  std::string operator()(const std::vector<std::string>& v) const {
    std::string s = "[";
    for (size_t i = 0; i < v.size(); ++i) s += (i ? ", \"" : "\"") + v[i] + "\"";
    return s + "]";
  }
  template <typename T, int N>
  std::string operator()(const cv::Vec<T, N>& v) const {
    std::string s = "(";
    for (int i = 0; i < N; ++i) {
      if constexpr (std::is_integral_v<T>) s += (i ? ", " : "") + std::to_string(v[i]);
      else s += (i ? ", " : "") + numberText(v[i]);
    }
    return s + ")";
  }
};

std::string describeAttribute(const Imf::Attribute& a) {
  if (auto t = typedValue(a)) return std::visit(AttributeText{}, *t);
  if (auto* v = as<Imf::Box2iAttribute>(a)) {
    const auto& b = v->value();
    return "(" + std::to_string(b.min.x) + ", " + std::to_string(b.min.y) + ") - (" +
           std::to_string(b.max.x) + ", " + std::to_string(b.max.y) + ")";
  }
  if (auto* v = as<Imf::CompressionAttribute>(a)) return compressionName(v->value());
  if (auto* v = as<Imf::LineOrderAttribute>(a))
    return v->value() == Imf::INCREASING_Y ? "increasing y" : v->value() == Imf::DECREASING_Y ? "decreasing y" : "random y";
  if (auto* v = as<Imf::ChannelListAttribute>(a)) {
    std::string s;
    for (auto it = v->value().begin(); it != v->value().end(); ++it)
      s += (s.empty() ? "" : ", ") + std::string(it.name()) + " " + pixelTypeName(it.channel().type);
    return s;
  }
  if (auto* v = as<Imf::RationalAttribute>(a))
    return std::to_string(v->value().n) + "/" + std::to_string(v->value().d);
  if (auto* v = as<Imf::ChromaticitiesAttribute>(a)) {
    const auto& c = v->value();
    return "red (" + numberText(c.red.x) + ", " + numberText(c.red.y) + "), green (" +
           numberText(c.green.x) + ", " + numberText(c.green.y) + "), blue (" +
           numberText(c.blue.x) + ", " + numberText(c.blue.y) + "), white (" +
           numberText(c.white.x) + ", " + numberText(c.white.y) + ")";
  }
  return "(" + std::string(a.typeName()) + " value)";
}

void insertAttribute(Imf::Header& h, const std::string& name, const ExrAttribute& value) {
  std::visit(
      [&](const auto& v) {
        using T = std::decay_t<decltype(v)>;
        if constexpr (std::is_same_v<T, int>) h.insert(name, Imf::IntAttribute(v));
        else if constexpr (std::is_same_v<T, float>) h.insert(name, Imf::FloatAttribute(v));
        else if constexpr (std::is_same_v<T, double>) h.insert(name, Imf::DoubleAttribute(v));
        else if constexpr (std::is_same_v<T, std::string>) h.insert(name, Imf::StringAttribute(v));
        else if constexpr (std::is_same_v<T, std::vector<float>>) h.insert(name, Imf::FloatVectorAttribute(v));
        else if constexpr (std::is_same_v<T, std::vector<std::string>>) h.insert(name, Imf::StringVectorAttribute(v));
        else if constexpr (std::is_same_v<T, cv::Vec2i>) h.insert(name, Imf::V2iAttribute(Imath::V2i(v[0], v[1])));
        else if constexpr (std::is_same_v<T, cv::Vec2f>) h.insert(name, Imf::V2fAttribute(Imath::V2f(v[0], v[1])));
        else if constexpr (std::is_same_v<T, cv::Vec2d>) h.insert(name, Imf::V2dAttribute(Imath::V2d(v[0], v[1])));
        else if constexpr (std::is_same_v<T, cv::Vec3f>) h.insert(name, Imf::V3fAttribute(Imath::V3f(v[0], v[1], v[2])));
        else if constexpr (std::is_same_v<T, cv::Vec3d>) h.insert(name, Imf::V3dAttribute(Imath::V3d(v[0], v[1], v[2])));
      },
      value);
}

std::vector<std::string> channelNamesFor(const ExrLayer& layer) {
  const std::string prefix = layer.name.empty() ? "" : layer.name + ".";
  if (layer.image.channels() == 3) return {prefix + "R", prefix + "G", prefix + "B"};
  return {prefix + "Y"};
}

}  // namespace

std::optional<double> numericAttribute(const ExrAttributes& attributes, const std::string& name) {
  auto it = attributes.find(name);
  if (it == attributes.end()) return std::nullopt;
  if (auto* i = std::get_if<int>(&it->second)) return *i;
  if (auto* f = std::get_if<float>(&it->second)) return *f;
  if (auto* d = std::get_if<double>(&it->second)) return *d;
  return std::nullopt;
}

std::optional<std::string> stringAttribute(const ExrAttributes& attributes, const std::string& name) {
  auto it = attributes.find(name);
  if (it == attributes.end()) return std::nullopt;
  if (auto* s = std::get_if<std::string>(&it->second)) return *s;
  return std::nullopt;
}

const ExrLayer* ExrImage::find(const std::string& name) const {
  for (const auto& l : layers)
    if (l.name == name) return &l;
  return nullptr;
}

const cv::Mat& ExrImage::main() const {
  const ExrLayer* l = find("");
  if (!l) throw std::logic_error("ExrImage has no main layer");
  return l->image;
}

bool ExrWriteOptions::IsValid(std::string* error) const {
  if (pixel_type != ExrPixelType::kFloat && pixel_type != ExrPixelType::kHalf) {
    if (error) *error = "pixel_type must be float or half";
    return false;
  }
  if (zip_level < 0 || zip_level > 9) {
    if (error) *error = "zip_level must be 0 (the default) or 1 to 9";
    return false;
  }
  return true;
}

void writeExr(const fs::path& path, const ExrImage& image, const ExrWriteOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw std::invalid_argument("ExrWriteOptions: " + why);
  if (image.layers.empty()) throw InputError(path.string(), "nothing to write: the image has no layers");
  const cv::Size size = image.layers.front().image.size();
  if (size.area() == 0) throw InputError(path.string(), "cannot write an empty image");
  std::set<std::string> names;
  for (const auto& l : image.layers) {
    if (l.image.type() != CV_32FC1 && l.image.type() != CV_32FC3)
      throw InputError(path.string(), layerLabel(l.name) + " is not CV_32FC1 or CV_32FC3");
    if (l.image.size() != size)
      throw InputError(path.string(), layerLabel(l.name) + " differs in size from the first layer");
    if (!names.insert(l.name).second)
      throw InputError(path.string(), layerLabel(l.name) + " appears twice");
  }
  for (const auto& [name, value] : image.attributes) {
    if (name.empty() || standardAttributeNames().count(name))
      throw InputError(path.string(), "attribute name '" + name + "' is reserved by OpenEXR");
  }

  Imf::Header header(size.width, size.height);
  header.compression() = options.compress ? Imf::ZIP_COMPRESSION : Imf::NO_COMPRESSION;
  if (options.zip_level > 0) header.zipCompressionLevel() = options.zip_level;
  for (const auto& [name, value] : image.attributes) insertAttribute(header, name, value);

  const bool half = options.pixel_type == ExrPixelType::kHalf;
  const Imf::PixelType type = half ? Imf::HALF : Imf::FLOAT;
  Imf::FrameBuffer fb;
  std::vector<cv::Mat> keep;                   // continuous float copies where needed
  std::vector<std::vector<Imath::half>> halves;  // converted data for half output
  halves.reserve(image.layers.size());
  for (const auto& l : image.layers) {
    const int nch = l.image.channels();
    auto channels = channelNamesFor(l);
    for (const auto& c : channels) header.channels().insert(c, Imf::Channel(type));
    if (half) {
      cv::Mat src = l.image.isContinuous() ? l.image : l.image.clone();
      const float* p = src.ptr<float>();
      std::vector<Imath::half> buf(src.total() * nch);
      for (size_t i = 0; i < buf.size(); ++i) buf[i] = Imath::half(p[i]);
      halves.push_back(std::move(buf));
      char* base = reinterpret_cast<char*>(halves.back().data());
      for (int c = 0; c < nch; ++c)
        fb.insert(channels[c], Imf::Slice(Imf::HALF, base + c * sizeof(Imath::half),
                                          sizeof(Imath::half) * nch,
                                          sizeof(Imath::half) * nch * size.width));
    } else {
      keep.push_back(l.image.isContinuous() ? l.image : l.image.clone());
      char* base = reinterpret_cast<char*>(keep.back().data);
      for (int c = 0; c < nch; ++c)
        fb.insert(channels[c], Imf::Slice(Imf::FLOAT, base + c * sizeof(float), sizeof(float) * nch,
                                          keep.back().step[0]));
    }
  }

  writeFileAtomically(path, [&](const fs::path& temporary) {
    try {
      Imf::OutputFile out(temporary.c_str(), header);
      out.setFrameBuffer(fb);
      out.writePixels(size.height);
    } catch (const std::exception& e) {
      throw RuntimeError("cannot write " + path.string() + ": " + e.what() +
                         " (check free disk space and permissions)");
    }
  }, options.durability);
}

void writeExr(const fs::path& path, const cv::Mat& image, const ExrAttributes& attributes,
              const ExrWriteOptions& options) {
  writeExr(path, ExrImage{{ExrLayer{"", image}}, attributes}, options);
}

ExrImage readExr(const fs::path& path, const ExrReadOptions& options) {
  auto file = openExr(path);
  ExrImage image;
  image.layers = readLayers(path, *file, layoutOf(path, file->header().channels()), options);
  for (auto it = file->header().begin(); it != file->header().end(); ++it) {
    if (standardAttributeNames().count(it.name())) continue;
    if (auto v = typedValue(it.attribute())) image.attributes[it.name()] = *v;
  }
  return image;
}

cv::Mat readExrLayer(const fs::path& path, const std::string& layer, const ExrReadOptions& options) {
  auto file = openExr(path);
  auto layouts = layoutOf(path, file->header().channels());
  for (const auto& l : layouts)
    if (l.name == layer) return readLayers(path, *file, {l}, options).front().image;
  std::string available;
  for (const auto& l : layouts) available += (available.empty() ? "" : ", ") + (l.name.empty() ? std::string("(main)") : l.name);
  throw InputError(path.string(), "has no " + layerLabel(layer) + " (layers: " +
                                      (available.empty() ? "none" : available) + ")");
}

std::vector<std::string> listExrLayers(const fs::path& path) {
  auto file = openExr(path);
  std::vector<std::string> names;
  for (const auto& l : layoutOf(path, file->header().channels())) names.push_back(l.name);
  return names;
}

ExrAttributes readExrAttributes(const fs::path& path) {
  auto file = openExr(path);
  ExrAttributes attributes;
  for (auto it = file->header().begin(); it != file->header().end(); ++it) {
    if (standardAttributeNames().count(it.name())) continue;
    if (auto v = typedValue(it.attribute())) attributes[it.name()] = *v;
  }
  return attributes;
}

ExrFileInfo describeExr(const fs::path& path, const ExrDescribeOptions& options) {
  if (options.layer || options.require_finite) {
    // The same checks a reader of that layer (or of every layer) makes.
    ExrReadOptions read{!options.require_finite};
    if (options.layer)
      readExrLayer(path, *options.layer, read);
    else
      readExr(path, read);
  }
  auto file = openExr(path);
  const Imf::Header& h = file->header();
  ExrFileInfo info;
  info.path = path.string();
  cv::Size size = sizeOf(h);
  info.width = size.width;
  info.height = size.height;
  info.compression = compressionName(h.compression());
  // Layers (a file of channels FlareKit cannot group still gets described channel by channel).
  try {
    for (const auto& l : layoutOf(path, h.channels())) info.layers.push_back(l.name);
  } catch (const InputError&) {
  }
  // Every channel, read as float (OpenEXR converts half and uint).
  std::vector<cv::Mat> planes;
  Imf::FrameBuffer fb;
  std::set<std::string> wanted;
  if (options.layer)
    for (const auto& l : layoutOf(path, h.channels()))
      if (l.name == *options.layer)
        for (const auto& c : l.read) wanted.insert(c.full);
  for (auto it = h.channels().begin(); it != h.channels().end(); ++it) {
    if (options.layer && !wanted.count(it.name())) continue;
    if (it.channel().xSampling != 1 || it.channel().ySampling != 1)
      throw InputError(path.string(), "channel '" + std::string(it.name()) + "' is subsampled; FlareKit reads full-resolution channels only");
    planes.emplace_back(size, CV_32FC1, cv::Scalar(0));
    fb.insert(it.name(), Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(planes.back().data),
                                    sizeof(float), planes.back().step[0]));
    info.channels.push_back({it.name(), pixelTypeName(it.channel().type)});
  }
  try {
    file->setFrameBuffer(fb);
    file->readPixels(h.dataWindow().min.y, h.dataWindow().max.y);
  } catch (const std::exception& e) {
    throw InputError(path.string(), std::string("truncated or corrupt pixel data: ") + e.what());
  }
  for (size_t i = 0; i < planes.size(); ++i) {
    auto& c = info.channels[i];
    double sum = 0;
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int y = 0; y < size.height; ++y) {
      const float* row = planes[i].ptr<float>(y);
      for (int x = 0; x < size.width; ++x) {
        if (!std::isfinite(row[x])) {
          ++c.nonfinite_count;
          continue;
        }
        ++c.finite_count;
        sum += row[x];
        lo = std::min(lo, double(row[x]));
        hi = std::max(hi, double(row[x]));
      }
    }
    if (c.finite_count) {
      c.min = lo;
      c.max = hi;
      c.mean = sum / double(c.finite_count);
    }
  }
  for (auto it = h.begin(); it != h.end(); ++it)
    info.attributes.push_back({it.name(), it.attribute().typeName(), describeAttribute(it.attribute())});
  return info;
}

nlohmann::json toJson(const ExrFileInfo& info) {
  nlohmann::json j;
  j["path"] = info.path;
  j["width"] = info.width;
  j["height"] = info.height;
  j["compression"] = info.compression;
  j["layers"] = info.layers;
  j["channels"] = nlohmann::json::array();
  for (const auto& c : info.channels) {
    nlohmann::json cj = {{"name", c.name}, {"pixel_type", c.pixel_type},
                         {"finite_count", c.finite_count}, {"nonfinite_count", c.nonfinite_count}};
    if (c.finite_count) {
      cj["min"] = c.min;
      cj["max"] = c.max;
      cj["mean"] = c.mean;
    } else {
      cj["min"] = cj["max"] = cj["mean"] = nullptr;
    }
    j["channels"].push_back(cj);
  }
  j["attributes"] = nlohmann::json::array();
  for (const auto& a : info.attributes)
    j["attributes"].push_back({{"name", a.name}, {"type", a.type}, {"value", a.value}});
  return j;
}

std::string toText(const ExrFileInfo& info) {
  std::ostringstream out;
  out << info.path << ": " << info.width << " x " << info.height << ", " << info.compression
      << " compression\n";
  out << "  layers: ";
  for (size_t i = 0; i < info.layers.size(); ++i)
    out << (i ? ", " : "") << (info.layers[i].empty() ? "(main)" : info.layers[i]);
  out << "\n  channels:\n";
  size_t w = 4;
  for (const auto& c : info.channels) w = std::max(w, c.name.size());
  for (const auto& c : info.channels) {
    out << "    " << std::left << std::setw(int(w)) << c.name << "  " << std::setw(5) << c.pixel_type;
    if (c.finite_count)
      out << "  min " << numberText(c.min) << "  max " << numberText(c.max) << "  mean "
          << numberText(c.mean);
    else
      out << "  no finite values";
    out << "  non-finite " << c.nonfinite_count << "\n";
  }
  out << "  attributes:\n";
  for (const auto& a : info.attributes)
    out << "    " << a.name << " (" << a.type << "): " << a.value << "\n";
  return out.str();
}

}  // namespace flarekit
