// Writes the binary seeds of the fuzz corpora that cannot be copied from the repository: small
// EXR files (every layout and attribute type FlareKit writes), EXR stack frames and truth files,
// the manifests of the small simulated capture (fuzz/capture_support.h), DNGs, 16-bit PNG/TIFF.
// Deterministic; run once when the writers change and commit the result (fuzz/README.md):
//
//   build/bin/flarekit_fuzz_make_seeds fuzz/corpus
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "acquisition/dng_writer.h"
#include "common/exr.h"
#include "fuzz/capture_support.h"
#include "fuzz/fuzz_support.h"

using namespace flarekit;
namespace fs = std::filesystem;

namespace {

cv::Mat ramp(int w, int h, int type, double scale) {
  cv::Mat m(h, w, CV_32FC1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<float>(y, x) = static_cast<float>(scale * (x + w * y) / (w * h));
  if (type == CV_32FC3) {
    cv::Mat c;
    cv::merge(std::vector<cv::Mat>{m, m * 0.5, m * 0.25}, c);
    return c;
  }
  return m;
}

void copyFile(const fs::path& from, const fs::path& to) {
  fs::create_directories(to.parent_path());
  fs::copy_file(from, to, fs::copy_options::overwrite_existing);
}

void exrSeeds(const fs::path& dir) {
  fs::create_directories(dir);
  writeExr(dir / "y_float_zip.exr", ramp(16, 16, CV_32FC1, 2.0));
  ExrWriteOptions half_raw;
  half_raw.pixel_type = ExrPixelType::kHalf;
  half_raw.compress = false;
  writeExr(dir / "rgb_half_raw.exr", ramp(16, 16, CV_32FC3, 1.0), {}, half_raw);
  // Layers and every attribute type.
  ExrImage e;
  e.layers.push_back({"", ramp(16, 16, CV_32FC3, 4.0)});
  e.layers.push_back({"ghost.3", ramp(16, 16, CV_32FC1, 0.5)});
  e.layers.push_back({"ghost.7", ramp(16, 16, CV_32FC3, 0.25)});
  cv::Mat sat = cv::Mat::zeros(16, 16, CV_32FC1);
  sat.at<float>(3, 4) = 1;
  e.layers.push_back({"saturated", sat});
  e.attributes = {{"flarekit.angle_deg", 2.5},
                  {"flarekit.iso", 100},
                  {"flarekit.f_number", 8.0f},
                  {"flarekit.camera", std::string("FlareKit fuzz")},
                  {"flarekit.exposures_s", std::vector<float>{0.25f, 1.0f}},
                  {"flarekit.names", std::vector<std::string>{"a", "b"}},
                  {"flarekit.optical_axis_offset_px", cv::Vec2d(1.5, -2)},
                  {"flarekit.size", cv::Vec2i(16, 16)},
                  {"flarekit.centroid_px", cv::Vec2f(3, 4)},
                  {"flarekit.v3f", cv::Vec3f(1, 2, 3)},
                  {"flarekit.v3d", cv::Vec3d(1, 2, 3)}};
  writeExr(dir / "layers_attributes.exr", e);
  cv::Mat nonfinite = ramp(8, 8, CV_32FC1, 1.0);
  nonfinite.at<float>(1, 1) = std::numeric_limits<float>::quiet_NaN();
  nonfinite.at<float>(2, 2) = std::numeric_limits<float>::infinity();
  writeExr(dir / "nonfinite.exr", nonfinite);
}

void exrStackSeeds(const fs::path& dir) {
  fs::create_directories(dir);
  cv::Mat sat = cv::Mat::zeros(16, 16, CV_32FC1);
  sat.at<float>(5, 5) = 1;
  ExrImage frame;
  frame.layers.push_back({"", ramp(16, 16, CV_32FC1, 3.0)});
  frame.layers.push_back({"saturated", sat});
  frame.attributes = {{"flarekit.angle_deg", 1.0}, {"flarekit.exposure_s", 1.0},
                      {"flarekit.units", std::string("electrons/s")}};
  writeExr(dir / "frame_mono.exr", frame);
  ExrImage rgb;
  rgb.layers.push_back({"", ramp(16, 16, CV_32FC3, 3.0)});
  rgb.attributes = {{"flarekit.angle_deg", 0.5f}, {"flarekit.pixel_pitch_um", 4.0},
                    {"flarekit.focal_length_mm", 50.0}, {"flarekit.cfa", std::string("RGGB")}};
  writeExr(dir / "frame_rgb.exr", rgb);
  ExrImage truth;
  truth.layers.push_back({"", ramp(16, 16, CV_32FC1, 1.0)});
  truth.layers.push_back({"ghost.1", ramp(16, 16, CV_32FC1, 0.5)});
  truth.layers.push_back({"ghost.2", ramp(16, 16, CV_32FC1, 0.25)});
  truth.attributes = {{"flarekit.angle_deg", 1.0}, {"flarekit.ghost.1.energy", 2.0},
                      {"flarekit.ghost.1.centroid_px", cv::Vec2d(4, 5)}};
  ExrWriteOptions half;
  half.pixel_type = ExrPixelType::kHalf;
  writeExr(dir / "truth_ghosts.exr", truth, half);
}

void captureSeeds(const fs::path& manifest_dir, const fs::path& resume_dir) {
  const fs::path work = fuzz::scratchDir() / "seeds";
  struct Case {
    const char* name;
    int stop_after;
  } cases[] = {{"complete.json", -1}, {"interrupted_after_2.json", 2}, {"started.json", 0}};
  for (const Case& c : cases) {
    const fs::path cap = work / c.name;
    fuzz::makeSmallCapture(cap, c.stop_after);
    copyFile(cap / "manifest.json", manifest_dir / c.name);
    copyFile(cap / "manifest.json", resume_dir / c.name);
  }
}

void rawSeeds(const fs::path& dir) {
  fs::create_directories(dir);
  cv::Mat data(16, 16, CV_16UC1);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) data.at<uint16_t>(y, x) = static_cast<uint16_t>(256 + 37 * x + 101 * y);
  acquisition::RawFrame spec;
  spec.data = data;
  spec.cfa = acquisition::Cfa::kRGGB;
  spec.black_level = 256;
  spec.white_level = 4095;
  spec.exposure_s = 0.25;
  spec.iso = 200;
  spec.f_number = 5.6;
  acquisition::writeDng(dir / "rggb_16x16.dng", spec, "FlareKit Fuzz");
  spec.cfa = acquisition::Cfa::kGBRG;
  acquisition::writeDng(dir / "gbrg_16x16.dng", spec);
}

void linearSeeds(const fs::path& dir) {
  fs::create_directories(dir);
  cv::Mat data(16, 16, CV_16UC1);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) data.at<uint16_t>(y, x) = static_cast<uint16_t>(64 + 13 * x + 200 * y);
  cv::imwrite((dir / "mono16.png").string(), data);
  cv::imwrite((dir / "mono16.tif").string(), data);
  cv::imwrite((dir / "gray8.png").string(), cv::Mat(8, 8, CV_8UC1, cv::Scalar(3)));
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_FOLDER (fuzz/corpus)\n", argv[0]);
    return 2;
  }
  const fs::path corpus = argv[1];
  fuzz::quietLogs();
  exrSeeds(corpus / "exr");
  exrStackSeeds(corpus / "exr_stack");
  captureSeeds(corpus / "capture_manifest", corpus / "capture_resume");
  rawSeeds(corpus / "raw_decode");
  linearSeeds(corpus / "linear_image");
  std::printf("seeds written under %s\n", corpus.c_str());
  return 0;
}
