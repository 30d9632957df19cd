#pragma once
// The real-time viewer of Walch et al. 2018 §3.4: one self-contained HTML page that draws a flare
// model with WebGL2 while the pointer moves the light (θ and φ through the captured lens's focal
// length), a slider or the wheel sets the exposure in EV, a list toggles and solos ghosts, and a
// chosen PNG or JPEG shows under the flare. The address's hash holds the view
// (#theta=8&phi=-20&ev=0; ui=0 hides the controls). The page draws with flare_shader.h's library,
// each ghost as a quad over its box grown by Fo, and tone-maps as common/image.h does.

#include <limits>
#include <string>

#include "model/flare_model.h"

namespace flarekit::view {

struct ViewerOptions {
  // Field angle θ of the first view when the address does not set one, degrees; NaN: the middle
  // of the model's angle range.
  double theta_deg = std::numeric_limits<double>::quiet_NaN();
  // Shown in the page's shader comment: where the model came from.
  std::string source_name;

  bool IsValid(std::string* error) const;
};

// The linear scale of exposure 0 EV: common/image.h's automatic exposure of the model drawn at the
// middle of its angle range (its 90th percentile to mid-grey), 1 for a model without ghosts.
double viewerExposureScale(const model::FlareModel& model);

// The middle of the model's angle range (0 without ghosts), degrees.
double middleAngle(const model::FlareModel& model);

// The page for `model` (valid). Throws std::invalid_argument for invalid options.
std::string viewerPage(const model::FlareModel& model, const ViewerOptions& options = {});

}  // namespace flarekit::view
