#include "common/exr.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/testing.h"

namespace flarekit {
namespace {

using testing::TempDir;

cv::Mat randomImage(cv::Size size, int channels, float lo, float hi, int seed) {
  cv::Mat m(size, CV_MAKETYPE(CV_32F, channels));
  cv::RNG rng(seed);
  rng.fill(m, cv::RNG::UNIFORM, lo, hi);
  return m;
}

bool bitExact(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y)
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  return true;
}

// Expects `f` to throw InputError whose one-line message names `path` and contains `needle`.
template <typename F>
void expectInputError(F f, const std::filesystem::path& path, const std::string& needle) {
  try {
    f();
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    std::string what = e.what();
    EXPECT_NE(what.find(path.string()), std::string::npos) << what;
    EXPECT_NE(what.find(needle), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

ExrImage sampleImage() {
  ExrImage image;
  image.layers.push_back({"", randomImage({37, 23}, 3, -5.f, 1e6f, 1)});
  image.layers.push_back({"ghost.3", randomImage({37, 23}, 1, 0.f, 10.f, 2)});
  image.layers.push_back({"ghost.7", randomImage({37, 23}, 3, 0.f, 1e-3f, 3)});
  image.attributes["flarekit.angle_deg"] = 12.25;
  image.attributes["flarekit.iso"] = 100;
  image.attributes["flarekit.gain"] = 0.5f;
  image.attributes["flarekit.lens"] = std::string("Heliar Tronnier");
  image.attributes["flarekit.bbox"] = std::vector<float>{1.f, 2.5f, 3.f, 4.f};
  image.attributes["flarekit.names"] = std::vector<std::string>{"a", "b"};
  image.attributes["flarekit.centroid"] = cv::Vec2d(3.25, -1.5);
  image.attributes["flarekit.size"] = cv::Vec2i(640, 427);
  image.attributes["flarekit.light"] = cv::Vec3f(1.f, 2.f, 3.f);
  image.attributes["flarekit.pos"] = cv::Vec3d(0.1, 0.2, 0.3);
  image.attributes["flarekit.half"] = cv::Vec2f(0.5f, 0.25f);
  return image;
}

TEST(Exr, FloatRoundTripIsBitExactWithAttributesAndLayers) {
  TempDir dir;
  ExrImage image = sampleImage();
  writeExr(dir / "a.exr", image);
  ExrImage back = readExr(dir / "a.exr");
  ASSERT_EQ(back.layers.size(), 3u);
  for (const auto& l : image.layers) {
    const ExrLayer* b = back.find(l.name);
    ASSERT_NE(b, nullptr) << l.name;
    EXPECT_TRUE(bitExact(l.image, b->image)) << l.name;
  }
  EXPECT_EQ(back.layers[0].name, "");
  EXPECT_EQ(back.attributes, image.attributes);
}

TEST(Exr, HalfRoundTripWithinHalfPrecision) {
  TempDir dir;
  ExrImage image;
  image.layers.push_back({"", randomImage({50, 40}, 3, 1e-3f, 6e4f, 4)});
  image.layers.push_back({"ghost.1", randomImage({50, 40}, 1, 0.f, 1.f, 5)});
  ExrWriteOptions options;
  options.pixel_type = ExrPixelType::kHalf;
  writeExr(dir / "h.exr", image, options);
  ExrImage back = readExr(dir / "h.exr");
  for (const auto& l : image.layers) {
    const cv::Mat& b = back.find(l.name)->image;
    for (size_t i = 0; i < l.image.total() * l.image.channels(); ++i) {
      float v = l.image.ptr<float>()[i], w = b.ptr<float>()[i];
      // Half has an 11-bit significand: relative rounding error ≤ 2^-11 for normal numbers,
      // absolute 2^-25 below the normal range.
      EXPECT_LE(std::fabs(v - w), std::max(std::fabs(v) * std::ldexp(1.f, -11), std::ldexp(1.f, -25)))
          << l.name << " " << i;
    }
  }
  auto info = describeExr(dir / "h.exr");
  for (const auto& c : info.channels) EXPECT_EQ(c.pixel_type, "half");
}

TEST(Exr, ReadsOneLayerAndListsLayers) {
  TempDir dir;
  ExrImage image = sampleImage();
  writeExr(dir / "a.exr", image);
  EXPECT_EQ(listExrLayers(dir / "a.exr"), (std::vector<std::string>{"", "ghost.3", "ghost.7"}));
  EXPECT_TRUE(bitExact(readExrLayer(dir / "a.exr", "ghost.7"), image.layers[2].image));
  EXPECT_TRUE(bitExact(readExrLayer(dir / "a.exr", ""), image.layers[0].image));
  EXPECT_EQ(readExrAttributes(dir / "a.exr"), image.attributes);
  expectInputError([&] { readExrLayer(dir / "a.exr", "ghost.4"); }, dir / "a.exr", "no layer 'ghost.4'");
}

TEST(Exr, ReadsOpenCvWrittenFiles) {
  TempDir dir;
  cv::Mat rgb = randomImage({20, 10}, 3, 0.f, 4.f, 6), bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  ASSERT_TRUE(cv::imwrite((dir / "cv.exr").string(), bgr));
  ExrImage back = readExr(dir / "cv.exr");
  ASSERT_NE(back.find(""), nullptr);
  // OpenCV stores R, G, B channels; FlareKit reads them into R,G,B memory order.
  EXPECT_TRUE(bitExact(back.main(), rgb));
}

TEST(Exr, MissingFileAndNonExr) {
  TempDir dir;
  expectInputError([&] { readExr(dir / "none.exr"); }, dir / "none.exr", "no such file");
  { std::ofstream(dir / "text.exr") << "this is not an image\n"; }
  expectInputError([&] { readExr(dir / "text.exr"); }, dir / "text.exr", "not an OpenEXR file");
  expectInputError([&] { describeExr(dir / "text.exr"); }, dir / "text.exr", "not an OpenEXR file");
}

TEST(Exr, TruncatedFile) {
  TempDir dir;
  writeExr(dir / "t.exr", randomImage({200, 100}, 3, 0.f, 1.f, 7), {}, ExrWriteOptions{ExrPixelType::kFloat, false});
  for (double keep : {0.5, 0.9, 0.99}) {
    auto size = std::filesystem::file_size(dir / "t.exr");
    std::filesystem::copy_file(dir / "t.exr", dir / "cut.exr", std::filesystem::copy_options::overwrite_existing);
    std::filesystem::resize_file(dir / "cut.exr", static_cast<uintmax_t>(size * keep));
    expectInputError([&] { readExr(dir / "cut.exr"); }, dir / "cut.exr", "truncated");
    expectInputError([&] { describeExr(dir / "cut.exr"); }, dir / "cut.exr", "truncated");
  }
  // Cut inside the header.
  std::filesystem::resize_file(dir / "cut.exr", 40);
  expectInputError([&] { readExr(dir / "cut.exr"); }, dir / "cut.exr", "truncated or corrupt");
}

// Writes a file with OpenEXR directly, for layouts FlareKit itself never writes.
void writeRaw(const std::filesystem::path& path, Imath::Box2i window, Imf::PixelType type) {
  Imf::Header h(Imath::Box2i({0, 0}, {9, 9}), window);
  h.channels().insert("Y", Imf::Channel(type));
  int w = window.max.x - window.min.x + 1, ht = window.max.y - window.min.y + 1;
  std::vector<uint32_t> data(size_t(w) * ht, 1);
  Imf::FrameBuffer fb;
  char* base = reinterpret_cast<char*>(data.data()) - (window.min.x + window.min.y * w) * 4;
  fb.insert("Y", Imf::Slice(type, base, 4, size_t(4) * w));
  Imf::OutputFile out(path.c_str(), h);
  out.setFrameBuffer(fb);
  out.writePixels(ht);
}

TEST(Exr, DataWindowMustStartAtOrigin) {
  TempDir dir;
  writeRaw(dir / "dw.exr", Imath::Box2i({2, 3}, {9, 9}), Imf::FLOAT);
  expectInputError([&] { readExr(dir / "dw.exr"); }, dir / "dw.exr", "data window starts at (2, 3)");
}

TEST(Exr, UnsupportedPixelType) {
  TempDir dir;
  writeRaw(dir / "u.exr", Imath::Box2i({0, 0}, {9, 9}), Imf::UINT);
  expectInputError([&] { readExr(dir / "u.exr"); }, dir / "u.exr", "pixel type uint");
  // Inspection still works: exr-info shows what is there.
  EXPECT_EQ(describeExr(dir / "u.exr").channels.at(0).pixel_type, "uint");
}

TEST(Exr, NonFiniteValuesWhereForbidden) {
  TempDir dir;
  cv::Mat m = randomImage({8, 6}, 1, 0.f, 1.f, 8);
  m.at<float>(4, 5) = std::numeric_limits<float>::quiet_NaN();
  writeExr(dir / "nan.exr", m);
  EXPECT_NO_THROW(readExr(dir / "nan.exr"));
  expectInputError([&] { readExr(dir / "nan.exr", ExrReadOptions{false}); }, dir / "nan.exr",
                   "non-finite value at pixel (5, 4)");
  auto info = describeExr(dir / "nan.exr");
  EXPECT_EQ(info.channels.at(0).nonfinite_count, 1);
  EXPECT_EQ(info.channels.at(0).finite_count, 47);
}

TEST(Exr, RejectsImagesItCannotStore) {
  TempDir dir;
  cv::Mat bytes(4, 4, CV_8UC1, cv::Scalar(1));
  expectInputError([&] { writeExr(dir / "b.exr", bytes); }, dir / "b.exr", "not CV_32FC1");
  ExrImage twoSizes;
  twoSizes.layers = {{"", cv::Mat::zeros(4, 4, CV_32F)}, {"x", cv::Mat::zeros(5, 4, CV_32F)}};
  expectInputError([&] { writeExr(dir / "b.exr", twoSizes); }, dir / "b.exr", "differs in size");
  ExrImage reserved;
  reserved.layers = {{"", cv::Mat::zeros(4, 4, CV_32F)}};
  reserved.attributes["channels"] = 3;
  expectInputError([&] { writeExr(dir / "b.exr", reserved); }, dir / "b.exr", "reserved");
  EXPECT_FALSE(std::filesystem::exists(dir / "b.exr"));
}

TEST(Exr, DescribeGivesStatisticsAndAttributes) {
  TempDir dir;
  cv::Mat m(2, 2, CV_32F);
  m.at<float>(0, 0) = 1;
  m.at<float>(0, 1) = 2;
  m.at<float>(1, 0) = 3;
  m.at<float>(1, 1) = std::numeric_limits<float>::infinity();
  writeExr(dir / "s.exr", m, {{"flarekit.angle_deg", 2.5}});
  auto info = describeExr(dir / "s.exr");
  EXPECT_EQ(info.width, 2);
  EXPECT_EQ(info.channels.at(0).name, "Y");
  EXPECT_DOUBLE_EQ(info.channels[0].min, 1);
  EXPECT_DOUBLE_EQ(info.channels[0].max, 3);
  EXPECT_DOUBLE_EQ(info.channels[0].mean, 2);
  EXPECT_EQ(info.channels[0].nonfinite_count, 1);
  bool found = false;
  for (const auto& a : info.attributes)
    if (a.name == "flarekit.angle_deg") {
      found = true;
      EXPECT_EQ(a.type, "double");
      EXPECT_EQ(a.value, "2.5");
    }
  EXPECT_TRUE(found);
  EXPECT_NE(toText(info).find("flarekit.angle_deg (double): 2.5"), std::string::npos);
}

// A header that claims more pixels than its file could hold is refused before any allocation.
TEST(Exr, DataWindowLargerThanTheFileIsCorrupt) {
  TempDir dir;
  {
    Imf::Header h(20000, 20000);  // float: 1.6 GB
    h.channels().insert("Y", Imf::Channel(Imf::FLOAT));
    Imf::OutputFile out((dir / "big.exr").c_str(), h);  // header and offsets only: pixels never written
  }
  expectInputError([&] { readExr(dir / "big.exr"); }, dir / "big.exr",
                   "corrupt header: its data window (20000 x 20000 pixels) cannot fit in a file of");
  expectInputError([&] { describeExr(dir / "big.exr"); }, dir / "big.exr", "corrupt header");
}

// OpenEXR reads an attribute's value whole while opening: a size the file cannot hold is refused first.
TEST(Exr, AttributeLargerThanTheFileIsCorrupt) {
  TempDir dir;
  writeExr(dir / "a.exr", cv::Mat(2, 2, CV_32F, cv::Scalar(1)), {{"note", std::string("hello")}});
  std::string bytes;
  {
    std::ifstream in(dir / "a.exr", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string key("note\0string\0", 12);
  const size_t at = bytes.find(key);
  ASSERT_NE(at, std::string::npos);
  bytes.replace(at + key.size(), 4, std::string("\x00\x00\x00\x60", 4));  // 1.6 GB
  { std::ofstream(dir / "a.exr", std::ios::binary) << bytes; }
  expectInputError([&] { readExr(dir / "a.exr"); }, dir / "a.exr",
                   "truncated or corrupt header: attribute 'note' claims 1610612736 bytes, more than the file holds");
}

// OpenEXR reads a channel list record by record, not by its declared size; the check follows it
// there and finds the 1.8 GB attribute after it (inputs found by fuzz/exr_fuzzer).
TEST(Exr, AttributeAfterAChannelListLongerThanItsSizeIsChecked) {
  for (const char* name : {"exr/regression_channel_list_longer_than_its_size.exr",
                           "exr_stack/regression_channel_list_longer_than_its_size.exr"}) {
    const std::filesystem::path file = std::filesystem::path(FLAREKIT_SOURCE_DIR) / "fuzz/corpus" / name;
    expectInputError([&] { readExr(file); }, file, "truncated or corrupt header: attribute '");
  }
}

// OpenEXR reads a float vector as the whole floats its size holds, leaving the bytes over for the
// next attribute's name; the check reads it so and finds the oversized attribute OpenEXR then sees
// (input found by fuzz/exr_fuzzer).
TEST(Exr, AttributeAfterAFloatVectorOfOddSizeIsChecked) {
  const std::filesystem::path file =
      std::filesystem::path(FLAREKIT_SOURCE_DIR) / "fuzz/corpus/exr/regression_floatvector_size_not_a_multiple_of_4.exr";
  expectInputError([&] { readExr(file); }, file, "truncated or corrupt header: attribute '");
}

// Attributes print as the shortest text that reads back, subnormal numbers too.
TEST(Exr, DescribesSubnormalAndNonFiniteAttributes) {
  TempDir dir;
  writeExr(dir / "a.exr", cv::Mat(2, 2, CV_32F, cv::Scalar(1)),
           {{"tiny", 4.9406564584124654e-324}, {"huge", std::numeric_limits<double>::infinity()}});
  const std::string text = toText(describeExr(dir / "a.exr"));
  EXPECT_NE(text.find("tiny (double): 5e-324"), std::string::npos) << text;
  EXPECT_NE(text.find("huge (double): inf"), std::string::npos) << text;
}

TEST(Exr, DefaultOptionsAreValid) {
  std::string why;
  EXPECT_TRUE(ExrWriteOptions{}.IsValid(&why)) << why;
}

TEST(Exr, ZipLevelChangesTheSizeNotThePixels) {
  TempDir dir;
  cv::Mat image(96, 128, CV_32FC3);  // repeating patterns, where zlib's levels differ
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x)
      image.at<cv::Vec3f>(y, x) = cv::Vec3f(0.01f * (x % 17), 0.1f * (y % 5), 0.001f * ((x * y) % 251));
  ExrWriteOptions fast, small;
  fast.zip_level = 1;
  small.zip_level = 9;
  writeExr(dir / "fast.exr", image, {}, fast);
  writeExr(dir / "small.exr", image, {}, small);
  EXPECT_EQ(cv::norm(readExrLayer(dir / "fast.exr", ""), image, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(readExrLayer(dir / "small.exr", ""), image, cv::NORM_INF), 0.0);
  EXPECT_GT(std::filesystem::file_size(dir / "fast.exr"), std::filesystem::file_size(dir / "small.exr"));
  ExrWriteOptions bad;
  bad.zip_level = 10;
  EXPECT_FALSE(bad.IsValid(nullptr));
}

}  // namespace
}  // namespace flarekit
