#pragma once
// Helpers for fit/'s tests (header-only; not part of the library).

#include <cmath>
#include <numbers>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "common/image.h"
#include "fit/frames.h"
#include "model/ghost_shape.h"
#include "model/model_renderer.h"

namespace flarekit::fit::testing {

// A one-channel ghost with the shape the fit tests share: centre (x, y), half-widths l, r, height
// h (px), border and inside intensity ib, ii; curvatures 0.5 / 0.6, fall-offs 6 px inside and
// 3 px outside, exponents 1.5.
inline model::GhostParameters ghost(double x, double y, double l, double r, double h, double ib,
                                    double ii) {
  model::GhostParameters g;
  g.center_x = x;
  g.center_y = y;
  g.left = l;
  g.right = r;
  g.height = h;
  g.curvature_left = 0.5;
  g.curvature_right = 0.6;
  g.border = {ib, 0, 0};
  g.inside = {ii, 0, 0};
  g.inside_falloff = 6;
  g.inside_exponent = 1.5;
  g.outside_falloff = 3;
  g.outside_exponent = 1.5;
  return g;
}

// A pan capture in memory, as a rig makes it: the light (a disc that clips) on the horizon at
// x = axis_x − focal_px·tan(θ − θ0), and ghosts mirror-symmetric about the horizon whose centres
// are odd about the optical zero, Mx = axis_x + rate·(light's x − axis_x), of fixed size.
struct PanScene {
  cv::Size size{320, 200};
  double axis_x = 160.4, horizon_y = 100.3;  // the optical axis, pixels
  double angle_zero_deg = 0.3;               // θ0
  double focal_px = 1000;
  double light_radius_px = 4;
  // Clipped: the light's disc of light_radius_px at 1, masked. Not clipped (a merged HDR frame):
  // a Gaussian of that σ, peak light_peak, valid everywhere.
  bool light_clipped = true;
  double light_peak = 0.5;
  struct Ghost {
    double rate = 1, radius_px = 20, border = 0.01, inside = 0.005;
    double height_ratio = 1;  // its half-height over its half-width
    double falloff_ratio = 0.4;  // its inside fall-off Fi over its half-width
  };
  std::vector<Ghost> ghosts = {{1.6, 30, 0.02, 0.01}, {-0.8, 45, 0.01, 0.015}};
  double noise = 1e-4;

  double lightX(double angle_deg) const {
    return axis_x - focal_px * std::tan((angle_deg - angle_zero_deg) * std::numbers::pi / 180);
  }
  model::GhostParameters ghostAt(size_t g, double angle_deg) const {
    model::GhostParameters p;
    p.center_x = axis_x + ghosts[g].rate * (lightX(angle_deg) - axis_x);
    p.center_y = horizon_y;
    p.left = p.right = ghosts[g].radius_px;
    p.height = ghosts[g].height_ratio * ghosts[g].radius_px;
    p.border = {ghosts[g].border, 0, 0};
    p.inside = {ghosts[g].inside, 0, 0};
    p.inside_falloff = ghosts[g].falloff_ratio * ghosts[g].radius_px;
    p.outside_falloff = 1.5;
    return p;
  }
  // Frames at `angles_deg`, one channel, with their valid masks (the light's disc clipped).
  FrameStack stack(const std::vector<double>& angles_deg) const {
    FrameStack s;
    s.size = size;
    s.channels = 1;
    cv::RNG rng(7);
    for (size_t i = 0; i < angles_deg.size(); ++i) {
      Frame f;
      f.index = static_cast<int>(i);
      f.angle_deg = angles_deg[i];
      std::vector<model::GhostParameters> all;
      for (size_t g = 0; g < ghosts.size(); ++g) all.push_back(ghostAt(g, angles_deg[i]));
      f.image = model::renderGhosts(all, size, 1);
      cv::Mat noise_image(size, CV_32F);
      rng.fill(noise_image, cv::RNG::NORMAL, 0, noise);
      f.image += noise_image + 2 * noise;
      f.valid = cv::Mat(size, CV_8U, cv::Scalar(255));
      const cv::Point2d light(lightX(angles_deg[i]), horizon_y);
      for (int y = 0; y < size.height; ++y)
        for (int x = 0; x < size.width; ++x) {
          const double r = std::hypot(x + 0.5 - light.x, y + 0.5 - light.y);
          if (!light_clipped) {
            f.image.at<float>(y, x) += static_cast<float>(light_peak * std::exp(-0.5 * r * r / (light_radius_px * light_radius_px)));
          } else if (r <= light_radius_px) {
            f.image.at<float>(y, x) = 1;
            f.valid.at<uchar>(y, x) = 0;
          }
        }
      s.frames.push_back(std::move(f));
    }
    s.info.image_size = size;
    s.info.angle_step_deg = angles_deg.size() > 1 ? angles_deg[1] - angles_deg[0] : 1;
    return s;
  }
};

inline std::vector<double> anglesFrom(double first, double last, double step) {
  std::vector<double> a;
  for (int i = 0; first + i * step <= last + 1e-9; ++i) a.push_back(first + i * step);
  return a;
}

// The luminance (Rec. 709) of an RGGB mosaic of `photosites` demosaiced bilinearly, as the
// simulated camera does (acquisition/hdr_merge.h demosaicBilinear): each colour the mean of its
// sites in the 3×3 neighbourhood, a site's own value where it has that colour.
inline cv::Mat bayerLuminance(const cv::Mat& photosites) {
  auto colour = [](int y, int x) { return y % 2 == 0 ? (x % 2 == 0 ? 0 : 1) : (x % 2 == 0 ? 1 : 2); };
  cv::Mat rgb(photosites.size(), CV_32FC3);
  for (int y = 0; y < photosites.rows; ++y)
    for (int x = 0; x < photosites.cols; ++x) {
      double sum[3] = {0, 0, 0};
      int count[3] = {0, 0, 0};
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || yy >= photosites.rows || xx < 0 || xx >= photosites.cols) continue;
          const int c = colour(yy, xx);
          if (c == colour(y, x) && (dx != 0 || dy != 0)) continue;
          sum[c] += photosites.at<float>(yy, xx);
          ++count[c];
        }
      for (int c = 0; c < 3; ++c) rgb.at<cv::Vec3f>(y, x)[c] = static_cast<float>(sum[c] / count[c]);
    }
  return luminance(rgb);
}

}  // namespace flarekit::fit::testing
