#include "render/flare_renderer.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/exr.h"
#include "common/testing.h"
#include "render/testing.h"

namespace flarekit::render {
namespace {

using testing::lensNamed;

FlareRenderOptions small() {
  FlareRenderOptions o;
  o.width_px = 240;
  o.height_px = 160;
  return o;
}

TEST(FlareRenderer, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(FlareRenderOptions{}.IsValid(&error)) << error;
}

TEST(FlareRenderer, InvalidOptionsAreInputErrors) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.grid_size = 1;
  EXPECT_FALSE(o.IsValid(nullptr));
  EXPECT_THROW(renderFlare(lens, {5, 0}, o), InputError);
  o = small();
  o.spectral_samples = 2;
  EXPECT_THROW(renderFlare(lens, {5, 0}, o), InputError);
  o = small();
  o.f_number = 1.0;  // wider than the lens
  EXPECT_THROW(renderFlare(lens, {5, 0}, o), InputError);
  EXPECT_THROW(renderFlare(lens, {NAN, 0}, small()), InputError);
}

// A small frame with few ghosts for the optical axis tests.
FlareRenderOptions tiny() {
  FlareRenderOptions o;
  o.width_px = 160;
  o.height_px = 107;
  o.max_ghosts = 4;
  o.ghost_layers = true;
  return o;
}

// Luminance centroid of a CV_32FC3 image (pixel centres at i + 0.5).
cv::Point2d centroidPx(const cv::Mat& image) {
  double sum = 0, sx = 0, sy = 0;
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x) {
      const cv::Vec3f& p = image.at<cv::Vec3f>(y, x);
      const double l = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
      sum += l;
      sx += l * (x + 0.5);
      sy += l * (y + 0.5);
    }
  return {sx / sum, sy / sum};
}

bool insideFrame(const cv::Rect& box, const cv::Size& size) {
  return box.x > 0 && box.y > 0 && box.br().x < size.width && box.br().y < size.height;
}

TEST(FlareRenderer, OpticalAxisOffsetIsValidated) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = tiny();
  EXPECT_EQ(o.optical_axis_offset_px, cv::Point2d(0, 0));
  o.optical_axis_offset_px = {160, -107};  // a whole frame away: the axis may lie off the image
  std::string error;
  EXPECT_TRUE(o.IsValid(&error)) << error;
  for (const cv::Point2d bad :
       {cv::Point2d(NAN, 0), cv::Point2d(0, INFINITY), cv::Point2d(161, 0), cv::Point2d(0, -108)}) {
    o.optical_axis_offset_px = bad;
    EXPECT_FALSE(o.IsValid(&error)) << bad;
    EXPECT_NE(error.find("optical axis offset"), std::string::npos) << error;
    EXPECT_THROW(renderFlare(lens, {3, 0}, o), InputError) << bad;
  }
}

// The optical axis meeting the image at (W/2 + dx, H/2 + dy) moves everything drawn by (dx, dy),
// sub-pixel offsets too: the light's image and its starburst, and every ghost. The roll turns
// the flare about the axis, so a rolled light moves by the same (dx, dy).
TEST(FlareRenderer, OpticalAxisOffsetMovesTheWholeFlare) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  const cv::Point2d offset(7.25, -3.5);
  for (RenderMethod method : {RenderMethod::kTiled, RenderMethod::kMatrix}) {
    SCOPED_TRACE(method == RenderMethod::kTiled ? "tiled" : "matrix");
    FlareRenderOptions o = tiny();
    o.method = method;
    const LightDirection light{2.5, 20};
    const FlareImage centred = renderFlare(lens, light, o);
    o.optical_axis_offset_px = offset;
    const FlareImage moved = renderFlare(lens, light, o);
    EXPECT_NEAR(moved.light_image_px.x - centred.light_image_px.x, offset.x, 1e-9);
    EXPECT_NEAR(moved.light_image_px.y - centred.light_image_px.y, offset.y, 1e-9);
    // The light's core (and its whole starburst, inside the frame in both) dominates the image.
    const cv::Point2d core = centroidPx(moved.radiance) - centroidPx(centred.radiance);
    EXPECT_NEAR(core.x, offset.x, 0.05);
    EXPECT_NEAR(core.y, offset.y, 0.05);
    // Every ghost layer that lies wholly inside the frame in both renders.
    ASSERT_EQ(moved.ghosts.size(), centred.ghosts.size());
    int compared = 0;
    for (size_t i = 0; i < centred.ghosts.size(); ++i) {
      const GhostRecord& a = centred.ghosts[i];
      const GhostRecord& b = moved.ghosts[i];
      ASSERT_EQ(a.id, b.id);
      if (a.energy <= 0 || !insideFrame(a.bbox_px, a.image.size()) ||
          !insideFrame(b.bbox_px, b.image.size()))
        continue;
      EXPECT_NEAR(b.centroid_px.x - a.centroid_px.x, offset.x, 0.05) << "ghost " << a.id;
      EXPECT_NEAR(b.centroid_px.y - a.centroid_px.y, offset.y, 0.05) << "ghost " << a.id;
      EXPECT_NEAR(b.energy, a.energy, 1e-3 * a.energy) << "ghost " << a.id;
      ++compared;
    }
    EXPECT_GE(compared, 1);
    const auto recorded = moved.attributes.find("flarekit.optical_axis_offset_px");
    ASSERT_NE(recorded, moved.attributes.end());
    EXPECT_EQ(std::get<cv::Vec2d>(recorded->second), cv::Vec2d(offset.x, offset.y));
    EXPECT_EQ(centred.attributes.count("flarekit.optical_axis_offset_px"), 0u);
  }
}

// The light's own image (the radiance less every ghost layer), starburst and halo, is centred on
// light_image_px, where truth frames record the light: on the axis at sub-pixel axis offsets, and
// off it.
TEST(FlareRenderer, LightsImageIsCentredOnItsRecordedPosition) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  for (const cv::Point2d offset : {cv::Point2d(0, 0), cv::Point2d(0.3, -0.2), cv::Point2d(7.25, -3.5)})
    for (const LightDirection light : {LightDirection{0, 0}, LightDirection{2.5, 20}})
      for (const double halo : {0.0, 0.1}) {
        SCOPED_TRACE(::testing::Message() << "offset " << offset << ", θ " << light.angle_deg << "°, halo " << halo);
        FlareRenderOptions o = tiny();
        o.optical_axis_offset_px = offset;
        o.halo_fraction = halo;
        const FlareImage f = renderFlare(lens, light, o);
        cv::Mat own = f.radiance.clone();
        for (const GhostRecord& g : f.ghosts)
          if (!g.image.empty()) own -= g.image;
        const cv::Point2d c = centroidPx(own);
        EXPECT_NEAR(c.x, f.light_image_px.x, 0.05);
        EXPECT_NEAR(c.y, f.light_image_px.y, 0.05);
      }
}

// A whole-pixel offset gives the same image shifted by whole pixels, away from the borders: the
// sprites exactly; the tiled rasterizer up to its float vertex positions, which round differently
// elsewhere on the image (a pixel centre on an edge two triangles share may take either's value).
TEST(FlareRenderer, WholePixelAxisOffsetShiftsTheImage) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  const cv::Point offset(6, -4);
  for (RenderMethod method : {RenderMethod::kTiled, RenderMethod::kMatrix}) {
    SCOPED_TRACE(method == RenderMethod::kTiled ? "tiled" : "matrix");
    FlareRenderOptions o = tiny();
    o.method = method;
    o.light_source = false;  // the ghosts' values, not the light's 10⁵ times brighter ones
    const FlareImage centred = renderFlare(lens, {4, 0}, o);
    o.optical_axis_offset_px = offset;
    const FlareImage moved = renderFlare(lens, {4, 0}, o);
    const cv::Rect inner(10, 10, o.width_px - 20, o.height_px - 20);
    const cv::Mat a = centred.radiance(inner), b = moved.radiance(inner + offset);
    double peak;
    cv::minMaxLoc(a.reshape(1), nullptr, &peak);
    ASSERT_GT(peak, 0);
    EXPECT_LT(cv::norm(a, b, cv::NORM_L1), 1e-4 * cv::norm(a, cv::NORM_L1));
    EXPECT_LT(cv::norm(a, b, cv::NORM_INF), 1e-2 * peak);
    if (method == RenderMethod::kMatrix) {
      EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
    }
  }
}

TEST(FlareRenderer, LightImageFollowsTheAngleConventions) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.ghost_layers = false;
  const FlareImage on_axis = renderFlare(lens, {0, 0}, o);
  EXPECT_NEAR(on_axis.light_image_px.x, 120, 0.05);
  EXPECT_NEAR(on_axis.light_image_px.y, 80, 0.05);
  const FlareImage left = renderFlare(lens, {5, 0}, o);
  // θ > 0 images to −x, about f·tan θ away.
  const double pitch = 36.0 / 240;
  EXPECT_NEAR(left.light_image_px.x, 120 - 99.24 * std::tan(5 * M_PI / 180) / pitch, 2.0);
  EXPECT_NEAR(left.light_image_px.y, 80, 0.05);
  // Roll turns counter-clockwise as displayed (y down), as in model/ and predict/: at φ = 90° the
  // light's image is below the centre.
  const FlareImage down = renderFlare(lens, {5, 90}, o);
  EXPECT_NEAR(down.light_image_px.x, 120, 0.05);
  EXPECT_GT(down.light_image_px.y, 80 + 20);
}

TEST(FlareRenderer, TheLightSourceIsFarBrighterThanItsGhosts) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  const FlareImage with = renderFlare(lens, {3, 0}, o);
  o.light_source = false;
  const FlareImage ghosts = renderFlare(lens, {3, 0}, o);
  double peak_all, peak_ghosts;
  cv::minMaxLoc(with.radiance.reshape(1), nullptr, &peak_all);
  cv::minMaxLoc(ghosts.radiance.reshape(1), nullptr, &peak_ghosts);
  EXPECT_GT(peak_all, 1000 * peak_ghosts);
  // The spot carries the direct flux: about the pupil area (π · 14.47²) over a pixel's area,
  // times the lens's transmission.
  const double flux_px = cv::sum(with.radiance - ghosts.radiance)[1];
  const double pupil_over_pixel = M_PI * 14.465 * 14.465 / (0.15 * 0.15);
  EXPECT_GT(flux_px, 0.5 * pupil_over_pixel);
  EXPECT_LT(flux_px, 1.0 * pupil_over_pixel);
  const cv::Point peak_at = [&] {
    cv::Point p;
    cv::Mat g;
    cv::extractChannel(with.radiance, g, 1);
    cv::minMaxLoc(g, nullptr, nullptr, nullptr, &p);
    return p;
  }();
  EXPECT_NEAR(peak_at.x + 0.5, with.light_image_px.x, 1.5);
  EXPECT_NEAR(peak_at.y + 0.5, with.light_image_px.y, 1.5);
}

// Ghosts of a rotationally symmetric lens lie on the line through the light's image and the
// image centre (the flare axis).
TEST(FlareRenderer, GhostsLineUpThroughTheLightAndTheCentre) {
  const Lens lens = lensNamed("brendel_tessar_100mm_usp2854889.json");
  FlareRenderOptions o = small();
  o.ghost_layers = true;
  o.light_source = false;
  o.sensor_width_mm = o.sensor_height_mm = 200;  // whole ghosts in view
  const double roll = 30.0;
  const FlareImage img = renderFlare(lens, {6, roll}, o);
  const cv::Point2d c(120, 80);
  const cv::Point2d axis = img.light_image_px - c;
  const double len = std::hypot(axis.x, axis.y);
  ASSERT_GT(len, 3.0);
  int checked = 0;
  for (const GhostRecord& g : img.ghosts) {
    if (g.energy <= 0 || g.bbox_px.width < 3) continue;
    if (g.bbox_px.x == 0 || g.bbox_px.y == 0 || g.bbox_px.br().x >= o.width_px || g.bbox_px.br().y >= o.height_px)
      continue;  // cut by the frame: its centroid moves
    const cv::Point2d d = g.centroid_px - c;
    const double off_axis = std::abs(d.x * axis.y - d.y * axis.x) / len;
    EXPECT_LT(off_axis, 0.5) << "ghost " << g.id;
    ++checked;
  }
  EXPECT_GE(checked, 10);
}

TEST(FlareRenderer, GhostLayersAddUpToTheImageAndCarryTheirTruth) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.ghost_layers = true;
  o.light_source = false;
  o.max_ghosts = 6;
  const FlareImage img = renderFlare(lens, {8, 0}, o);
  ASSERT_EQ(img.ghosts.size(), 6u);
  cv::Mat sum(img.radiance.size(), CV_32FC3, cv::Scalar::all(0));
  for (const GhostRecord& g : img.ghosts) sum += g.image;
  EXPECT_LT(cv::norm(sum, img.radiance, cv::NORM_INF), 1e-4 * cv::norm(img.radiance, cv::NORM_INF));
  // Ranked by the estimate, brightest first.
  for (size_t i = 1; i < img.ghosts.size(); ++i)
    EXPECT_GE(img.ghosts[i - 1].intensity_estimate, img.ghosts[i].intensity_estimate);
  testing::TempDir dir;
  writeExr(dir / "flare.exr", toExrImage(img));
  const ExrImage back = readExr(dir / "flare.exr");
  EXPECT_EQ(back.layers.size(), 7u);
  const GhostRecord& g = img.ghosts.front();
  const std::string key = "flarekit.ghost." + std::to_string(g.id) + ".";
  ASSERT_TRUE(back.find("ghost." + std::to_string(g.id)));
  EXPECT_NEAR(*numericAttribute(back.attributes, key + "energy"), g.energy, 1e-9 * g.energy);
  EXPECT_TRUE(back.attributes.count(key + "surfaces"));
  EXPECT_TRUE(back.attributes.count(key + "bbox_px"));
  EXPECT_TRUE(back.attributes.count(key + "centroid_px"));
  EXPECT_NEAR(*numericAttribute(back.attributes, "flarekit.angle_deg"), 8.0, 0);
}

// A FlareRenderer reused for a sequence gives each frame exactly as a fresh render does, and an
// image handed out before the next render keeps its pixels.
TEST(FlareRenderer, ReusedRendererAndImageGiveFreshRenders) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderer renderer;
  FlareImage frame;
  for (RenderMethod method : {RenderMethod::kTiled, RenderMethod::kMatrix}) {
    FlareRenderOptions o = small();
    o.method = method;
    o.ghost_layers = true;
    o.max_ghosts = 4;
    renderer.render(lens, {8, 0}, o, &frame);
    const cv::Mat handed_out = frame.radiance;  // shares the pixels, as a caller's copy would
    const cv::Mat layer_out = frame.ghosts.front().image;
    const cv::Mat kept = handed_out.clone(), kept_layer = layer_out.clone();
    o.max_ghosts = 3;
    for (double angle : {3.0, 12.0}) {
      renderer.render(lens, {angle, 10}, o, &frame);
      const FlareImage fresh = renderFlare(lens, {angle, 10}, o);
      EXPECT_EQ(cv::norm(frame.radiance, fresh.radiance, cv::NORM_INF), 0.0) << angle;
      ASSERT_EQ(frame.ghosts.size(), fresh.ghosts.size());
      for (size_t i = 0; i < fresh.ghosts.size(); ++i) {
        EXPECT_EQ(frame.ghosts[i].id, fresh.ghosts[i].id);
        EXPECT_EQ(frame.ghosts[i].energy, fresh.ghosts[i].energy);
        EXPECT_EQ(cv::norm(frame.ghosts[i].image, fresh.ghosts[i].image, cv::NORM_INF), 0.0);
      }
      EXPECT_EQ(frame.light_image_px, fresh.light_image_px);
      EXPECT_EQ(frame.attributes.size(), fresh.attributes.size());
    }
    EXPECT_EQ(cv::norm(handed_out, kept, cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(layer_out, kept_layer, cv::NORM_INF), 0.0);
  }
  // Another size: new planes of that size.
  FlareRenderOptions o = small();
  o.width_px = 100;
  renderer.render(lens, {5, 0}, o, &frame);
  EXPECT_EQ(frame.radiance.cols, 100);
  EXPECT_EQ(cv::norm(frame.radiance, renderFlare(lens, {5, 0}, o).radiance, cv::NORM_INF), 0.0);
}

// A reused renderer keeps the lens's setup (coatings, wavelengths, reflectance tables) from frame
// to frame; every change of the lens or of an option that setup depends on gives the fresh render.
TEST(FlareRenderer, ReusedRendererFollowsEveryChangeOfTheLensAndItsOptions) {
  const Lens heliar = lensNamed("heliar_tronnier.json");
  Lens thicker = heliar;
  thicker.surfaces[1].thickness_mm += 0.5;
  FlareRenderOptions base = small();
  base.method = RenderMethod::kTiled;
  base.max_ghosts = 6;
  struct Change {
    const char* what;
    const Lens* lens;
    FlareRenderOptions options;
  };
  std::vector<Change> changes;
  auto with = [&](const char* what, auto set, const Lens* lens = nullptr) {
    FlareRenderOptions o = base;
    set(o);
    changes.push_back({what, lens ? lens : &heliar, o});
  };
  with("nothing", [](FlareRenderOptions&) {});
  with("f-number", [](FlareRenderOptions& o) { o.f_number = 8; });
  with("focus at infinity", [](FlareRenderOptions& o) { o.focus_at_infinity = true; });
  with("wavelengths", [](FlareRenderOptions& o) { o.spectral_samples = 5; });
  with("coating index", [](FlareRenderOptions& o) { o.coating_ior = 1.45; });
  with("default coating", [](FlareRenderOptions& o) { o.default_coating_nm = 450; });
  with("coating override", [](FlareRenderOptions& o) { o.coating_override_nm = 700; });
  with("uncoated", [](FlareRenderOptions& o) { o.uncoated = true; });
  with("lens", [](FlareRenderOptions&) {}, &thicker);
  FlareRenderer renderer;
  FlareImage frame;
  cv::Mat previous;
  for (const Change& c : changes) {
    renderer.render(*c.lens, {6, 0}, c.options, &frame);
    const FlareImage fresh = renderFlare(*c.lens, {6, 0}, c.options);
    EXPECT_EQ(cv::norm(frame.radiance, fresh.radiance, cv::NORM_INF), 0.0) << c.what;
    if (!previous.empty() && std::string(c.what) != "nothing") {
      EXPECT_GT(cv::norm(frame.radiance, previous, cv::NORM_INF), 0.0) << c.what << " changed nothing";
    }
    previous = fresh.radiance.clone();
  }
}

TEST(FlareRenderer, CullingOptionsReduceTheGhostList) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.light_source = false;
  EXPECT_EQ(renderFlare(lens, {5, 0}, o).summary.ghosts_rendered, 28);
  o.same_side_of_stop_only = true;
  EXPECT_EQ(renderFlare(lens, {5, 0}, o).summary.ghosts_rendered, 13);
  o.same_side_of_stop_only = false;
  o.min_relative_intensity = 0.01;
  const int kept = renderFlare(lens, {5, 0}, o).summary.ghosts_rendered;
  EXPECT_GT(kept, 0);
  EXPECT_LT(kept, 28);
}

TEST(FlareRenderer, CoatingsColourAndDimTheGhosts) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.light_source = false;
  const double coated = cv::sum(renderFlare(lens, {5, 0}, o).radiance)[1];
  o.uncoated = true;
  const double bare = cv::sum(renderFlare(lens, {5, 0}, o).radiance)[1];
  EXPECT_GT(bare, 3 * coated);  // 4 % vs ~1 % per reflection, squared
  // A coating designed for green reflects least in green: its ghosts turn magenta.
  o.uncoated = false;
  o.coating_override_nm = 510;
  const cv::Scalar s = cv::sum(renderFlare(lens, {5, 0}, o).radiance);
  EXPECT_LT(s[1], s[0]);
  EXPECT_LT(s[1], s[2]);
}

TEST(FlareRenderer, SpectralModeAgreesWithRgbInOverallBrightness) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.light_source = false;
  o.grid_size = 24;
  const cv::Scalar rgb = cv::sum(renderFlare(lens, {5, 0}, o).radiance);
  o.spectral_samples = 8;
  const FlareImage spectral = renderFlare(lens, {5, 0}, o);
  EXPECT_EQ(spectral.summary.wavelengths, 8);
  const cv::Scalar s = cv::sum(spectral.radiance);
  const double y_rgb = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
  const double y_spec = 0.2126 * s[0] + 0.7152 * s[1] + 0.0722 * s[2];
  EXPECT_NEAR(y_spec / y_rgb, 1.0, 0.5);
}

TEST(FlareRenderer, MatrixMethodPutsGhostsWhereTheTracerDoes) {
  const Lens lens = lensNamed("heliar_tronnier.json");
  FlareRenderOptions o = small();
  o.light_source = false;
  o.ghost_layers = true;
  o.f_number = 16;
  o.sensor_width_mm = o.sensor_height_mm = 200;
  o.same_side_of_stop_only = true;
  const FlareImage traced = renderFlare(lens, {2, 0}, o);
  o.method = RenderMethod::kMatrix;
  const FlareImage matrix = renderFlare(lens, {2, 0}, o);
  ASSERT_EQ(traced.ghosts.size(), matrix.ghosts.size());
  int compared = 0;
  for (size_t i = 0; i < traced.ghosts.size(); ++i) {
    const GhostRecord& t = traced.ghosts[i];
    const GhostRecord& m = matrix.ghosts[i];
    ASSERT_EQ(t.id, m.id);
    if (t.energy <= 0 || t.bbox_px.width < 6 || t.bbox_px.x == 0 || t.bbox_px.br().x >= o.width_px) continue;
    EXPECT_NEAR(m.centroid_px.x, t.centroid_px.x, 0.05 * t.bbox_px.width + 0.5) << t.id;
    EXPECT_NEAR(m.bbox_px.width, t.bbox_px.width, 0.05 * t.bbox_px.width + 2) << t.id;
    ++compared;
  }
  EXPECT_GE(compared, 5);
}

}  // namespace
}  // namespace flarekit::render
