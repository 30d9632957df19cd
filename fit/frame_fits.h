#pragma once
// The per-frame fits of a capture fit (`flarekit fit --report DIR` writes DIR/frame_fits.json):
// every ghost as it was fitted in each frame, before the polynomials summarise its track (Walch
// et al. 2018 §3.3.1 against §3.3.2). `flarekit fit-eval` measures them like a model, so a person
// can tell what the frames' fits reach from what the polynomials keep of them.
//
//   {
//     "format": "flarekit.frame-fits", "version": 1,
//     "image_width": 640, "image_height": 427, "channels": 1,
//     "frames": [
//       { "angle_deg": 0.2,
//         "ghosts": [ { "id": 3, "parameters": { "Mx": 301.5, "My": 213.5, ..., "Eo": 1.2 } } ],
//         "pedestal": { "P00": 4e-5, "P10": -1e-5, ..., "P02": 0.0 } }      // optional
//     ]
//   }
//
// Parameters are named as in the model file (model/ghost_shape.h parameterName) and must be valid
// ghost parameters; the pedestal's terms as model/pedestal.h names them, all present when it is;
// frames are in ascending angle order, each angle once.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "fit/flare_fitter.h"
#include "model/flare_model.h"

namespace flarekit::fit {

inline constexpr char kFrameFitsFormat[] = "flarekit.frame-fits";
inline constexpr int kFrameFitsVersion = 1;

struct FrameFits {
  cv::Size image_size;  // capture pixels
  int channels = 1;     // 1 or 3
  struct FittedFrame {
    double angle_deg = 0;
    std::vector<model::GhostAtAngle> ghosts;
    model::Pedestal pedestal;  // empty: none
  };
  std::vector<FittedFrame> frames;  // ascending angle

  // The fits of every fitted frame of `result` (stage 5, fit/frame_fit.h), in angle order.
  static FrameFits fromResult(const FitResult& result, cv::Size image_size, int channels);
  // InputError naming the file and key on a malformed file.
  static FrameFits load(const std::filesystem::path& path);
  static FrameFits parse(const std::string& text, const std::string& file);
  static FrameFits fromJson(const ConfigNode& root);
  nlohmann::json toJson() const;
  void save(const std::filesystem::path& path) const;  // atomically

  // The fitted frame at `angle_deg` (within 1e-9°), or nullptr when that frame was not fitted.
  const FittedFrame* at(double angle_deg) const;
};

}  // namespace flarekit::fit
