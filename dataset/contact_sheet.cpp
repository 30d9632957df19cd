#include "dataset/contact_sheet.h"

#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/input_file.h"
#include "dataset/flare_export.h"

namespace flarekit::dataset {
namespace {

namespace fs = std::filesystem;

cv::Mat readPicture(const fs::path& p, int flags) {
  checkInputFile(p);
  cv::Mat m = cv::imread(p.string(), flags);
  if (m.empty()) throw InputError(p.string(), "is not a readable PNG");
  return m;
}

// A distinct, saturated colour for the k-th mask (golden-angle hues), BGR.
cv::Vec3b maskColour(size_t k) {
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(static_cast<double>((k * 111) % 180), 230, 255)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  return bgr.at<cv::Vec3b>(0, 0);
}

}  // namespace

bool ContactSheetOptions::IsValid(std::string* error) const {
  if (samples < 1 || samples > 1000 || tile_width_px < 32 || tile_width_px > 4096) {
    if (error) *error = "the sheet needs 1 to 1000 samples and tiles 32 to 4096 pixels wide";
    return false;
  }
  return true;
}

cv::Mat contactSheet(const fs::path& set_dir, const fs::path& jsonl, const ContactSheetOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw InputError("contact sheet: " + why);
  std::istringstream lines(readInputFile(jsonl));
  std::vector<nlohmann::json> samples;
  for (std::string line; static_cast<int>(samples.size()) < o.samples && std::getline(lines, line);) {
    try {
      samples.push_back(nlohmann::json::parse(line));
    } catch (const nlohmann::json::exception&) {
      throw InputError(jsonl.string(), "line " + std::to_string(samples.size() + 1) + " is not JSON");
    }
  }
  if (samples.empty()) throw InputError(jsonl.string(), "has no samples");

  const int caption = 22, gap = 4;
  cv::Mat rows;
  for (const auto& j : samples) {
    const std::string name = j.at("name").get<std::string>(), png = name + ".png";
    std::vector<cv::Mat> tiles = {readPicture(set_dir / kCompoundFolder / png, cv::IMREAD_COLOR),
                                  readPicture(set_dir / kFlareFolder / png, cv::IMREAD_COLOR),
                                  readPicture(set_dir / kLightFolder / png, cv::IMREAD_COLOR)};
    cv::Mat masks(tiles[0].size(), CV_8UC3, cv::Scalar(40, 40, 40));
    const auto ids = j.at("ghost_ids").get<std::vector<int>>();
    const auto pixels = j.at("mask_pixels").get<std::vector<long long>>();
    // Each mask filled dimly, then every outline bright on top, so overlapping masks stay apart.
    std::vector<std::pair<cv::Mat, cv::Vec3b>> shown;
    for (size_t k = 0; k < ids.size() && k < pixels.size(); ++k) {
      if (pixels[k] == 0) continue;
      const cv::Mat m = readPicture(set_dir / kMaskFolder / name / ("ghost_" + std::to_string(ids[k]) + ".png"),
                                    cv::IMREAD_GRAYSCALE);
      if (m.size() != masks.size()) throw InputError(set_dir.string(), "mask of " + name + " differs in size");
      shown.emplace_back(m, maskColour(k));
      masks.setTo(cv::Scalar(shown.back().second) * 0.4, m);
    }
    for (const auto& [m, colour] : shown) {
      cv::Mat inner, edge;
      cv::erode(m, inner, cv::Mat(), cv::Point(-1, -1), std::max(1, m.cols / 128));
      cv::subtract(m, inner, edge);
      masks.setTo(cv::Scalar(colour), edge);
    }
    tiles.push_back(masks);
    const int tw = o.tile_width_px, th = static_cast<int>(std::lround(double(tw) * tiles[0].rows / tiles[0].cols));
    cv::Mat row(th + caption, static_cast<int>(tiles.size()) * (tw + gap) - gap, CV_8UC3, cv::Scalar(24, 24, 24));
    for (size_t k = 0; k < tiles.size(); ++k) {
      cv::Mat small;
      cv::resize(tiles[k], small, {tw, th}, 0, 0, cv::INTER_AREA);
      small.copyTo(row(cv::Rect(static_cast<int>(k) * (tw + gap), caption, tw, th)));
    }
    const std::string model = fs::path(j.at("model").get<std::string>()).filename().string();
    const std::string text = name + "  " + model + "  theta " + cv::format("%.2f", j.at("theta_deg").get<double>()) +
                             "  roll " + cv::format("%.0f", j.at("roll_deg").get<double>()) + "  EV " +
                             cv::format("%+.2f", j.at("exposure_ev").get<double>()) + "  ghosts " +
                             std::to_string(ids.size());
    cv::putText(row, text, {4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(220, 220, 220), 1, cv::LINE_AA);
    if (rows.empty())
      rows = row;
    else
      cv::vconcat(std::vector<cv::Mat>{rows, cv::Mat(gap, row.cols, CV_8UC3, cv::Scalar(0, 0, 0)), row}, rows);
  }
  // Column titles.
  const int tw = o.tile_width_px;
  cv::Mat header(caption, rows.cols, CV_8UC3, cv::Scalar(0, 0, 0));
  const char* titles[] = {"Compound_Flare", "Flare", "Light_Source", "Mask (one colour per ghost)"};
  for (int k = 0; k < 4; ++k)
    cv::putText(header, titles[k], {k * (tw + gap) + 4, 16}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 220, 255), 1,
                cv::LINE_AA);
  cv::Mat sheet;
  cv::vconcat(header, rows, sheet);
  return sheet;
}

}  // namespace flarekit::dataset
