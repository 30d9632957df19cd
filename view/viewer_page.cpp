#include "view/viewer_page.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "common/image.h"
#include "view/flare_shader.h"

namespace flarekit::view {

// view/viewer.html, embedded by CMake (viewer_html.cpp).
extern const char* const kViewerHtml;

bool ViewerOptions::IsValid(std::string* error) const {
  if (!std::isnan(theta_deg) && !std::isfinite(theta_deg)) {
    if (error) *error = "theta_deg must be finite (or NaN for the model's middle)";
    return false;
  }
  return true;
}

double middleAngle(const model::FlareModel& m) {
  if (m.ghosts.empty()) return 0;
  double lo = m.ghosts.front().angle_min_deg, hi = m.ghosts.front().angle_max_deg;
  for (const auto& g : m.ghosts) {
    lo = std::min(lo, g.angle_min_deg);
    hi = std::max(hi, g.angle_max_deg);
  }
  return 0.5 * (lo + hi);
}

double viewerExposureScale(const model::FlareModel& m) {
  if (m.ghosts.empty()) return 1;
  return autoExposureScale(m.render(middleAngle(m)));
}

std::string viewerPage(const model::FlareModel& m, const ViewerOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw std::invalid_argument("ViewerOptions: " + why);
  FlareShaderOptions shader;
  shader.source_name = options.source_name;
  const nlohmann::json data = {
      {"model", m.toJson()},
      {"shader", flareShader(m, shader)},
      {"exposure_scale", viewerExposureScale(m)},
      {"theta_deg", std::isnan(options.theta_deg) ? middleAngle(m) : options.theta_deg}};
  // Inside <script>, "</" could close the element: JSON allows "<\/" for it.
  std::string text = data.dump();
  for (size_t at = 0; (at = text.find("</", at)) != std::string::npos; at += 3) text.replace(at, 2, "<\\/");
  std::string page = kViewerHtml;
  const std::string marker = "FLAREKIT_DATA";
  page.replace(page.find(marker), marker.size(), text);
  return page;
}

}  // namespace flarekit::view
