// Tests of the capture-level pieces: options, polynomials, extrapolation, the model built from
// tracks, and a whole synthetic stack fitted end to end in memory.
#include "fit/fit_capture.h"

#include <algorithm>
#include <filesystem>
#include <functional>

#include <gtest/gtest.h>

#include "fit/frame_fits.h"
#include "model/model_renderer.h"

namespace flarekit::fit {
namespace {

// The capture of the hand-made tracks below: a valid model file's metadata, 200 × 120 pixels.
model::CaptureInfo testCapture(double angle_step_deg = 1) {
  model::CaptureInfo info;
  info.camera = info.lens = info.light = "test";
  info.f_number = info.iso = info.exposure_s = info.pixel_pitch_um = 1;
  info.angle_step_deg = angle_step_deg;
  info.image_size = {200, 120};
  return info;
}

// Appends one fitted frame to a hand-made track, with every per-frame record the fitter keeps
// (explained, fitted, not carried).
void addFrame(GhostTrackFit& t, double angle_deg, const model::GhostParameters& g) {
  t.angles_deg.push_back(angle_deg);
  t.fits.push_back(g);
  t.residual_rms.push_back(0);
  t.peak.push_back(1);
  t.unexplained.push_back(false);
  t.carried.push_back(false);
}

// PSNR of a model's ghost against a fit, both drawn on the test capture (peak: the fit's brightest
// value).
double psnrAgainstFit(const model::GhostParameters& model_ghost, const model::GhostParameters& fit) {
  const cv::Size size = testCapture().image_size;
  const cv::Mat fit_image = model::renderGhosts(std::span(&fit, 1), size, 1);
  const cv::Mat model_image = model::renderGhosts(std::span(&model_ghost, 1), size, 1);
  double peak = 0;
  cv::minMaxLoc(fit_image, nullptr, &peak);
  const cv::Mat d = model_image - fit_image;
  const double mse = d.dot(d) / d.total();
  return 10 * std::log10(peak * peak / mse);
}

TEST(FitOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(FitOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(DetectionOptions{}.IsValid(&error)) << error;
  EXPECT_TRUE(TrackingOptions{}.IsValid(&error)) << error;
  FitOptions bad;
  bad.threads = 0;
  EXPECT_FALSE(bad.IsValid(&error));
  FitOptions negative;
  negative.joint_refine_sweeps = -1;
  EXPECT_FALSE(negative.IsValid(&error));
}

TEST(FitPolynomial, ReproducesAQuadraticInDegrees) {
  std::vector<double> a, v;
  for (double t = 10; t <= 20; t += 0.5) {
    a.push_back(t);
    v.push_back(3 - 0.5 * t + 0.02 * t * t);
  }
  const auto p = fitPolynomial(a, v, 2);
  ASSERT_EQ(p.coefficients.size(), 3u);
  EXPECT_NEAR(p.coefficients[0], 3, 1e-8);
  EXPECT_NEAR(p.coefficients[1], -0.5, 1e-9);
  EXPECT_NEAR(p.coefficients[2], 0.02, 1e-10);
  // Fewer points than the degree needs: the degree drops.
  EXPECT_EQ(fitPolynomial({1.0}, {4.0}, 2).coefficients.size(), 1u);
}

TEST(PolynomialInliers, LeaveOutOneWildFrameAndNothingElse) {
  std::vector<double> a, v;
  for (int i = 0; i < 9; ++i) {
    a.push_back(0.5 * i);
    v.push_back(2e-4 + 1e-5 * i - 3e-6 * i * i + (i % 2 ? 2e-6 : -2e-6));  // a noisy quadratic
  }
  EXPECT_EQ(polynomialInliers(a, v, 2), std::vector<bool>(9, true));
  v[1] = 0.17;  // one frame's fit went into the light
  std::vector<bool> expected(9, true);
  expected[1] = false;
  EXPECT_EQ(polynomialInliers(a, v, 2), expected);
  // Through the model: the ghost's brightness follows the other eight frames.
  GhostTrackFit t;
  for (int i = 0; i < 9; ++i) {
    model::GhostParameters g;
    g.center_x = 100 + 3 * i;
    g.inside = {v[i], 0, 0};
    addFrame(t, a[i], g);
  }
  const model::CaptureInfo info = testCapture();
  const model::FlareModel m = buildFlareModel({t}, info, 1, 2);
  const auto at = m.ghostsAt(0.5);
  ASSERT_EQ(at.size(), 1u);
  EXPECT_NEAR(at[0].parameters.inside[0], 2e-4 + 1e-5 - 3e-6, 5e-6);
  // Too few frames to tell: all kept.
  EXPECT_EQ(polynomialInliers({0, 1, 2, 3}, {1, 1, 9, 1}, 2), std::vector<bool>(4, true));
}

TEST(Extrapolate, FollowsALinearTrack) {
  std::vector<double> a;
  std::vector<model::GhostParameters> fits;
  for (int i = 0; i < 8; ++i) {
    model::GhostParameters g;
    g.center_x = 100 + 5 * i;
    g.center_y = 50;
    a.push_back(0.2 * i);
    fits.push_back(g);
  }
  const auto next = extrapolate(a, fits, 1.6, 8, 2);
  EXPECT_NEAR(next.center_x, 140, 1e-6);
  EXPECT_NEAR(next.center_y, 50, 1e-9);
}

TEST(BuildFlareModel, PolynomialsStayWithinBoundsAndAutoDegreeIsLowForLinearData) {
  GhostTrackFit t;
  t.id = 4;
  for (int i = 0; i < 20; ++i) {
    model::GhostParameters g;
    g.center_x = 100 + 3 * i;
    g.center_y = 60;
    // Ii near its bound 0 and noisy: a degree-2 fit would dip below 0 inside the range.
    g.inside = {i % 2 ? 0.0 : 0.02, 0, 0};
    addFrame(t, 0.2 * i, g);
  }
  const model::CaptureInfo info = testCapture();
  for (int degree : {2, -1}) {
    const model::FlareModel m = buildFlareModel({t}, info, 1, degree);
    std::string error;
    EXPECT_TRUE(m.IsValid(&error)) << error;
    EXPECT_NEAR(m.ghosts[0].parameters[model::param::kMx].evaluate(1.0), 115, 1e-6);
  }
  const model::FlareModel automatic = buildFlareModel({t}, info, 1, -1);
  EXPECT_LE(automatic.ghosts[0].parameters[model::param::kMx].coefficients.size(), 2u);
}

TEST(BuildFlareModel, AGlareFollowsItsPedestalOverTheCapture) {
  // Veiling glare flat over the frame (fit/cost.h isGlare), fitted in every frame of a 0–30°
  // capture, its pedestal falling 20× as the light leaves (as on the 640×427 captures). The
  // model must draw each frame's pedestal within 10 % of its fit's, to the last frame.
  GhostTrackFit t;
  t.id = 0;
  const model::CaptureInfo info = testCapture(0.5);
  for (int i = 0; i <= 60; ++i) {
    model::GhostParameters g;
    g.center_x = 100;
    g.center_y = 60;
    g.left = g.right = g.height = 640;
    g.inside_falloff = 50;
    g.outside_falloff = 120;
    g.border = {1e-4, 0, 0};
    g.inside = {1e-4 * std::exp(-0.5 * i / 10), 0, 0};
    ASSERT_TRUE(isGlare(g, info.image_size));
    addFrame(t, 0.5 * i, g);
  }
  const model::FlareModel m = buildFlareModel({t}, info, 1, 2);
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  auto pedestal = [&](const model::GhostParameters& g) {
    return cv::mean(model::renderGhosts(std::span(&g, 1), info.image_size, 1))[0];
  };
  for (size_t i = 0; i < t.fits.size(); ++i) {
    const auto at = m.ghostsAt(t.angles_deg[i]);
    ASSERT_EQ(at.size(), 1u);
    const double fit = pedestal(t.fits[i]);
    EXPECT_NEAR(pedestal(at[0].parameters), fit, 0.1 * fit) << "at " << t.angles_deg[i] << "°";
  }
}

// The glow fades 400× over a capture (more than a degree-4 polynomial can follow everywhere):
// fitted in σ of each frame's noise, which fades with it, the model's pedestal follows the faint
// end too; in absolute terms the bright frames take the polynomial and the faint end is left.
// (Degree 4, below kPedestalDegree, so that the weights matter.)
TEST(BuildPedestalTrack, FollowsTheGlowToTheCapturesFaintEnd) {
  constexpr int kDegree = 4;
  std::vector<double> angles, noise, unweighted, truth;
  std::vector<model::Pedestal> pedestals;
  for (int i = 0; i <= 60; ++i) {
    const double theta = 0.5 * i, level = 2e-4 * std::exp(-theta / 5);
    angles.push_back(theta);
    truth.push_back(level);
    noise.push_back(0.05 * level);
    unweighted.push_back(0);
    pedestals.push_back(model::Pedestal{1, {level, -0.5 * level, 0, -2 * level, 0, -level}});
  }
  // The largest error of the constant term over the last 5° (the faint end), in its frame's σ.
  auto faint_end_error = [&](const std::vector<double>& sigma) {
    const auto track = buildPedestalTrack(angles, pedestals, sigma, 1, kDegree, 0.25, 0, 30);
    double error = 0;
    for (size_t i = 50; i < angles.size(); ++i)
      error = std::max(error, std::abs(track->terms[0].evaluate(angles[i]) - truth[i]) / noise[i]);
    return error;
  };
  const double weighted = faint_end_error(noise), plain = faint_end_error(unweighted);
  EXPECT_LT(weighted, 3);  // measured 1.7 σ
  EXPECT_GT(plain, 20);    // measured 74 σ
  const auto track = buildPedestalTrack(angles, pedestals, noise, 1, kDegree, 0.25, 0, 30);
  EXPECT_EQ(track->angle_min_deg, 0);
  EXPECT_EQ(track->angle_max_deg, 30);
  EXPECT_FALSE(buildPedestalTrack({}, {}, {}, 1, kDegree, 0.25, 0, 30).has_value());
}

TEST(BuildFlareModel, TheModelCarriesEachFrameFitsBrightness) {
  // A ghost whose fits trade border brightness against outer fall-off from frame to frame (a
  // compact bright border in even frames, a faint wide glow in odd ones): polynomials of Ib, Fo
  // and Eo each on their own pair the mean border with the mean fall-off. The model's ghost at
  // each fitted angle must still carry about the fits' light: within 15 % of the mean energy of
  // the fits around it, and the whole track's within 5 %.
  GhostTrackFit t;
  t.id = 1;
  for (int i = 0; i < 11; ++i) {
    model::GhostParameters g;
    g.center_x = 80 + 4 * i;
    g.center_y = 60;
    g.left = g.right = g.height = 15;
    g.inside = {0.01, 0, 0};
    g.border = {i % 2 ? 0.003 : 0.02, 0, 0};
    g.outside_falloff = i % 2 ? 40 : 4;
    g.outside_exponent = i % 2 ? 2 : 1;
    addFrame(t, 0.5 * i, g);
  }
  const model::CaptureInfo info = testCapture();
  const model::FlareModel m = buildFlareModel({t}, info, 1, 2);
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  auto energy = [&](const model::GhostParameters& g) {
    return cv::sum(model::renderGhosts(std::span(&g, 1), info.image_size, 1))[0];
  };
  double fits_total = 0, model_total = 0;
  std::vector<double> fits;
  for (const auto& g : t.fits) fits.push_back(energy(g));
  for (size_t i = 0; i < t.fits.size(); ++i) {
    const auto at = m.ghostsAt(t.angles_deg[i]);
    ASSERT_EQ(at.size(), 1u);
    const double e = energy(at[0].parameters);
    const double around = i == 0 || i + 1 == fits.size() ? fits[i] : 0.25 * (fits[i - 1] + 2 * fits[i] + fits[i + 1]);
    if (i > 0 && i + 1 < fits.size()) {
      EXPECT_NEAR(e, around, 0.15 * around) << "at " << t.angles_deg[i] << "°";
    }
    fits_total += fits[i];
    model_total += e;
  }
  EXPECT_NEAR(model_total, fits_total, 0.05 * fits_total);
}

TEST(BuildFlareModel, RefinedInImageTheModelDrawsWhatTheFitsDraw) {
  // A disc that brightens along its track, fitted one way while faint and another while bright:
  // a linear ramp to Ii = 0.001 at 20 px (the centre) up to 2.5°, then a steep ramp (exponent 6)
  // towards a virtual Ii = 0.3 at 40 px, 0.0047 at the centre, as the Heliar glare's fits turned
  // at 1°. Polynomials through each parameter on their own, and intensities refitted in image
  // space without weights, give the faint frames the bright frames' light. Refined in image
  // space, the model's ghost must come within 30 dB PSNR of every fit (peak: the fit's brightest
  // value).
  GhostTrackFit t;
  t.id = 2;
  for (int i = 0; i < 12; ++i) {
    model::GhostParameters g;
    g.center_x = 70 + 5 * i;
    g.center_y = 60;
    g.left = g.right = g.height = 20;
    g.border = {0.0002, 0, 0};
    const bool faint = i < 6;
    g.inside = {faint ? 0.001 : 0.3, 0, 0};
    g.inside_falloff = faint ? 20 : 40;
    g.inside_exponent = faint ? 1 : 6;
    g.outside_falloff = 3;
    addFrame(t, 0.5 * i, g);
  }
  const model::CaptureInfo info = testCapture();
  const model::FlareModel plain = buildFlareModel({t}, info, 1, 2);
  const model::FlareModel refined = buildFlareModel({t}, info, 1, 2, 0, -90, 90, true);
  std::string error;
  ASSERT_TRUE(refined.IsValid(&error)) << error;
  auto modelPsnr = [&](const model::FlareModel& m, size_t i) {
    const auto at = m.ghostsAt(t.angles_deg[i]);
    EXPECT_EQ(at.size(), 1u);
    return psnrAgainstFit(at[0].parameters, t.fits[i]);
  };
  double plain_worst = 1e9;
  for (size_t i = 0; i < t.fits.size(); ++i) {
    plain_worst = std::min(plain_worst, modelPsnr(plain, i));
    EXPECT_GE(modelPsnr(refined, i), 30) << "at " << t.angles_deg[i] << "°";
  }
  // Without the refinement the faint frames are missed (25.8 dB at 2.5°): the case needs it.
  EXPECT_LT(plain_worst, 30);
}

TEST(BuildFlareModel, AGhostWhoseInsideFallOffRunsBeyondItsOutlineKeepsItsFitsBrightness) {
  // A small ghost whose fits hold its inside fall-off Fi and exponent Ei at their bounds, far
  // deeper than its outline (Brendel Tessar 640×427, λ × 1, track 39 at 3.6–6.8°: L 0.8–3 px,
  // R 7–4.8 px, h 6 px, Fi 769 px, Ei 10, Ii 0.0031). Its image shows only Ib and
  // (Ii − Ib)·(depth / Fi)^Ei ≈ 0 inside, so Ii itself is not seen, and the image-space solves
  // took the model's Ii to 5.4e18. The model's Ib and Ii at every fitted angle must stay within
  // 4 × the brightest of the fits' (their bound), and its image within 30 dB of each fit's.
  GhostTrackFit t;
  t.id = 3;
  for (int i = 0; i < 17; ++i) {
    model::GhostParameters g;
    g.center_x = 90 + i;
    g.center_y = 60;
    g.left = 0.8 + 0.14 * i;
    g.right = 7 - 0.14 * i;
    g.height = 6;
    g.border = {2e-5 - 6e-7 * i, 0, 0};
    g.inside = {0.0031, 0, 0};
    g.inside_falloff = 769;
    g.inside_exponent = 10;
    g.outside_falloff = 17 + 0.6 * i;
    g.outside_exponent = 0.7 + 0.3 * i;
    addFrame(t, 0.2 * i, g);
  }
  const model::CaptureInfo info = testCapture();
  const model::FlareModel m = buildFlareModel({t}, info, 1, 2, 0, -90, 90, true);
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  for (size_t i = 0; i < t.fits.size(); ++i) {
    const auto at = m.ghostsAt(t.angles_deg[i]);
    ASSERT_EQ(at.size(), 1u);
    const model::GhostParameters& g = at[0].parameters;
    EXPECT_LE(g.inside[0], 4 * 0.0031 * (1 + 1e-9)) << "at " << t.angles_deg[i] << "°";
    EXPECT_LE(g.border[0], 4 * 0.0031 * (1 + 1e-9)) << "at " << t.angles_deg[i] << "°";
    EXPECT_GE(psnrAgainstFit(g, t.fits[i]), 30) << "at " << t.angles_deg[i] << "°";
  }
}

TEST(BuildFlareModel, RefinedInImageAVeilKeepsTheAxisItsFitsFound) {
  // The fits of a frame-wide veil (Heliar Tronnier 640×427, λ × 1, track 30 at 6.8–13.2°, 33
  // frames, tests/data/fit/heliar640_veil_fits.json): its top and bottom lie beyond the frame
  // (h 191–338 px against a half-height of 213.5) and its fits trade h against the curvature
  // from frame to frame, but every fit has its mirror axis My within 3.2 px of the flare axis
  // (y = 213.5). Ghosts are mirror-symmetric about that axis (Walch et al. 2018 §3.2); the model
  // refined in image space must keep it there, within 2 px of the fits' median, at every angle.
  // Left free, the refinement traded My against h where the image hardly tells them apart and
  // moved it to 206–286 px.
  const FrameFits fits = FrameFits::load(std::filesystem::path(FLAREKIT_SOURCE_DIR) / "tests/data/fit/heliar640_veil_fits.json");
  GhostTrackFit t;
  t.id = 30;
  std::vector<double> axis;
  for (const auto& f : fits.frames) {
    ASSERT_EQ(f.ghosts.size(), 1u);
    addFrame(t, f.angle_deg, f.ghosts[0].parameters);
    axis.push_back(f.ghosts[0].parameters.center_y);
  }
  ASSERT_EQ(t.fits.size(), 33u);
  model::CaptureInfo info = testCapture(0.2);
  info.image_size = fits.image_size;
  const model::FlareModel m = buildFlareModel({t}, info, 1, 2, 0.1, 0, 30, true);
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  std::nth_element(axis.begin(), axis.begin() + axis.size() / 2, axis.end());
  const double median_axis = axis[axis.size() / 2];
  EXPECT_NEAR(median_axis, 213.5, 1);
  for (double angle : t.angles_deg) {
    const auto at = m.ghostsAt(angle);
    ASSERT_EQ(at.size(), 1u);
    EXPECT_NEAR(at[0].parameters.center_y, median_axis, 2) << "at " << angle << "°";
  }
}

TEST(BuildFlareModel, RefinedTogetherTheGhostsDrawTheSumOfTheirFits) {
  // A small bright disc inside a broad faint one, fitted in every other frame the other way: the
  // broad ghost takes most of the small one's light as a bright core (a steep ramp, Fi 50 px,
  // exponent 6) and the small one is left dim, as the fits of overlapping Heliar veils trade
  // light from frame to frame. No polynomial follows either ghost's fits, and each ghost refined
  // on its own ends between its two kinds of fit; the sum of the fits, though, barely changes,
  // and the ghosts refined together must draw it more closely.
  GhostTrackFit small, broad;
  small.id = 0;
  broad.id = 1;
  for (int i = 0; i <= 10; ++i) {
    const bool traded = i % 2 == 1;
    model::GhostParameters s;
    s.center_x = 100 + 2 * i;
    s.center_y = 60;
    s.left = s.right = s.height = 12;
    s.border = s.inside = {traded ? 0.0007 : 0.002, 0, 0};
    s.outside_falloff = 2;
    addFrame(small, 0.5 * i, s);
    model::GhostParameters b = s;
    b.left = b.right = 60;
    b.height = 45;
    b.border = {0.0002, 0, 0};
    b.inside = {traded ? 0.003 : 0.0002, 0, 0};
    b.inside_falloff = traded ? 50 : 5;
    b.inside_exponent = traded ? 6 : 1;
    b.outside_falloff = 3;
    addFrame(broad, 0.5 * i, b);
  }
  const model::CaptureInfo info = testCapture();
  const std::vector<GhostTrackFit> tracks = {small, broad};
  auto error = [&](const model::FlareModel& m) {
    double sum = 0;
    for (size_t i = 0; i < small.fits.size(); ++i) {
      const std::vector<model::GhostParameters> fits = {small.fits[i], broad.fits[i]};
      std::vector<model::GhostParameters> at;
      for (const auto& g : m.ghostsAt(small.angles_deg[i])) at.push_back(g.parameters);
      EXPECT_EQ(at.size(), 2u);
      const cv::Mat d = model::renderGhosts(at, info.image_size, 1) -
                        model::renderGhosts(fits, info.image_size, 1);
      sum += d.dot(d);
    }
    return sum;
  };
  const double alone = error(buildFlareModel(tracks, info, 1, 2, 0, -90, 90, true, 0));
  const model::FlareModel m = buildFlareModel(tracks, info, 1, 2, 0, -90, 90, true, 2);
  // Measured: 0.79 × the error of the ghosts refined alone.
  EXPECT_LT(error(m), 0.9 * alone);
  // Each ghost is still itself: the small one where its fits are, the broad one broad.
  for (size_t i = 0; i < small.fits.size(); ++i) {
    const auto at = m.ghostsAt(small.angles_deg[i]);
    ASSERT_EQ(at.size(), 2u);
    const auto& s = at[0].id == small.id ? at[0].parameters : at[1].parameters;
    const auto& b = at[0].id == small.id ? at[1].parameters : at[0].parameters;
    EXPECT_NEAR(s.center_x, small.fits[i].center_x, 1) << "at " << small.angles_deg[i] << "°";
    EXPECT_NEAR(s.right, 12, 2) << "at " << small.angles_deg[i] << "°";
    EXPECT_NEAR(b.right, 60, 6) << "at " << small.angles_deg[i] << "°";
  }
}

TEST(SplitTracks, ATrackThatJumpsToAnotherGhostBecomesTwo) {
  // Frames 0–7 follow a small ghost moving right; frames 8–15 a large one elsewhere (the track
  // jumped). One quadratic per parameter describes neither, so the track is cut between 7 and 8.
  GhostTrackFit t;
  t.id = 3;
  t.key_frame = 2;
  for (int i = 0; i < 16; ++i) {
    model::GhostParameters g;
    const bool small = i < 8;
    g.center_x = small ? 40 + 2 * i : 150 - 3 * i;
    g.center_y = 60;
    g.left = g.right = g.height = small ? 8 : 45;
    g.inside = {0.01, 0, 0};
    addFrame(t, 0.5 * i, g);
  }
  const model::CaptureInfo info = testCapture();
  const auto split = splitTracksPolynomialsCannotFollow({t}, info, 1, 2, 3, 10);
  ASSERT_EQ(split.size(), 2u);
  EXPECT_EQ(split[0].id, 3);
  EXPECT_EQ(split[0].key_frame, 2);
  EXPECT_EQ(split[0].angles_deg.back(), 3.5);
  EXPECT_EQ(split[1].id, 10);
  EXPECT_EQ(split[1].key_frame, -1);
  EXPECT_EQ(split[1].angles_deg.front(), 4.0);
  EXPECT_EQ(split[1].unexplained.size(), 8u);
  // A track the polynomials follow stays whole.
  GhostTrackFit smooth = t;
  for (int i = 0; i < 16; ++i) smooth.fits[i] = t.fits[i % 8];
  for (int i = 8; i < 16; ++i) smooth.fits[i].center_x = 40 + 2 * i;
  EXPECT_EQ(splitTracksPolynomialsCannotFollow({smooth}, info, 1, 2, 3, 10).size(), 1u);
}

TEST(SplitTracks, ATrackThatTurnsFromASharpVeilIntoGlareBecomesTwo) {
  // One outline wider than the frame over 12 frames: a sharp veil (Fo 5 px) for six, glare (Fo
  // 150 px, isGlare on the 233 px diagonal) for six. The outlines are the same ghost's, so only
  // the change of kind tells the two apart.
  const model::CaptureInfo info = testCapture();
  auto veil = [](double fo) {
    model::GhostParameters g;
    g.center_x = 100;
    g.center_y = 60;
    g.left = g.right = 150;
    g.height = 100;
    g.border = {1e-3, 0, 0};
    g.inside = {2e-3, 0, 0};
    g.outside_falloff = fo;
    return g;
  };
  ASSERT_FALSE(isGlare(veil(5), info.image_size));
  ASSERT_TRUE(isGlare(veil(150), info.image_size));
  GhostTrackFit t;
  t.id = 4;
  for (int i = 0; i < 12; ++i) addFrame(t, 0.5 * i, veil(i < 6 ? 5 : 150));
  const auto split = splitTracksPolynomialsCannotFollow({t}, info, 1, 2, 3, 10);
  ASSERT_EQ(split.size(), 2u);
  EXPECT_EQ(split[0].angles_deg.back(), 2.5);
  EXPECT_EQ(split[1].angles_deg.front(), 3.0);
  EXPECT_EQ(split[0].end_high, "split: glare on one side, a sharp outline on the other");
  EXPECT_EQ(split[1].end_low, split[0].end_high);
  // Glare whose fall-off dips for two frames (fewer than min_frames) stays one track.
  GhostTrackFit flicker = t;
  for (int i = 0; i < 12; ++i) flicker.fits[i] = veil(i == 5 || i == 6 ? 5 : 150);
  EXPECT_EQ(splitTracksPolynomialsCannotFollow({flicker}, info, 1, 2, 3, 10).size(), 1u);
}

// A sharp ghost ends where its fit runs to a size bound or out of the image. Glare, the glow
// of the veils too faint to see, does not: its outline may be wider than the frame, one side at
// 0.5 px, or its centre outside the image with its fall-off reaching in; it ends only where that
// reach misses the image, or where it sinks into the noise.
TEST(TrackEndReason, EndsASharpGhostAtItsSizeBoundsButGlareOnlyOutOfReachOrInTheNoise) {
  const cv::Size size(640, 427);  // diagonal 769 px
  const double sigma = 1e-3;
  const TrackingOptions options;
  auto ghost = [](double mx, double l, double r, double h, double fo, double intensity) {
    model::GhostParameters g;
    g.center_x = mx;
    g.center_y = 213;
    g.left = l;
    g.right = r;
    g.height = h;
    g.border = {intensity, 0, 0};
    g.inside = {intensity, 0, 0};
    g.outside_falloff = fo;
    return g;
  };
  const double sharp = 5, glow = 400;
  ASSERT_FALSE(isGlare(ghost(320, 100, 100, 100, sharp, 0.1), size));
  ASSERT_TRUE(isGlare(ghost(320, 100, 100, 100, glow, 0.1), size));
  const std::string broke = "fit broke down (size at its bound)";
  for (double fo : {sharp, glow}) {
    SCOPED_TRACE(fo);
    const bool glare = fo == glow;
    EXPECT_EQ(trackEndReason(ghost(320, 100, 100, 100, fo, 0.1), size, sigma, options), "");
    EXPECT_EQ(trackEndReason(ghost(320, 100, 760, 300, fo, 0.1), size, sigma, options),
              glare ? "" : broke);
    EXPECT_EQ(trackEndReason(ghost(320, 0.5, 200, 300, fo, 0.1), size, sigma, options),
              glare ? "" : broke);
    // Centre 640 px left of the frame, outline 300 px across: only the glow reaches in.
    EXPECT_EQ(trackEndReason(ghost(-640, 300, 300, 300, fo, 0.1), size, sigma, options),
              glare ? "" : "left the image");
    EXPECT_EQ(trackEndReason(ghost(-1500, 300, 300, 300, fo, 0.1), size, sigma, options),
              "left the image");
    EXPECT_EQ(trackEndReason(ghost(320, 100, 100, 100, fo, 3 * sigma), size, sigma, options),
              "sank into the noise");
  }
}

TEST(BuildFlareModel, RangesReachHalfwayToTheNeighbouringFrames) {
  // Tracks fitted at 1.0–2.0° and 2.5–3.0° in frames 0.5° apart, the capture 0–3°: the first ghost
  // exists up to 2.25°, the second from there on, and the capture's end bounds the second.
  auto track = [](int id, double from, double to) {
    GhostTrackFit t;
    t.id = id;
    for (double a = from; a <= to + 1e-9; a += 0.5) {
      model::GhostParameters g;
      g.center_x = 100 + 10 * a;
      g.center_y = 60;
      addFrame(t, a, g);
    }
    return t;
  };
  const model::CaptureInfo info = testCapture(0.5);
  const model::FlareModel m = buildFlareModel({track(0, 1.0, 2.0), track(1, 2.5, 3.0)}, info, 1, 1, 0.25, 0.0, 3.0);
  std::string error;
  ASSERT_TRUE(m.IsValid(&error)) << error;
  EXPECT_DOUBLE_EQ(m.ghosts[0].angle_min_deg, 0.75);
  EXPECT_DOUBLE_EQ(m.ghosts[0].angle_max_deg, 2.25);
  EXPECT_DOUBLE_EQ(m.ghosts[1].angle_min_deg, 2.25);
  EXPECT_DOUBLE_EQ(m.ghosts[1].angle_max_deg, 3.0);
  // Between the fitted frames the ghost is where its polynomial puts it.
  EXPECT_NEAR(m.ghosts[0].parameters[model::param::kMx].evaluate(2.2), 122, 1e-9);
}

// An empty grey stack of 160 × 100 frames 0.25° apart, for the frames the tests below draw.
FrameStack testStack() {
  FrameStack stack;
  stack.size = {160, 100};
  stack.channels = 1;
  stack.info = testCapture(0.25);
  stack.info.image_size = stack.size;
  return stack;
}

// Frame `index` of `stack` at `angle_deg`: the ghosts rendered, every pixel valid.
Frame ghostFrame(const FrameStack& stack, int index, double angle_deg,
                 const std::vector<model::GhostParameters>& ghosts) {
  Frame f;
  f.index = index;
  f.angle_deg = angle_deg;
  f.image = model::renderGhosts(ghosts, stack.size, 1);
  f.valid = cv::Mat(stack.size, CV_8U, cv::Scalar(255));
  return f;
}

// A disc-like ghost 15 × 14 px in half-size at (x, 50).
model::GhostParameters ghostAt(double x, double border, double inside) {
  model::GhostParameters g;
  g.center_x = x;
  g.center_y = 50;
  g.left = g.right = 15;
  g.height = 14;
  g.border = {border, 0, 0};
  g.inside = {inside, 0, 0};
  return g;
}

void addNoise(Frame& f, double sigma) {
  cv::Mat noise(f.image.size(), CV_32F);
  cv::randn(noise, 0, sigma);
  f.image += noise;
}

TEST(FitCapture, RecoversMovingGhostsInMemory) {
  FrameStack stack = testStack();
  cv::theRNG().state = 5;
  for (int i = 0; i < 9; ++i) {
    const double theta = 0.25 * i;
    Frame f = ghostFrame(stack, i, theta, {ghostAt(50 + 8 * theta, 1, 0.4)});
    addNoise(f, 0.01);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  const FitResult r = fitCapture(stack, options);
  ASSERT_EQ(r.model.ghosts.size(), 1u);
  const auto at = r.model.ghostsAt(1.0);
  ASSERT_EQ(at.size(), 1u);
  EXPECT_NEAR(at[0].parameters.center_x, 58, 0.1);
  EXPECT_NEAR(at[0].parameters.left, 15, 0.2);
  EXPECT_NEAR(at[0].parameters.border[0], 1, 0.03);
  EXPECT_TRUE(r.summary.unexplained.empty());
  EXPECT_FALSE(r.summary.BriefReport().empty());
}

// With pixel_noise the fitter counts in the frame's pixel noise: on frames whose background is a
// slope (as veils make it), the background's spread is over 1.5× the pixel noise of 0.01.
TEST(FitCapture, WithThePixelNoiseCountsInTheFramesPixelNoise) {
  FrameStack stack = testStack();
  cv::theRNG().state = 5;
  cv::Mat slope(stack.size, CV_32F);
  for (int y = 0; y < slope.rows; ++y)
    for (int x = 0; x < slope.cols; ++x) slope.at<float>(y, x) = 0.0005f * x;
  for (int i = 0; i < 9; ++i) {
    Frame f = ghostFrame(stack, i, 0.25 * i, {ghostAt(50 + 2 * i, 1, 0.4)});
    f.image += slope;
    addNoise(f, 0.01);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  for (const bool pixel : {false, true}) {
    options.pixel_noise = pixel;
    const FitResult r = fitCapture(stack, options);
    ASSERT_EQ(r.frames.size(), stack.frames.size());
    for (size_t i = 0; i < r.frames.size(); ++i) {
      const Frame& f = stack.frames[r.frames[i].frame];
      const double pixel_sigma = estimatePixelNoiseSigma(f.image, f.valid);
      EXPECT_NEAR(pixel_sigma, 0.01, 0.0015);
      if (pixel) {
        EXPECT_EQ(r.frames[i].noise_sigma, pixel_sigma);
      } else {
        EXPECT_EQ(r.frames[i].noise_sigma, estimateNoiseSigma(f.image, f.valid));
        EXPECT_GT(r.frames[i].noise_sigma, 1.5 * pixel_sigma);
      }
    }
    // The ghost is found either way (the slope is drawn by other ghosts, which this does not test).
    int found = 0;
    for (const auto& g : r.model.ghostsAt(1.0))
      found += std::abs(g.parameters.center_x - 58) < 0.5 && std::abs(g.parameters.left - 15) < 0.5;
    EXPECT_EQ(found, 1) << "pixel noise " << pixel;
  }
}

// A sharp ghost on a pedestal (what many veils far wider than the frame, each too faint to see,
// sum to): the model holds the ghost where it is with its sharp outline, and the pedestal apart
// from it as glare, flat over the frame (fit/cost.h isGlare).
TEST(FitCapture, HoldsASharpGhostApartFromThePedestalUnderIt) {
  FrameStack stack = testStack();
  cv::theRNG().state = 9;
  model::GhostParameters glow;
  glow.center_x = 80;
  glow.center_y = 50;
  glow.left = glow.right = glow.height = 400;
  glow.border = {0.1, 0, 0};
  glow.inside = {0.1, 0, 0};
  glow.outside_falloff = 100;
  for (int i = 0; i < 9; ++i) {
    const double theta = 0.25 * i;
    Frame f = ghostFrame(stack, i, theta, {ghostAt(60 + 8 * theta, 0.5, 0.3), glow});
    addNoise(f, 0.005);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  const FitResult r = fitCapture(stack, options);
  int sharp = 0, glare = 0;
  for (const auto& at : r.model.ghostsAt(1.0)) {
    const auto& g = at.parameters;
    if (isGlare(g, stack.size)) {
      ++glare;
      std::vector<model::GhostParameters> one = {g};
      double lo = 0, hi = 0;
      cv::minMaxLoc(model::renderGhosts(one, stack.size, 1), &lo, &hi);
      EXPECT_NEAR(lo, 0.1, 0.005);
      EXPECT_EQ(lo, hi) << "the glare is flat over the frame";
    }
    if (std::abs(g.center_x - 68) < 0.5 && std::abs(g.left - 15) < 1 && std::abs(g.right - 15) < 1 &&
        g.outside_falloff < 5)
      ++sharp;
  }
  EXPECT_EQ(sharp, 1) << r.summary.BriefReport();
  EXPECT_EQ(glare, 1) << r.summary.BriefReport();
}

// A sharp ghost on a glow that rises towards the top and bottom edges, away from the flare axis,
// and fades with θ: a glare can hold its mean only, and detection looks for ghosts on the axis;
// the pedestal (model/pedestal.h) draws it, in the frames' fits and in the model.
TEST(FitCapture, DrawsTheGlowTheGhostsLeaveAsAPedestal) {
  FrameStack stack = testStack();
  cv::theRNG().state = 5;
  std::vector<cv::Mat> truth;
  for (int i = 0; i < 9; ++i) {
    const double theta = 0.25 * i;
    Frame f = ghostFrame(stack, i, theta, {ghostAt(50 + 8 * theta, 1, 0.4)});
    cv::Mat glow(stack.size, CV_32F);
    for (int y = 0; y < glow.rows; ++y)
      for (int x = 0; x < glow.cols; ++x) {
        const double v = (y + 0.5 - 50) / 160;  // model/pedestal.h's v
        glow.at<float>(y, x) = static_cast<float>((0.4 - 0.05 * theta) * v * v);
      }
    f.image += glow;
    truth.push_back(f.image.clone());
    addNoise(f, 0.005);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  // RMS of the frames' fits' and the model's images against the noise-free frames.
  auto errors = [&](const FitResult& r) {
    double fits = 0, model = 0;
    for (const FrameFit& ff : r.frames) {
      cv::Mat drawn = model::renderGhosts(ff.ghosts, stack.size, 1);
      ff.pedestal.addTo(drawn, stack.size);
      fits += std::pow(cv::norm(drawn, truth[ff.frame], cv::NORM_L2), 2);
      model += std::pow(cv::norm(r.model.render(ff.angle_deg), truth[ff.frame], cv::NORM_L2), 2);
    }
    const double n = double(r.frames.size()) * stack.size.area();
    return std::pair(std::sqrt(fits / n), std::sqrt(model / n));
  };
  options.pedestal = false;
  const FitResult without = fitCapture(stack, options);
  EXPECT_FALSE(without.model.pedestal.has_value());
  options.pedestal = true;
  const FitResult with = fitCapture(stack, options);
  ASSERT_TRUE(with.model.pedestal.has_value());
  const auto [fits_without, model_without] = errors(without);
  const auto [fits_with, model_with] = errors(with);
  // The glow is 0.039 at the edges at θ = 0 (8 σ of the noise).
  EXPECT_GT(fits_without, 0.01);
  EXPECT_GT(model_without, 0.01);
  EXPECT_LT(fits_with, 0.1 * fits_without);
  EXPECT_LT(model_with, 0.1 * model_without);
  // The ghost is found as it was.
  int found = 0;
  for (const auto& g : with.model.ghostsAt(1.0))
    found += std::abs(g.parameters.center_x - 58) < 0.5 && std::abs(g.parameters.left - 15) < 0.5;
  EXPECT_EQ(found, 1);
}

// Frames in which a fit's ghosts were carried through the light rather than fitted.
int carriedFrames(const FitResult& r) {
  int carried = 0;
  for (const auto& t : r.tracks)
    for (bool c : t.carried) carried += c;
  return carried;
}

// The image centre of testStack's frames, where every ghost is at θ = 0.
const cv::Point2d kAxisCentre(80, 50);

// The fit of 13 frames 0.25° apart (0–3°), each showing ghost(θ) and a point light that starts at
// the image centre and moves to −x by `light_px_per_deg`: a halo 20 / (1 + (r/3)²)^1.5 and a
// clipped core of 3 px radius (left out of the valid mask); noise σ 0.005.
FitResult fitBesideAMovingLight(double light_px_per_deg,
                                const std::function<model::GhostParameters(double)>& ghost) {
  FrameStack stack = testStack();
  cv::theRNG().state = 7;
  for (int i = 0; i < 13; ++i) {
    const double theta = 0.25 * i;
    const cv::Point2d light = kAxisCentre - cv::Point2d(light_px_per_deg * theta, 0);
    Frame f = ghostFrame(stack, i, theta, {ghost(theta)});
    for (int y = 0; y < f.image.rows; ++y)
      for (int x = 0; x < f.image.cols; ++x) {
        const double r = std::hypot(x + 0.5 - light.x, y + 0.5 - light.y);
        f.image.at<float>(y, x) += static_cast<float>(20 / std::pow(1 + (r / 3) * (r / 3), 1.5));
        if (r < 3) f.valid.at<uchar>(y, x) = 0;
      }
    addNoise(f, 0.005);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  return fitCapture(stack, options);
}

// Near θ = 0 a ghost is concentric with the light, and the light's point-symmetric estimate S
// takes it with the halo: its fit sinks into the noise. The fitter carries it from the frames
// where it stands clear of the light into the light, towards the image centre, as bright as it
// was, and the report marks those frames as carried.
TEST(FitCapture, CarriesAGhostIntoTheLightNearTheAxis) {
  // The light moves to −x, the ghost to +x: 30 px apart per degree.
  const FitResult r = fitBesideAMovingLight(20, [](double theta) {
    model::GhostParameters g;
    g.center_x = kAxisCentre.x + 10 * theta;
    g.center_y = kAxisCentre.y;
    g.left = g.right = 14;
    g.height = 13;
    g.border = {0.8, 0, 0};
    g.inside = {0.3, 0, 0};
    return g;
  });
  // At θ = 0: a ghost at the image centre, of about the true size and brightness.
  bool found = false;
  for (const auto& at : r.model.ghostsAt(0)) {
    const auto& g = at.parameters;
    found = found || (std::hypot(g.center_x - kAxisCentre.x, g.center_y - kAxisCentre.y) < 3 &&
                      std::abs(g.left - 14) < 3 && std::abs(g.right - 14) < 3 &&
                      std::abs(g.border[0] - 0.8) < 0.2);
  }
  EXPECT_TRUE(found) << r.summary.BriefReport();
  EXPECT_GT(carriedFrames(r), 0);
}

// A ghost larger than the light's zone keeps its parts beyond the zone in the data (S is kept only
// where the light's image is brighter than at the zone's edge), and its fits beside the light
// stand: it is fitted there, not carried, and keeps the size it has there. Carried, it kept the
// size of its nearest fit clear of the light (26 px here, against 30 at θ = 0). The light leaves
// the frame at 2°, as it does on the rig.
TEST(FitCapture, FitsAGhostLargerThanTheLightsZoneNearTheAxis) {
  const FitResult r = fitBesideAMovingLight(40, [](double theta) {
    model::GhostParameters g;  // shrinking by 4 px a degree
    g.center_x = kAxisCentre.x + 10 * theta;
    g.center_y = kAxisCentre.y;
    g.left = g.right = 30 - 4 * theta;
    g.height = 28 - 4 * theta;
    g.border = {0.4, 0, 0};
    g.inside = {0.1, 0, 0};
    return g;
  });
  EXPECT_EQ(carriedFrames(r), 0) << r.summary.BriefReport();
  bool found = false;
  for (const auto& at : r.model.ghostsAt(0)) {
    const auto& g = at.parameters;
    found = found || (std::hypot(g.center_x - kAxisCentre.x, g.center_y - kAxisCentre.y) < 3 &&
                      std::abs(g.left - 30) < 2 && std::abs(g.right - 30) < 2);
  }
  EXPECT_TRUE(found) << r.summary.BriefReport();
}

// A ghost that one frame does not show (there its fit sinks into the noise, as a faint veil's
// fit breaks down for a frame) ends one track and starts another: the two are one ghost, and the
// model has one, across that frame.
TEST(FitCapture, AGhostLostForOneFrameIsOneGhost) {
  FrameStack stack = testStack();
  cv::theRNG().state = 11;
  for (int i = 0; i < 13; ++i) {
    const double theta = 0.25 * i;
    const double brightness = i == 6 ? 0 : 1;
    Frame f = ghostFrame(stack, i, theta, {ghostAt(50 + 8 * theta, brightness, 0.4 * brightness)});
    addNoise(f, 0.01);
    stack.frames.push_back(f);
  }
  FitOptions options;
  options.progress = false;
  const FitResult r = fitCapture(stack, options);
  ASSERT_EQ(r.model.ghosts.size(), 1u) << r.summary.BriefReport();
  const auto at = r.model.ghostsAt(1.5);
  ASSERT_EQ(at.size(), 1u);
  EXPECT_NEAR(at[0].parameters.center_x, 62, 0.5);
}

}  // namespace
}  // namespace flarekit::fit
