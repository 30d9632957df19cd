// Writes the example scene's background (stage_background.exr): what the scene's camera sees
// without flare, in the units of the overlay (predict/scene.h): a dim stage under a dark sky, a
// few set pieces, and each light's own image where it falls in the frame.
//
//   build/bin/flarekit_make_stage_background predict/examples/stage.json predict/examples/stage_background.exr
#include <cmath>
#include <iostream>

#include <opencv2/imgproc.hpp>

#include "common/exr.h"
#include "predict/geometry.h"
#include "predict/scene.h"

int main(int argc, char** argv) {
  using namespace flarekit;
  if (argc != 3) {
    std::cerr << "usage: " << argv[0] << " SCENE.json OUT.exr\n";
    return 2;
  }
  try {
    predict::Scene scene = predict::loadScene(argv[1]);
    const cv::Size size{960, 640};
    cv::Mat bg(size, CV_32FC3);
    for (int y = 0; y < size.height; ++y) {
      const double v = static_cast<double>(y) / size.height;
      // Night sky above the horizon (y = 0.5), a warm-lit floor below.
      const cv::Vec3f sky(0.006f + 0.01f * static_cast<float>(v), 0.008f + 0.012f * static_cast<float>(v), 0.02f + 0.02f * static_cast<float>(v));
      const cv::Vec3f floor(0.09f, 0.07f, 0.05f);
      bg.row(y).setTo(v < 0.5 ? cv::Scalar(sky[0], sky[1], sky[2]) : cv::Scalar(floor[0], floor[1], floor[2]) * (0.6 + v));
    }
    // Set pieces: a back wall flat, two towers, a riser.
    cv::rectangle(bg, cv::Rect(200, 180, 560, 140), cv::Scalar(0.05, 0.045, 0.04), cv::FILLED);
    cv::rectangle(bg, cv::Rect(90, 120, 70, 260), cv::Scalar(0.12, 0.1, 0.08), cv::FILLED);
    cv::rectangle(bg, cv::Rect(800, 140, 60, 240), cv::Scalar(0.12, 0.1, 0.08), cv::FILLED);
    cv::rectangle(bg, cv::Rect(300, 330, 360, 40), cv::Scalar(0.3, 0.25, 0.2), cv::FILLED);
    // Each light's own image: a small disc, far brighter than anything else.
    const predict::AngleRange all{-90, 90};
    for (const auto& light : scene.lights) {
      const auto g = predict::lightGeometry(light, scene.camera.pose, scene.camera, all, size);
      if (!g.in_frame) continue;
      const auto& c = light.color;
      cv::circle(bg, cv::Point(static_cast<int>(g.image_px.x), static_cast<int>(g.image_px.y)), 4,
                 cv::Scalar(60 * c[0], 60 * c[1], 60 * c[2]), cv::FILLED, cv::LINE_AA);
    }
    writeExr(argv[2], bg, {{"flarekit.scene", std::string(argv[1])}}, {.pixel_type = ExrPixelType::kHalf});
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  return 0;
}
