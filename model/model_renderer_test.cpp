#include "model/model_renderer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "model/intensity.h"

namespace flarekit::model {
namespace {

GhostParameters ghostAt(double x, double y, double r, int channels = 1) {
  GhostParameters g;
  g.channels = channels;
  g.center_x = x;
  g.center_y = y;
  g.left = r * 1.1;
  g.right = r * 0.8;
  g.height = r;
  g.curvature_left = 0.45;
  g.curvature_right = 0.7;
  g.border = {1.0, 0.7, 0.4};
  g.inside = {0.3, 0.5, 0.2};
  g.inside_falloff = 0.3 * r;
  g.inside_exponent = 1.6;
  g.outside_falloff = 4;
  g.outside_exponent = 1.3;
  return g;
}

TEST(ModelRenderer, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(RenderOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(ViewTransform{}.IsValid(&error)) << error;
  EXPECT_TRUE(ViewTransform{}.isIdentity());
  RenderOptions bad;
  bad.block_size = 0;
  EXPECT_FALSE(bad.IsValid(&error));
}

TEST(ModelRenderer, EveryPixelIsTheModelAtItsCentre) {
  // The block classification and the tiles must not change any pixel: compare with the per-pixel
  // reference, for grey and RGB, ghosts overlapping, one reaching over the image edge.
  for (int channels : {1, 3}) {
    std::vector<GhostParameters> ghosts = {ghostAt(40, 30, 18, channels), ghostAt(55, 38, 9, channels),
                                           ghostAt(95, 10, 25, channels)};
    const cv::Size size(110, 70);
    const cv::Mat image = renderGhosts(ghosts, size, channels);
    ASSERT_EQ(image.type(), CV_MAKETYPE(CV_32F, channels));
    double worst = 0, total = 0;
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        double sum[3] = {0, 0, 0};
        for (const auto& g : ghosts) {
          double v[3];
          evaluateGhost(g, {x + 0.5, y + 0.5}, v, nullptr);
          for (int c = 0; c < channels; ++c) sum[c] += v[c];
        }
        for (int c = 0; c < channels; ++c) {
          worst = std::max(worst, std::abs(image.ptr<float>(y)[x * channels + c] - sum[c]));
          total += sum[c];
        }
      }
    EXPECT_LE(worst, 1e-6);
    EXPECT_GT(total, 100);  // the ghosts are really there
  }
}

TEST(ModelRenderer, FastPathMatchesThePerPixelReferenceOnRandomGhosts) {
  // The renderer's per-pixel fast path (Newton from the row's previous nearest points, certified)
  // and its fall-backs must give the per-pixel reference everywhere, also for shapes that make it
  // decline: corners (Cl or Cr = 0), boxes (= 1), thin and flat ghosts, fall-off ranges deeper
  // than the outline's radius of curvature, exponents over their whole range, and rolled views.
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> unit(0, 1);
  auto log_uniform = [&](double lo, double hi) { return lo * std::pow(hi / lo, unit(rng)); };
  auto curvature = [&] {
    const double u = unit(rng);
    return u < 0.15 ? 0.0 : u > 0.85 ? 1.0 : unit(rng);
  };
  double worst = 0;
  long pixels = 0;
  for (int trial = 0; trial < 60; ++trial) {
    GhostParameters g;
    g.center_x = 50 * unit(rng);
    g.center_y = 40 * unit(rng);
    g.left = log_uniform(0.5, 50);
    g.right = log_uniform(0.5, 50);
    g.height = log_uniform(0.5, 50);
    g.curvature_left = curvature();
    g.curvature_right = curvature();
    g.border = {log_uniform(0.1, 2), 0, 0};
    g.inside = {2 * unit(rng), 0, 0};
    g.inside_falloff = log_uniform(0.1, 40);
    g.outside_falloff = log_uniform(0.1, 8);
    g.inside_exponent = log_uniform(0.1, 10);
    g.outside_exponent = log_uniform(0.1, 10);
    ASSERT_TRUE(isValid(g));
    const ViewTransform view = trial % 4 == 3 ? ViewTransform::roll(unit(rng) * 6.28, {25, 20}) : ViewTransform{};
    const cv::Rect roi = ghostPixelBounds(g, view);
    const cv::Mat image = renderGhosts(std::vector<GhostParameters>{g}, roi, 1, {}, view);
    for (int y = 0; y < roi.height; ++y)
      for (int x = 0; x < roi.width; ++x) {
        double v[1];
        evaluateGhost(g, {roi.x + x + 0.5, roi.y + y + 0.5}, v, nullptr, {}, view);
        const double error = std::abs(image.at<float>(y, x) - v[0]);
        worst = std::max(worst, error);
        ASSERT_LE(error, 1e-6) << "trial " << trial << " pixel " << roi.x + x << "," << roi.y + y
                               << " L " << g.left << " R " << g.right << " h " << g.height << " Cl "
                               << g.curvature_left << " Cr " << g.curvature_right << " Fi "
                               << g.inside_falloff << " Fo " << g.outside_falloff;
        ++pixels;
      }
  }
  EXPECT_GT(pixels, 40000);
  std::ostringstream figures;
  figures << std::scientific << worst << " over " << pixels << " pixels";
  RecordProperty("worst_difference", figures.str());
}

TEST(ModelRenderer, RegionOfInterestEqualsTheCropAndThreadsDoNotMatter) {
  std::vector<GhostParameters> ghosts = {ghostAt(60, 50, 30), ghostAt(120, 70, 12), ghostAt(20, 90, 40)};
  const cv::Mat full = renderGhosts(ghosts, cv::Size(200, 150), 1);
  const cv::Rect roi(37, 21, 91, 77);
  const cv::Mat part = renderGhosts(ghosts, roi, 1);
  EXPECT_EQ(cv::norm(part, full(roi), cv::NORM_INF), 0.0);
  RenderOptions serial;
  serial.parallel = false;
  serial.tile_size = 16;
  EXPECT_EQ(cv::norm(renderGhosts(ghosts, cv::Size(200, 150), 1, serial), full, cv::NORM_INF), 0.0);
  // addGhosts accumulates.
  cv::Mat twice = full.clone();
  addGhosts(ghosts, cv::Rect(0, 0, 200, 150), twice);
  EXPECT_LE(cv::norm(twice, 2 * full, cv::NORM_INF), 1e-6);
}

TEST(ModelRenderer, TouchesOnlyPixelsWithinReach) {
  const GhostParameters g = ghostAt(70, 60, 20);
  const cv::Rect reach = ghostPixelBounds(g);
  cv::Mat image(140, 160, CV_32FC1, cv::Scalar(-1));  // sentinel: untouched pixels stay −1
  addGhosts(std::vector<GhostParameters>{g}, cv::Rect(0, 0, 160, 140), image);
  int lit = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const float v = image.at<float>(y, x);
      if (!reach.contains({x, y})) {
        EXPECT_EQ(v, -1.0f) << x << "," << y;
      }
      if (v > -1.0f) ++lit;
      // The model is zero farther than Fo from the box, so the reach is not too tight either.
      const double dx = std::max({g.center_x - g.left - (x + 0.5), 0.0, x + 0.5 - g.center_x - g.right});
      const double dy = std::max({g.center_y - g.height - (y + 0.5), 0.0, y + 0.5 - g.center_y - g.height});
      if (std::hypot(dx, dy) < g.outside_falloff - 0.5) {
        EXPECT_TRUE(reach.contains({x, y}));
      }
    }
  EXPECT_GT(lit, 1000);
  // A ghost far outside the region renders nothing.
  const cv::Mat empty = renderGhosts(std::vector<GhostParameters>{ghostAt(5000, 5000, 20)}, cv::Size(64, 64), 1);
  EXPECT_EQ(cv::countNonZero(empty), 0);
}

TEST(ModelRenderer, RejectsMismatchedChannelsAndInvalidGhosts) {
  std::vector<GhostParameters> rgb = {ghostAt(10, 10, 5, 3)};
  EXPECT_THROW(renderGhosts(rgb, cv::Size(20, 20), 1), std::invalid_argument);
  GhostParameters bad = ghostAt(10, 10, 5);
  bad.left = -1;
  EXPECT_THROW(renderGhosts(std::vector<GhostParameters>{bad}, cv::Size(20, 20), 1), std::invalid_argument);
}

// Central differences of the per-pixel model (in double), at pixel centres where the model is
// smooth in the parameter: away from d = 0, d = −Fi, d = Fo, and the medial axis (the distance
// must move by about the analytic amount for two step sizes).
TEST(ModelRenderer, DerivativeImagesMatchCentralDifferences) {
  for (int channels : {1, 3}) {
    std::vector<GhostParameters> ghosts = {ghostAt(30, 28, 14, channels), ghostAt(48, 34, 9, channels)};
    ghosts[1].curvature_left = 0.9;
    ghosts[1].outside_falloff = 6;
    ghosts[1].outside_exponent = 0.7;
    const cv::Rect roi(5, 4, 60, 50);
    const RenderedGhosts r = renderGhostsWithDerivatives(ghosts, roi, channels);
    ASSERT_EQ(r.derivatives.size(), ghosts.size());
    EXPECT_LE(cv::norm(r.image, renderGhosts(ghosts, roi, channels), cv::NORM_INF), 0.0);
    const int n = parameterCount(channels);
    int compared = 0, nonzero = 0;
    for (size_t gi = 0; gi < ghosts.size(); ++gi) {
      const GhostParameters& g = ghosts[gi];
      const GhostDerivativeImages& d = r.derivatives[gi];
      ASSERT_EQ(static_cast<int>(d.images.size()), n);
      EXPECT_EQ(d.rect, ghostPixelBounds(g) & roi);
      const std::vector<double> base = toParameterVector(g);
      for (int k = 0; k < n; ++k) {
        // The scale of this derivative over the ghost, for the relative comparison's floor.
        double peak = 0;
        cv::minMaxLoc(cv::abs(d.images[k].reshape(1)), nullptr, &peak);
        for (int y = d.rect.y; y < d.rect.y + d.rect.height; ++y)
          for (int x = d.rect.x; x < d.rect.x + d.rect.width; ++x) {
            const cv::Point2d p(x + 0.5, y + 0.5);
            const double dist = signedDistance(g, p);
            const double margin = 0.02;
            if (std::abs(dist) < margin || std::abs(dist + g.inside_falloff) < margin ||
                std::abs(dist - g.outside_falloff) < margin)
              continue;
            auto fd = [&](double h, double* out) {
              std::vector<double> v = base;
              v[k] = base[k] + h;
              double plus[3], minus[3];
              evaluateGhost(fromParameterVector(v, channels), p, plus, nullptr);
              v[k] = base[k] - h;
              evaluateGhost(fromParameterVector(v, channels), p, minus, nullptr);
              for (int c = 0; c < channels; ++c) out[c] = (plus[c] - minus[c]) / (2 * h);
            };
            const double h = 1e-5 * std::max(1.0, std::abs(base[k]));
            double fd1[3], fd2[3];
            fd(h, fd1);
            fd(2 * h, fd2);
            for (int c = 0; c < channels; ++c) {
              if (std::abs(fd1[c] - fd2[c]) > 1e-4 * std::max(1.0, std::abs(fd1[c]))) continue;  // not smooth here
              const double analytic = d.images[k].ptr<float>(y - d.rect.y)[(x - d.rect.x) * channels + c];
              const double tolerance = 1e-3 * std::max(std::abs(fd1[c]), 1e-3 * peak) + 1e-7;
              EXPECT_NEAR(analytic, fd1[c], tolerance)
                  << "ghost " << gi << " " << parameterName(k, channels) << " channel " << c << " at " << p
                  << " d " << dist;
              ++compared;
              if (std::abs(fd1[c]) > 1e-6) ++nonzero;
            }
          }
      }
    }
    EXPECT_GT(compared, 20000);
    EXPECT_GT(nonzero, 5000);
  }
}

TEST(ModelRenderer, RollRotatesTheFlareAboutTheCentre) {
  // A render at roll φ equals the φ = 0 render rotated about the image centre (PSNR ≥ 40 dB away
  // from the border). Smooth ghosts, so that resampling the reference is accurate.
  const cv::Size size(240, 180);
  const cv::Point2d centre(120, 90);
  std::vector<GhostParameters> ghosts = {ghostAt(70, 90, 20), ghostAt(160, 70, 12), ghostAt(110, 120, 30)};
  for (auto& g : ghosts) {
    g.outside_falloff = 6;
    g.inside_falloff = 8;
    g.inside_exponent = 1.2;
    g.outside_exponent = 1.5;
  }
  const cv::Mat upright = renderGhosts(ghosts, size, 1);
  double lowest_psnr = 1e9;
  for (double roll_deg : {17.0, -63.0, 90.0, 141.0}) {
    const cv::Mat rolled = renderGhosts(ghosts, size, 1, {}, ViewTransform::roll(roll_deg * M_PI / 180, centre));
    // OpenCV's matrix maps source pixel centres' coordinates (no half-pixel shift): the centre of
    // the image at (W/2, H/2) in our convention is (W/2 − 0.5, H/2 − 0.5) in OpenCV's.
    const cv::Mat m = cv::getRotationMatrix2D(cv::Point2f(119.5f, 89.5f), roll_deg, 1.0);
    cv::Mat reference;
    cv::warpAffine(upright, reference, m, size, cv::INTER_CUBIC, cv::BORDER_CONSTANT, 0);
    cv::Mat mask = cv::Mat::zeros(size, CV_8U);
    cv::circle(mask, cv::Point(120, 90), 80, cv::Scalar(255), cv::FILLED);
    double peak = 0;
    cv::minMaxLoc(upright, nullptr, &peak);
    cv::Mat diff = rolled - reference;
    diff = diff.mul(diff);
    const double mse = cv::mean(diff, mask)[0];
    const double psnr = 10 * std::log10(peak * peak / mse);
    EXPECT_GE(psnr, 40) << "roll " << roll_deg;
    lowest_psnr = std::min(lowest_psnr, psnr);
    // And the rolled image is not the upright one (the test can fail).
    cv::Mat same = upright - reference;
    EXPECT_GT(cv::mean(same.mul(same), mask)[0], 10 * mse) << "roll " << roll_deg;
  }
  RecordProperty("lowest_psnr_db", std::to_string(lowest_psnr));
}

TEST(ModelRenderer, ScaledViewShrinksTheFlare) {
  // Rendering at half the width puts the model's pixel (x, y) at the half-size image's
  // (x/2, y/2) about the centres.
  const GhostParameters g = ghostAt(100, 60, 20);
  ViewTransform half;
  half.scale = 0.5;
  half.model_center = {100, 75};
  half.image_center = {50, 37.5};
  const cv::Point2d q = half.modelFromImage({50 + 3, 37.5 - 4});
  EXPECT_NEAR(q.x, 106, 1e-12);
  EXPECT_NEAR(q.y, 67, 1e-12);
  const cv::Point2d back = half.imageFromModel(q);
  EXPECT_NEAR(back.x, 53, 1e-12);
  EXPECT_NEAR(back.y, 33.5, 1e-12);
  const cv::Mat small = renderGhosts(std::vector<GhostParameters>{g}, cv::Size(100, 75), 1, {}, half);
  double v[1];
  evaluateGhost(g, half.modelFromImage({20.5, 10.5}), v, nullptr);
  EXPECT_NEAR(small.at<float>(10, 20), v[0], 1e-6);
  EXPECT_GT(cv::sum(small)[0], 100);
}

}  // namespace
}  // namespace flarekit::model
