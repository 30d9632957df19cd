// LibRaw decoding of DNG files written by the test itself.
#include "acquisition/raw_decode.h"

#include <gtest/gtest.h>

#include <ctime>
#include <fstream>
#include <iterator>

#include <opencv2/imgcodecs.hpp>

#include "acquisition/dng_writer.h"
#include "common/testing.h"

namespace flarekit::acquisition {
namespace {

cv::Mat pattern(int rows, int cols) {
  cv::Mat m(rows, cols, CV_16UC1);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) m.at<uint16_t>(y, x) = static_cast<uint16_t>(300 + 7 * x + 13 * y);
  return m;
}

TEST(RawDecode, ReadsBayerDngWithLevelsAndExif) {
  testing::TempDir dir;
  cv::Mat raw = pattern(48, 64);
  RawFrame spec;
  spec.data = raw;
  spec.cfa = Cfa::kRGGB;
  spec.black_level = 256;
  spec.white_level = 16383;
  spec.exposure_s = 0.25;
  spec.iso = 200;
  spec.f_number = 5.6;
  writeDng(dir / "a.dng", spec, "FlareKit Test Camera");
  RawFrame f = decodeRawFile(dir / "a.dng");
  ASSERT_EQ(f.data.size(), raw.size());
  EXPECT_EQ(f.cfa, Cfa::kRGGB);
  EXPECT_EQ(f.black_level, 256);
  EXPECT_EQ(f.white_level, 16383);
  EXPECT_NEAR(f.exposure_s, 0.25, 1e-6);
  EXPECT_NEAR(f.iso, 200, 1e-6);
  EXPECT_NEAR(f.f_number, 5.6, 1e-3);
  EXPECT_EQ(cv::norm(f.data, raw, cv::NORM_INF), 0.0);
  EXPECT_NE(f.camera.find("FlareKit Test Camera"), std::string::npos) << f.camera;
  // Other Bayer layouts round-trip too.
  spec.cfa = Cfa::kGBRG;
  writeDng(dir / "b.dng", spec);
  EXPECT_EQ(decodeRawFile(dir / "b.dng").cfa, Cfa::kGBRG);
  spec.cfa = Cfa::kMono;
  EXPECT_THROW(writeDng(dir / "m.dng", spec), InputError);
}

// The capture time and focal length travel in the DNG's EXIF (LibRaw read 1970 and 0 mm before).
TEST(RawDecode, ReadsCaptureTimeAndFocalLengthOfADng) {
  testing::TempDir dir;
  RawFrame spec;
  spec.data = pattern(48, 64);
  spec.cfa = Cfa::kRGGB;
  spec.black_level = 256;
  spec.white_level = 16383;
  spec.exposure_s = 1;
  DngMetadata meta;
  meta.capture_time = 1780000000;  // 2026-05-28
  meta.focal_length_mm = 100;
  writeDng(dir / "a.dng", spec, meta);
  RawFrame f = decodeRawFile(dir / "a.dng");
  EXPECT_EQ(f.capture_time, 1780000000);
  EXPECT_NEAR(f.focal_length_mm, 100, 1e-6);
  // Without either, the frame's own values; the time defaults to now.
  spec.focal_length_mm = 35;
  const int64_t before = static_cast<int64_t>(std::time(nullptr));
  writeDng(dir / "b.dng", spec);
  RawFrame g = decodeRawFile(dir / "b.dng");
  EXPECT_NEAR(g.focal_length_mm, 35, 1e-6);
  EXPECT_GE(g.capture_time, before);
  EXPECT_LE(g.capture_time, static_cast<int64_t>(std::time(nullptr)));
}

TEST(RawDecode, NotARawFileIsAnInputErrorNamingTheFile) {
  testing::TempDir dir;
  std::ofstream(dir / "x.cr2") << "this is not a raw file";
  try {
    decodeRawFile(dir / "x.cr2");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("x.cr2"), std::string::npos);
  }
  EXPECT_THROW(decodeRawFile(dir / "missing.dng"), InputError);
}

TEST(RawDecode, LinearImagesMustBeSixteenBitSingleChannel) {
  testing::TempDir dir;
  cv::imwrite((dir / "ok.png").string(), pattern(8, 8));
  RawFrame f = loadLinearImage(dir / "ok.png", 0.5, 0, 65535, Cfa::kMono);
  EXPECT_EQ(f.exposure_s, 0.5);
  cv::imwrite((dir / "eight.png").string(), cv::Mat(8, 8, CV_8UC1, cv::Scalar(3)));
  EXPECT_THROW(loadLinearImage(dir / "eight.png", 1, 0, 255, Cfa::kMono), InputError);
}

std::string linearImageError(const std::filesystem::path& file) {
  try {
    loadLinearImage(file, 1, 0, 65535, Cfa::kMono);
  } catch (const InputError& e) {
    return e.what();
  }
  return "no error";
}

// Only PNG and TIFF reach OpenCV (whose imread would try its DICOM and GDAL decoders on anything
// else), and a PNG header cannot claim more pixels than its file could hold.
TEST(RawDecode, LinearImagesAreCheckedBeforeDecoding) {
  testing::TempDir dir;
  std::ofstream(dir / "x.tif") << "II\x88\x88 not a TIFF";
  EXPECT_EQ(linearImageError(dir / "x.tif"), (dir / "x.tif").string() + ": not a PNG or TIFF file");
  cv::imwrite((dir / "big.png").string(), pattern(8, 8));
  std::string bytes;
  {
    std::ifstream in(dir / "big.png", std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  bytes.replace(16, 8, std::string("\x00\x01\x86\xa0\x00\x01\x86\xa0", 8));  // 100000 x 100000
  { std::ofstream(dir / "big.png", std::ios::binary) << bytes; }
  EXPECT_NE(linearImageError(dir / "big.png").find("corrupt PNG header: 100000 x 100000 pixels cannot fit"),
            std::string::npos);
}

}  // namespace
}  // namespace flarekit::acquisition
