#include "fit/fit_capture.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <set>
#include <sstream>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "common/error.h"
#include "common/image.h"
#include "common/log.h"
#include "common/progress.h"
#include "fit/evaluation.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

using model::GhostParameters;

bool TrackingOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (extrapolation_frames < 1) return fail("extrapolation_frames must be ≥ 1");
  if (extrapolation_degree < 0 || extrapolation_degree > 3) return fail("extrapolation_degree must be in [0, 3]");
  if (!(min_peak_sigma > 0)) return fail("min_peak_sigma must be > 0");
  if (!(min_visible_fraction >= 0 && min_visible_fraction <= 1)) return fail("min_visible_fraction must be in [0, 1]");
  if (!(min_cost_reduction >= 0 && min_cost_reduction <= 1)) return fail("min_cost_reduction must be in [0, 1]");
  if (!(unexplained_fraction > 0)) return fail("unexplained_fraction must be > 0");
  if (detect_every < 1) return fail("detect_every must be ≥ 1");
  if (min_track_frames < 1) return fail("min_track_frames must be ≥ 1");
  return true;
}

bool FitOptions::IsValid(std::string* error) const {
  if (!cost.IsValid(error) || !solver.IsValid(error) || !detection.IsValid(error) ||
      !tracking.IsValid(error) || !pedestal_fit.IsValid(error))
    return false;
  if (!auto_degree && (degree < 0 || degree > model::kMaxPolynomialDegree)) {
    if (error) *error = "degree must be in [0, " + std::to_string(model::kMaxPolynomialDegree) + "]";
    return false;
  }
  if (joint_refine_sweeps < 0) {
    if (error) *error = "joint_refine_sweeps must be ≥ 0";
    return false;
  }
  if (threads < 1) {
    if (error) *error = "threads must be ≥ 1";
    return false;
  }
  return true;
}

std::string FitSummary::BriefReport() const {
  std::ostringstream s;
  s.precision(3);
  s << "Fitted " << ghosts << " ghost(s) over " << frames_fitted << " of " << frames_total
    << " frames with " << optimizer << " in " << seconds_total << " s (fitting " << seconds_fitting
    << " s, detection " << seconds_detecting << " s, model " << seconds_modelling << " s); "
    << detections << " ghost(s) detected, " << detections_rejected << " candidate(s) rejected, "
    << ghosts_dropped_short << " short track(s) dropped; " << iterations << " iterations, " << evaluations
    << " cost evaluations; polynomial degree " << (degree < 0 ? std::string("auto") : std::to_string(degree)) << ".";
  if (!unexplained.empty()) {
    s << " Not described by the model in part of their frames:";
    for (const auto& [id, fraction] : unexplained) s << " ghost " << id << " (" << 100 * fraction << " %)";
    s << ".";
  }
  if (!warnings.empty()) s << " " << warnings.size() << " warning(s).";
  return s.str();
}

// ── Polynomials ───────────────────────────────────────────────────────────────────────────────

namespace {

// A polynomial in the centred, scaled variable t = (θ − t0) / scale, solved there for conditioning.
struct CentredPolynomial {
  Eigen::VectorXd a;
  double t0 = 0, scale = 1;
  double evaluate(double angle) const {
    const double t = (angle - t0) / scale;
    double v = 0;
    for (int k = static_cast<int>(a.size()) - 1; k >= 0; --k) v = v * t + a(k);
    return v;
  }
};

// The centred variable for `angles` (not empty): t0 their mean, scale their largest distance from it.
CentredPolynomial centredVariable(const std::vector<double>& angles) {
  CentredPolynomial p;
  p.t0 = std::accumulate(angles.begin(), angles.end(), 0.0) / static_cast<double>(angles.size());
  p.scale = 0;
  for (double a : angles) p.scale = std::max(p.scale, std::abs(a - p.t0));
  if (p.scale <= 0) p.scale = 1;
  return p;
}

// Weighted least squares (weights empty: all 1) of `degree`, lowered to what the points allow.
CentredPolynomial solveCentred(const std::vector<double>& angles, const std::vector<double>& values,
                               const std::vector<double>& weights, int degree) {
  const int n = static_cast<int>(angles.size());
  CentredPolynomial p = centredVariable(angles);
  degree = std::clamp(degree, 0, n - 1);
  Eigen::MatrixXd A(n, degree + 1);
  Eigen::VectorXd b(n);
  for (int i = 0; i < n; ++i) {
    const double t = (angles[i] - p.t0) / p.scale;
    const double w = weights.empty() ? 1.0 : std::sqrt(weights[i]);
    double power = 1;
    for (int k = 0; k <= degree; ++k, power *= t) A(i, k) = w * power;
    b(i) = w * values[i];
  }
  p.a = A.colPivHouseholderQr().solve(b);
  return p;
}

// Σ a_k ((θ − t0)/s)^k expanded into powers of θ, as the model file stores it.
model::Polynomial expanded(const CentredPolynomial& centred) {
  const int d = static_cast<int>(centred.a.size()) - 1;
  std::vector<double> c(d + 1, 0.0);
  for (int k = 0; k <= d; ++k) {
    const double ak = centred.a(k) / std::pow(centred.scale, k);
    double binom = 1;  // C(k, j)
    for (int j = 0; j <= k; ++j) {
      c[j] += ak * binom * std::pow(-centred.t0, k - j);
      binom = binom * (k - j) / (j + 1);
    }
  }
  return {c};
}

}  // namespace

model::Polynomial fitPolynomial(const std::vector<double>& angles, const std::vector<double>& values,
                                int degree) {
  if (angles.empty()) return {{0.0}};
  return expanded(solveCentred(angles, values, {}, degree));
}

std::vector<bool> polynomialInliers(const std::vector<double>& angles,
                                    const std::vector<double>& values, int degree) {
  const int n = static_cast<int>(angles.size());
  std::vector<bool> inlier(n, true);
  // Too few frames to tell a spike from the curve.
  if (n < degree + 3) return inlier;
  std::vector<double> magnitudes;
  for (double v : values) magnitudes.push_back(std::abs(v));
  // Below this a residual is rounding, not evidence: 1e-3 of the parameter's typical size.
  const double floor = 1e-3 * medianOf(magnitudes) + 1e-12;
  // Least absolute deviations by iteratively reweighted least squares: unlike least squares, the
  // curve is not pulled towards a single wild value, whatever its size.
  std::vector<double> weights(n, 1.0), residuals(n, 0.0);
  for (int iteration = 0; iteration < 30; ++iteration) {
    const CentredPolynomial p = solveCentred(angles, values, weights, degree);
    for (int i = 0; i < n; ++i) {
      residuals[i] = std::abs(values[i] - p.evaluate(angles[i]));
      weights[i] = 1.0 / std::max(residuals[i], floor);
    }
  }
  // Frames beyond 4 robust σ (MAD) of that curve are spikes.
  const double limit = std::max(4 * 1.4826 * medianOf(residuals), 10 * floor);
  for (int i = 0; i < n; ++i) inlier[i] = residuals[i] <= limit;
  return inlier;
}

GhostParameters extrapolate(const std::vector<double>& angles, const std::vector<GhostParameters>& fits,
                            double angle, int frames, int degree) {
  const int n = static_cast<int>(angles.size());
  // The `frames` fits nearest to the angle.
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) {
    return std::abs(angles[a] - angle) < std::abs(angles[b] - angle);
  });
  order.resize(std::min(n, frames));
  const int channels = fits[0].channels;
  const int count = model::parameterCount(channels);
  std::vector<double> a;
  std::vector<std::vector<double>> v(count);
  for (int i : order) {
    a.push_back(angles[i]);
    auto p = model::toParameterVector(fits[i]);
    for (int k = 0; k < count; ++k) v[k].push_back(p[k]);
  }
  // Fewer points than 2 × (degree + 1) make extrapolations noisy: lower the degree.
  const int d = std::min(degree, std::max(0, static_cast<int>(a.size()) / 2 - 1));
  // With 2–3 fits, degree 0: their mean, which seeds a moving ghost half the track behind (12-frame
  // CLI hold-out capture at 1.2°: 8 px). Seeding from the nearest fit instead was measured (stop
  // 41) on the Heliar 640×427 capture, λ × 0.98–1.01: the model's recall / precision / median PSNR
  // / centroid error 68.8 % / 78.0 % / 25.7 dB / 8.5 px against 73.1 / 81.6 / 25.8 / 7.7 over
  // five λ. Not taken.
  std::vector<double> out(count);
  for (int k = 0; k < count; ++k) out[k] = fitPolynomial(a, v[k], d).evaluate(angle);
  return model::clampToBounds(model::fromParameterVector(out, channels));
}

namespace {

bool polynomialWithinBounds(const model::Polynomial& p, const model::ParameterBounds& b, double lo, double hi) {
  // A small margin: the model file's own check samples the range with its own rounding.
  const double margin_lo = 1e-6 * std::max(1.0, std::abs(b.lower));
  const double margin_hi = b.upper >= model::kUnbounded ? 0 : 1e-6 * std::max(1.0, std::abs(b.upper));
  for (int i = 0; i <= 256; ++i) {
    const double v = p.evaluate(lo + (hi - lo) * i / 256.0);
    if (!std::isfinite(v) || v < b.lower + margin_lo || v > b.upper - margin_hi) return false;
  }
  return true;
}

bool polynomialWithinBounds(const model::Polynomial& p, int index, int channels, double lo, double hi) {
  return polynomialWithinBounds(p, model::parameterBounds(index, channels), lo, hi);
}

// The bounds of a track's model: the model's own, with its Ib and Ii at most
// kTrackIntensityBound × the brightest Ib or Ii of the track's fits. Where a ghost's inside
// fall-off Fi runs far deeper than its outline (a small piece of a caustic, fits held at Fi's and
// Ei's bounds), its image shows only (Ii − Ib)·(depth / Fi)^Ei inside, and the image-space solves
// (fitIntensitiesInImage, refineTrackInImage) took Ii anywhere along that product: Brendel Tessar
// 640×427, λ × 1, track 39 at 3.6–6.8°, fits' Ii 0.0031, the model's 5.4e18 (test
// BuildFlareModel.AGhostWhoseInsideFallOffRunsBeyondItsOutlineKeepsItsFitsBrightness). Over
// λ × 0.98–1.02 on the 640×427 captures, 33 ghosts of the ten models ran brighter than 10 × their
// fits' brightest (up to 1.7e21 ×); bounded, none (at most 3.9 ×). Means over the five λ, recall %
// / precision % / median PSNR dB / median centroid error px (bench/fit_accuracy.sh), unbounded →
// bounded: Heliar 74.7 / 81.5 / 25.9 / 7.1 → 74.1 / 81.3 / 25.9 / 7.0, Tessar 77.2 / 59.5 / 26.8
// / 10.9 → 77.2 / 59.5 / 26.8 / 10.8; held out (--holdout odd), Heliar 80.5 / 78.2 / 24.9 / 8.1
// → 77.8 / 76.6 / 24.9 / 7.8 (recall lower at every λ, by 0.7–6.9 points: ghosts moved by their
// neighbours' change in the joint sweeps), Tessar 74.4 / 62.9 / 26.1 / 13.2 → 74.0 / 63.2 / 26.2 /
// 12.8, and held-out frames below 10 dB 9 → 6. Bounded, a refinement can still trade Fi for the
// Ii it may not take (Tessar λ × 0.98 held out, 2.2°: a ghost's Fi 503 → 63 px at Ii 0.62 →
// 0.14, its middle 170 × brighter, the frame at −24.3 dB).
constexpr double kTrackIntensityBound = 4;
std::vector<model::ParameterBounds> trackBounds(const GhostTrackFit& t, int channels) {
  std::vector<model::ParameterBounds> bounds;
  for (int k = 0; k < model::parameterCount(channels); ++k) bounds.push_back(model::parameterBounds(k, channels));
  double brightest = 0;
  for (const GhostParameters& f : t.fits)
    for (int c = 0; c < f.channels; ++c) brightest = std::max({brightest, f.border[c], f.inside[c]});
  if (brightest > 0) {
    const model::ParameterLayout layout{channels};
    for (int c = 0; c < channels; ++c)
      bounds[layout.ib(c)].upper = bounds[layout.ii(c)].upper = kTrackIntensityBound * brightest;
  }
  return bounds;
}

int autoDegree(const std::vector<double>& a, const std::vector<double>& v) {
  // Held-out error: fit on every other frame, measure on the rest (and the other way round).
  int best = 1;
  double best_error = std::numeric_limits<double>::infinity();
  for (int d = 1; d <= 4; ++d) {
    double error = 0;
    int used = 0;
    for (int parity = 0; parity < 2; ++parity) {
      std::vector<double> ta, tv;
      for (size_t i = 0; i < a.size(); ++i)
        if (static_cast<int>(i % 2) == parity) {
          ta.push_back(a[i]);
          tv.push_back(v[i]);
        }
      if (static_cast<int>(ta.size()) < d + 2) continue;
      const auto p = fitPolynomial(ta, tv, d);
      for (size_t i = 0; i < a.size(); ++i)
        if (static_cast<int>(i % 2) != parity) {
          const double e = p.evaluate(a[i]) - v[i];
          error += e * e;
          ++used;
        }
    }
    if (used == 0) break;
    error /= used;
    // A higher degree must earn its place: 2 % lower error.
    if (error < 0.98 * best_error) {
      best_error = error;
      best = d;
    }
  }
  return best;
}

// Intersection over union of two ghosts' outline bounding boxes (0 when both are empty).
// Whole boxes, though a veil's part beyond the frame is unseen and its fits trade it freely:
// with the boxes clipped to the frame (for sameGhost, the tracks' joins and splits), the large
// veils' fits were taken for one another, and the Heliar 640×427 model over λ × 0.98–1.02 fell
// to a recall of 54.9 % (40.6–72.7) and a median PSNR of 19.5 dB, against 77.2 % and 25.4 dB.
double outlineIoU(const GhostParameters& a, const GhostParameters& b) {
  const cv::Rect2d box_a = model::outlineBounds(a), box_b = model::outlineBounds(b);
  const double overlap = (box_a & box_b).area(), joint = box_a.area() + box_b.area() - overlap;
  return joint > 0 ? overlap / joint : 0.0;
}

// A level of k×k-pixel averages of an image of `image_size`, k the largest that leaves at least
// about `pixels`: where the model's ghosts are compared with the fits in image space (brightness
// and outlines, not a pixel's detail).
struct ImageLevel {
  ImageLevel(cv::Size image_size, double pixels) : image_size(image_size) {
    const int factor = std::max(1, static_cast<int>(std::sqrt(image_size.area() / pixels)));
    size = cv::Size(std::max(1, image_size.width / factor), std::max(1, image_size.height / factor));
    view.scale = 1.0 / factor;
  }
  cv::Size image_size;  // the capture's
  cv::Size size;
  model::ViewTransform view;
};

// Refits the Ib and Ii polynomials of `g` (the other parameters' polynomials fixed) in image
// space: the intensity transfer is linear in Ib and Ii (model/intensity.h), so the coefficients
// that bring the model's ghost closest, in least squares over pixels, to the fit of every frame in
// `use` are one linear solve. Polynomials of Ib and Ii on their own ignore that the fits trade
// brightness against fall-off from frame to frame (a frame-filling veil: a bright plateau outside
// a small outline in one frame, a bright inside in the next): evaluated with the fall-off
// polynomials they made the Heliar veil twice the frames' brightness at 19.5°. The degree is
// lowered until every polynomial stays within bounds; returns false (g unchanged) when even
// constants do not.
bool fitIntensitiesInImage(const GhostTrackFit& t, const std::vector<bool>& use, cv::Size image_size,
                           int channels, int degree, model::GhostTrack& g) {
  std::vector<int> frames;
  std::vector<double> angles;
  for (size_t i = 0; i < t.fits.size(); ++i)
    if (use[i]) {
      frames.push_back(static_cast<int>(i));
      angles.push_back(t.angles_deg[i]);
    }
  if (frames.empty()) return false;
  const ImageLevel level(image_size, 40000);
  const cv::Size size = level.size;
  const model::ViewTransform& view = level.view;
  const model::RenderOptions render;
  // Per frame: the fit's image (the target) and the unit border and inside images of the ghost
  // the other polynomials give at that angle.
  struct FrameImages {
    cv::Mat target, border, inside;
  };
  std::vector<FrameImages> images;
  for (int i : frames) {
    FrameImages f;
    const GhostParameters fit = t.fits[i];
    f.target = model::renderGhosts(std::span(&fit, 1), size, channels, render, view);
    GhostParameters shape = g.at(t.angles_deg[i], channels);
    shape.channels = 1;
    shape.border = {1, 0, 0};
    shape.inside = {0, 0, 0};
    f.border = model::renderGhosts(std::span(&shape, 1), size, 1, render, view);
    shape.border = {0, 0, 0};
    shape.inside = {1, 0, 0};
    f.inside = model::renderGhosts(std::span(&shape, 1), size, 1, render, view);
    images.push_back(std::move(f));
  }
  const model::ParameterLayout layout{channels};
  const std::vector<model::ParameterBounds> bounds = trackBounds(t, channels);
  constexpr double kEnergyWeight = 10;
  for (int d = std::min(degree, static_cast<int>(frames.size()) - 1); d >= 0; --d) {
    // Unknowns: a_k of Ib and b_k of Ii in the centred variable, the same for every channel's
    // design; one right-hand side per channel.
    const CentredPolynomial basis = centredVariable(angles);
    const int n = 2 * (d + 1);
    Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(n, n);
    Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(n, channels);
    Eigen::VectorXd phi(n);
    for (size_t f = 0; f < images.size(); ++f) {
      const double tt = (angles[f] - basis.t0) / basis.scale;
      std::vector<double> powers(d + 1, 1.0);
      for (int k = 1; k <= d; ++k) powers[k] = powers[k - 1] * tt;
      const FrameImages& im = images[f];
      Eigen::VectorXd phi_sum = Eigen::VectorXd::Zero(n);
      // All of the fit's light, also where the model's ghost does not reach.
      const cv::Scalar light = cv::sum(im.target);
      Eigen::VectorXd target_sum(channels);
      for (int c = 0; c < channels; ++c) target_sum(c) = light[c];
      double support = 0;
      for (int y = 0; y < size.height; ++y) {
        const float* wb = im.border.ptr<float>(y);
        const float* wi = im.inside.ptr<float>(y);
        const float* target = im.target.ptr<float>(y);
        for (int x = 0; x < size.width; ++x) {
          if (wb[x] == 0 && wi[x] == 0) continue;
          for (int k = 0; k <= d; ++k) {
            phi(k) = powers[k] * wb[x];
            phi(d + 1 + k) = powers[k] * wi[x];
          }
          normal.selfadjointView<Eigen::Lower>().rankUpdate(phi);
          for (int c = 0; c < channels; ++c) rhs.col(c) += phi * target[x * channels + c];
          phi_sum += phi;
          support += 1;
        }
      }
      // The frame's light as well: λ·n·(mean residual)², λ = kEnergyWeight. Pixel least squares
      // alone leaves the energy off where the fixed fall-off differs from the fit's (a test
      // track 15 % short); a prediction's estimators are means of light.
      if (support > 0) {
        normal.selfadjointView<Eigen::Lower>().rankUpdate(phi_sum, kEnergyWeight / support);
        rhs += (kEnergyWeight / support) * phi_sum * target_sum.transpose();
      }
    }
    normal = normal.selfadjointView<Eigen::Lower>();
    if (normal.trace() <= 0) return false;
    const Eigen::MatrixXd solution = normal.ldlt().solve(rhs);
    std::vector<model::Polynomial> border(channels), inside(channels);
    bool within = solution.allFinite();
    for (int c = 0; c < channels && within; ++c) {
      CentredPolynomial pb = basis, pi = basis;
      pb.a = solution.col(c).head(d + 1);
      pi.a = solution.col(c).tail(d + 1);
      border[c] = expanded(pb);
      inside[c] = expanded(pi);
      within = polynomialWithinBounds(border[c], bounds[layout.ib(c)], g.angle_min_deg, g.angle_max_deg) &&
               polynomialWithinBounds(inside[c], bounds[layout.ii(c)], g.angle_min_deg, g.angle_max_deg);
    }
    if (!within) continue;
    for (int c = 0; c < channels; ++c) {
      g.parameters[layout.ib(c)] = border[c];
      g.parameters[layout.ii(c)] = inside[c];
    }
    return true;
  }
  return false;
}

// Refines every polynomial of `g` at once in image space (ours; the paper stops at polynomials
// through each parameter, Walch et al. 2018 §3.3.3): Gauss–Newton with Marquardt's damping on the
// coefficients, so that the model's ghost comes closest to the track's fit in every frame,
// rendered, each frame's squared error divided by the square of its flare's peak (`frame_peaks`:
// angle → the brightest fit of that frame), as PSNR weighs it. Polynomials through each parameter
// on its own summarise a track whose fits trade one parameter against another from frame to frame,
// and there they draw none of the fits: on the Heliar 640×427 capture the fits gave a median PSNR
// against the noise-free flare of 29.3 dB and the model 24.5 dB. Its glare at 0–1.6°, whose fits
// held Ii between 1.6e-4 and 0.33 behind inside exponents of 1 to 10, came out with Ii 0.04 and an
// exponent of 6.8: 150× the fit's brightness at 0°.
// The unknowns are changes of each polynomial in the centred variable, within the degree it has;
// the Jacobian is the renderer's derivative images times powers of θ, and the normal equations are
// built from each frame's Gram matrix of those images. A parameter whose polynomial a step takes
// out of its bounds inside the range is held where it is from then on; the mirror axis My is held
// from the start.
// Rendered at 10000 pixels (a quarter of the 640×427 frame's): at 20000 the Heliar and Tessar
// 640×427 models' recall, precision, PSNR and centroid error (means over λ × 0.99 / 1 / 1.01) were
// the same to 0.3 (% / dB / px), and the Heliar's model step took 8.7 s instead of 14.3 s.
constexpr double kRefinePixels = 10000;

void refineTrackInImage(const GhostTrackFit& t, const ImageLevel& level, int channels,
                        const std::vector<cv::Mat>& targets, const std::map<double, double>& frame_peaks,
                        model::GhostTrack& g) {
  if (t.fits.size() < 2) return;
  const std::vector<double>& angles = t.angles_deg;
  const cv::Size size = level.size;
  const cv::Rect roi(0, 0, size.width, size.height);
  const model::ViewTransform& view = level.view;
  const model::RenderOptions render;
  std::vector<double> weights;
  for (double angle : angles) {
    const double peak = frame_peaks.at(angle);
    weights.push_back(1.0 / std::max(peak * peak, 1e-30));
  }
  const int count = model::parameterCount(channels);
  const CentredPolynomial basis = centredVariable(angles);
  std::vector<int> offset(count + 1, 0);  // unknowns of parameter k: offset[k] … offset[k+1] − 1
  for (int k = 0; k < count; ++k)
    offset[k + 1] = offset[k] + static_cast<int>(g.parameters[k].coefficients.size());
  const int n = offset[count];
  std::vector<int> parameter_of(n);  // the parameter of each unknown
  for (int k = 0; k < count; ++k) std::fill(parameter_of.begin() + offset[k], parameter_of.begin() + offset[k + 1], k);
  // The model's bounds, and a sharp track's outside fall-off within the sharp bound its fits were
  // held to (fit/cost.h fitBounds), so that a sharp ghost's model is sharp too. With the model's
  // bounds alone the refinement softened sharp ghosts into glare, as if to draw light of their
  // neighbours': on the 640×427 captures (0–30° at 0.2°, five λ × 0.98–1.02) the Heliar models
  // held 175–210 ghost-frames of glare and the Tessar's 209–335, where the frames' fits had one a
  // frame, 151 (Tessar λ × 1, track 9 at 0.6–2.2°: the fits' Fo 0–77 px, the model's 3167 px).
  // fit-eval finds no ghost with a glare (fit/evaluation.h), so held, the models' recall rose to
  // that of the frames' fits; means over the five λ, recall / precision / median PSNR / median
  // centroid error, model's bounds → held (bench/fit_accuracy.sh):
  //   Heliar Tronnier: 68.5 → 75.3 %, 82.1 → 82.1 %, 25.4 → 25.0 dB, 7.4 → 7.3 px;
  //   Brendel Tessar:  66.9 → 77.8 %, 62.5 → 60.0 %, 25.2 → 25.2 dB, 11.1 → 11.6 px;
  // held out (--holdout odd), Heliar 71.6 → 80.8 %, 76.9 → 78.3 %, 24.5 → 24.6 dB, 7.7 → 7.6 px;
  // Tessar 63.0 → 74.1 %, 64.9 → 63.1 %, 24.6 → 24.6 dB, 13.1 → 12.5 px. The Heliar's PSNR fell at
  // every λ (by 0.2–0.6 dB): the light the softened ghosts drew that no fit holds. Held within
  // all of the fits' fitBounds (the centre, sizes and Fi too), the same five λ gave the same:
  // Heliar 75.3 / 82.2 / 25.0 / 7.2, Tessar 77.8 / 60.1 / 25.2 / 11.1.
  std::vector<model::ParameterBounds> bounds = trackBounds(t, channels);
  const cv::Size image = level.image_size;
  if (std::none_of(t.fits.begin(), t.fits.end(), [&](const GhostParameters& f) { return isGlare(f, image); })) {
    const int fo = model::ParameterLayout{channels}.fo();
    bounds[fo].upper = fitBounds(fo, channels, image, model::kUnbounded, false).upper;
  }
  // Σ_frames w ‖model − fit‖², and with `jtj`, `jtr`: JᵀJ and Jᵀr of that sum.
  auto evaluate = [&](const model::GhostTrack& track, Eigen::MatrixXd* jtj, Eigen::VectorXd* jtr) {
    double cost = 0;
    if (jtj) {
      *jtj = Eigen::MatrixXd::Zero(n, n);
      *jtr = Eigen::VectorXd::Zero(n);
    }
    for (size_t f = 0; f < angles.size(); ++f) {
      const GhostParameters q = track.at(angles[f], channels);
      cv::Mat residual;
      model::RenderedGhosts r;
      if (jtj) {
        r = model::renderGhostsWithDerivatives(std::span(&q, 1), roi, channels, render, view);
        residual = r.image - targets[f];
      } else {
        residual = model::renderGhosts(std::span(&q, 1), size, channels, render, view) - targets[f];
      }
      cost += weights[f] * residual.dot(residual);
      if (!jtj) continue;
      const model::GhostDerivativeImages& d = r.derivatives[0];
      if (d.rect.empty()) continue;
      // The frame's Gram matrix G = Σ_x D Dᵀ and gradient Σ_x D r of the derivative images D over
      // the pixels they reach, by one matrix product.
      const cv::Mat res = residual(d.rect);
      const int row_values = d.rect.width * channels;
      Eigen::MatrixXd rows(static_cast<Eigen::Index>(d.rect.height) * row_values, count);
      Eigen::VectorXd values(rows.rows());
      Eigen::Index used = 0;
      for (int y = 0; y < d.rect.height; ++y) {
        const float* rr = res.ptr<float>(y);
        for (int x = 0; x < row_values; ++x) {
          bool any = false;
          for (int k = 0; k < count; ++k) {
            const float v = d.images[k].ptr<float>(y)[x];
            rows(used, k) = v;
            any = any || v != 0;
          }
          if (!any) continue;
          values(used++) = rr[x];
        }
      }
      const auto reached = rows.topRows(used);
      Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(count, count);
      gram.selfadjointView<Eigen::Lower>().rankUpdate(reached.transpose());
      gram = gram.selfadjointView<Eigen::Lower>();
      const Eigen::VectorXd grad = reached.transpose() * values.head(used);
      // J columns of parameter k's coefficient j: D_k · t^j.
      const double tt = (angles[f] - basis.t0) / basis.scale;
      Eigen::VectorXd power(n);
      for (int k = 0; k < count; ++k) {
        double pw = 1;
        for (int j = offset[k]; j < offset[k + 1]; ++j, pw *= tt) power(j) = pw;
      }
      for (int a = 0; a < n; ++a) {
        (*jtr)(a) += weights[f] * power(a) * grad(parameter_of[a]);
        for (int b = 0; b <= a; ++b)
          (*jtj)(a, b) += weights[f] * power(a) * power(b) * gram(parameter_of[a], parameter_of[b]);
      }
    }
    if (jtj) *jtj = jtj->selfadjointView<Eigen::Lower>();
    return cost;
  };
  // The track with each polynomial changed by δ (coefficients in the centred variable); `left`
  // marks the parameters whose polynomial the step takes out of bounds.
  auto stepped = [&](const model::GhostTrack& from, const Eigen::VectorXd& delta, std::vector<bool>& left) {
    model::GhostTrack to = from;
    for (int k = 0; k < count; ++k) {
      CentredPolynomial c = basis;
      c.a = delta.segment(offset[k], offset[k + 1] - offset[k]);
      const std::vector<double> change = expanded(c).coefficients;
      for (size_t j = 0; j < change.size(); ++j) to.parameters[k].coefficients[j] += change[j];
      left[k] = !polynomialWithinBounds(to.parameters[k], bounds[k], g.angle_min_deg, g.angle_max_deg);
    }
    return to;
  };
  Eigen::MatrixXd jtj;
  Eigen::VectorXd jtr;
  double cost = evaluate(g, &jtj, &jtr), mu = 1e-3;
  // Parameters held where they are: a step that took their polynomial out of bounds (a constant
  // at a bound, a fall-off against the diagonal) is solved again without them. Only the model's
  // bounds (and trackBounds's on Ib and Ii): the refinement also takes parameters where the image
  // hardly tells them apart (a
  // glare's centre 2800 px off the frame, Fi 20–90× deeper than the outline with Ii to match),
  // but held within the range of the track's fits (plus half of it), the model's median PSNR fell
  // (640×427 captures, λ × 1, Heliar / Tessar: 25.6 / 25.7 → 25.3 / 25.3 dB; held out 24.6 / 23.0
  // → 23.9 / 22.9 dB). With every fit's Fi first cut to the outline's greatest depth,
  // min((L + R)/2, h), and its Ii to match (the same image), it moved both ways (25.4 / 25.8 dB).
  std::vector<bool> held(count, false);
  // The mirror axis My stays where the fits' polynomial puts it. Ghosts are mirror-symmetric
  // about the flare axis (Walch et al. 2018 §3.2), and the fits find it (Heliar 640×427, λ × 1:
  // median 0.3 px off it), but a veil whose top and bottom lie beyond the frame shows the
  // refinement little of its axis, which it traded against h and the curvatures: in that model
  // 44 ghost-frames lay more than 5 px off the axis, up to 147 px (track 30, 6.8–13.2°: the fits'
  // My 211–217 px, the model's 206–286; test BuildFlareModel.RefinedInImageAVeilKeepsTheAxisItsFitsFound);
  // held: none, at most 4.4 px. Means over λ × 0.98–1.02 on the 640×427 captures (recall % /
  // precision % / median PSNR dB / median centroid error px, bench/fit_accuracy.sh), free → held:
  // Heliar 75.3 / 82.1 / 25.0 / 7.3 → 74.9 / 81.6 / 25.1 / 6.9, Tessar 77.8 / 60.0 / 25.2 / 11.6 →
  // 78.3 / 60.4 / 25.2 / 11.3: within the spread over λ, but each ghost drawn about its axis.
  // h still runs away there (track 30 at 12.8°: 1910 px against the fits' 294, and the model draws
  // no edge where the disc's is); held within the range of the track's fits ± 50 % as well, λ × 1
  // gave Heliar 77.5 / 80.4 / 25.6 / 7.0 → 78.2 / 82.4 / 25.2 / 7.7 and Tessar 78.3 / 55.2 /
  // 25.3 / 12.0 → 75.5 / 53.3 / 25.2 / 12.2, so h is left free.
  held[model::param::kMy] = true;
  // At 25 iterations, λ × 1 on the 640×427 captures: the models' median PSNR the same to 0.1 dB
  // (Heliar 25.6 → 25.5, Tessar 25.9 → 26.0), and the Tessar's fit took 72.6 s against 57.6–62.9.
  constexpr int kMaxIterations = 10;
  for (int it = 0, rejected = 0; it < kMaxIterations && rejected < 8;) {
    Eigen::MatrixXd a = jtj;
    Eigen::VectorXd b = -jtr;
    const double damping_floor = 1e-12 * jtj.diagonal().maxCoeff();
    for (int i = 0; i < n; ++i) a(i, i) += mu * std::max(jtj(i, i), damping_floor);
    for (int k = 0; k < count; ++k) {
      if (!held[k]) continue;
      for (int i = offset[k]; i < offset[k + 1]; ++i) {
        a.row(i).setZero();
        a.col(i).setZero();
        a(i, i) = 1;
        b(i) = 0;
      }
    }
    const Eigen::VectorXd delta = a.ldlt().solve(b);
    if (!delta.allFinite()) break;
    std::vector<bool> left(count, false);
    model::GhostTrack trial = stepped(g, delta, left);
    bool newly_held = false;
    for (int k = 0; k < count; ++k)
      if (left[k] && !held[k]) held[k] = newly_held = true;
    if (newly_held) continue;
    // With its derivatives at once: most steps are taken, and the rendering with derivatives draws
    // the same image.
    Eigen::MatrixXd trial_jtj;
    Eigen::VectorXd trial_jtr;
    const double trial_cost = evaluate(trial, &trial_jtj, &trial_jtr);
    if (trial_cost < cost) {
      const bool converged = cost - trial_cost < 1e-4 * cost;
      g = std::move(trial);
      cost = trial_cost;
      jtj = std::move(trial_jtj);
      jtr = std::move(trial_jtr);
      mu = std::max(mu / 3, 1e-9);
      ++it;
      rejected = 0;
      if (converged) break;
    } else {
      mu *= 4;
      ++rejected;
    }
  }
}

// The ghosts' polynomials refined together, in `sweeps` Jacobi sweeps of refineTrackInImage: each
// ghost towards its own model image plus half of what all the model's ghosts together still miss
// of the sum of the fits in each of its frames. Refined one by one, each ghost comes closest to
// its own fits, but the fits of overlapping ghosts trade light and shape from frame to frame (a
// frame-wide veil's edges beyond the frame: Heliar 640×427, λ × 1, ghost 61 had Mx 615, L 706,
// R 97 at 18.0° and Mx 345, L 364, R 364 at 18.2°), which no polynomial follows, while their sum,
// the frame, changes smoothly; a ghost can make up there for what its neighbours' polynomials
// miss. Half, because every ghost over a shortfall moves to fill it at once.
// Towards the frames themselves instead of the fits' sum (the frame without the light's image,
// averaged to the level's pixels, where every pixel is valid), the model's median PSNR rose (means
// over λ × 0.98–1.02 on the 640×427 captures, Heliar / Tessar: 25.8 / 25.5 → 26.3 / 26.1 dB),
// but the large veils' models moved to cover the light of the veils no fit found: recall fell
// 73.1 / 75.0 → 72.2 / 72.9 % and the median centroid error rose 7.7 / 10.6 → 8.5 / 11.9 px
// (true ghosts of radius ≥ 200 px: 15.5 → 17.4 px, Heliar). With those veils' shapes held, the
// PSNR fell below the fits' sum's (λ × 1: 25.3 / 25.3 against 25.6 / 25.7 dB).
void refineTracksTogether(const std::vector<GhostTrackFit>& tracks,
                          const std::vector<std::vector<cv::Mat>>& fit_images,
                          const std::map<double, double>& frame_peaks, const ImageLevel& level,
                          int channels, int sweeps, std::vector<model::GhostTrack>& ghosts) {
  constexpr double kRelaxation = 0.5;
  // Per fitted frame (by angle), the sum of the tracks' images there.
  auto sumByAngle = [&](const std::vector<std::vector<cv::Mat>>& images) {
    std::map<double, cv::Mat> sum;
    for (size_t i = 0; i < tracks.size(); ++i)
      for (size_t j = 0; j < images[i].size(); ++j) {
        cv::Mat& s = sum[tracks[i].angles_deg[j]];
        if (s.empty())
          s = images[i][j].clone();
        else
          s += images[i][j];
      }
    return sum;
  };
  const std::map<double, cv::Mat> fits_sum = sumByAngle(fit_images);
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    std::vector<std::vector<cv::Mat>> model_images(tracks.size());
    tbb::parallel_for(size_t{0}, tracks.size(), [&](size_t i) {
      for (double angle : tracks[i].angles_deg) {
        const GhostParameters q = ghosts[i].at(angle, channels);
        model_images[i].push_back(
            model::renderGhosts(std::span(&q, 1), level.size, channels, {}, level.view));
      }
    });
    const std::map<double, cv::Mat> model_sum = sumByAngle(model_images);
    tbb::parallel_for(size_t{0}, tracks.size(), [&](size_t i) {
      std::vector<cv::Mat> targets;
      for (size_t j = 0; j < model_images[i].size(); ++j) {
        const double angle = tracks[i].angles_deg[j];
        targets.push_back(model_images[i][j] +
                          kRelaxation * (fits_sum.at(angle) - model_sum.at(angle)));
      }
      refineTrackInImage(tracks[i], level, channels, targets, frame_peaks, ghosts[i]);
    });
  }
}

// A track's ghost with each parameter a polynomial through its fits: buildFlareModel's first
// step, before the intensities are solved in image space (which the outline does not depend on).
struct PolynomialGhost {
  model::GhostTrack ghost;
  std::vector<bool> image_inliers;  // the fits in which no parameter is a spike
  int intensity_degree = 0;         // the highest degree of Ib's and Ii's polynomials
};

PolynomialGhost polynomialsThroughFits(const GhostTrackFit& t, cv::Size image_size, int channels,
                                       int degree, double range_margin_deg, double capture_min_deg,
                                       double capture_max_deg) {
  PolynomialGhost out;
  model::GhostTrack& g = out.ghost;
  std::vector<bool>& image_inliers = out.image_inliers;
  g.id = t.id;
  g.angle_min_deg = std::max(capture_min_deg, std::min(t.angles_deg.front(), t.angles_deg.front() - range_margin_deg));
  g.angle_max_deg = std::min(capture_max_deg, std::max(t.angles_deg.back(), t.angles_deg.back() + range_margin_deg));
  const int count = model::parameterCount(channels);
  const model::ParameterLayout layout{channels};
  // Frames where no parameter is a spike: only there can the model's ghost be compared with the
  // fit in image space (fitIntensitiesInImage). With the intensities' spikes alone left out, a
  // frame fitted with half its outline hidden in the light's core (L 3 px instead of 14) set the
  // model's Ib at the track's end to 0.45 where every fit had 0.8.
  image_inliers.assign(t.fits.size(), true);
  // Veiling glare spans the capture (fit/cost.h isGlare: one track of all 151 frames on the
  // 640×427 captures), and its pedestal falls 20× over 0–30° (Tessar λ × 1: the fits' Ii
  // 1.7e-4 → 8.2e-6), which a parabola does not follow: at 30° its model drew 2× the fits'
  // pedestal over the whole frame, 20 dB against the fits' 31 (test
  // BuildFlareModel.AGlareFollowsItsPedestalOverTheCapture). Its polynomials take at least
  // kGlareDegree. Means over λ × 0.98–1.02 (recall % / precision % / median PSNR dB / median
  // centroid error px, bench/fit_accuracy.sh), degree 2 → 4: Heliar 74.9 / 81.6 / 25.1 / 6.9 →
  // 74.7 / 81.5 / 25.1 / 7.1, Tessar 78.3 / 60.4 / 25.2 / 11.3 → 77.2 / 59.5 / 26.2 / 10.9, the
  // Tessar's PSNR higher at every λ (by 0.5–1.6 dB); held out (--holdout odd), Heliar 81.0 /
  // 78.5 / 24.6 / 7.2 → 80.5 / 78.2 / 24.6 / 8.1, Tessar 74.1 / 63.1 / 24.5 / 12.4 → 74.3 / 62.9 /
  // 25.2 / 13.2. The frames' fits are the same.
  const bool glare = std::all_of(t.fits.begin(), t.fits.end(),
                                 [&](const GhostParameters& f) { return isGlare(f, image_size); });
  const int ghost_degree = glare && degree >= 0 ? std::max(degree, kGlareDegree) : degree;
  for (int k = 0; k < count; ++k) {
    std::vector<double> all;
    for (const auto& f : t.fits) all.push_back(model::toParameterVector(f)[k]);
    // Frames where the fit jumped away from its neighbours for a frame (into the light or a
    // neighbouring ghost) are left out: one Heliar frame's Ii 700× its neighbours' set a
    // ghost's brightness over its whole range.
    const std::vector<bool> inlier =
        polynomialInliers(t.angles_deg, all, ghost_degree < 0 ? 2 : ghost_degree);
    std::vector<double> a, v;
    for (size_t i = 0; i < all.size(); ++i)
      if (inlier[i]) {
        a.push_back(t.angles_deg[i]);
        v.push_back(all[i]);
      }
    int d = ghost_degree < 0 ? autoDegree(a, v) : ghost_degree;
    model::Polynomial p = fitPolynomial(a, v, d);
    // Lower the degree until the polynomial stays within the parameter's bounds over the
    // range (degree 0, a constant clamped into them, always does).
    while (!polynomialWithinBounds(p, k, channels, g.angle_min_deg, g.angle_max_deg) && d > 0)
      p = fitPolynomial(a, v, --d);
    if (d == 0) {
      // The constant is the median: a short track too wild for a curve (three Heliar frames
      // with Ib 8e-5, 0.0075 and 0.043 and fall-offs of 332, 3 and 18 px) is not summarised
      // by a mean that pairs the brightest border with the widest glow.
      // A constant at a bound (fits that ran into it) is moved a hair inside, where the model
      // file's check accepts it whatever its rounding.
      const auto b = model::parameterBounds(k, channels);
      const double lo = b.lower + 1e-6 * std::max(1.0, std::abs(b.lower));
      const double hi = b.upper >= model::kUnbounded ? b.upper : b.upper - 1e-6 * std::max(1.0, std::abs(b.upper));
      p.coefficients = {std::clamp(medianOf(v), lo, hi)};
    }
    g.parameters.push_back(p);
    if (k >= layout.ib(0) && k < layout.fi()) out.intensity_degree = std::max(out.intensity_degree, d);
    for (size_t i = 0; i < inlier.size(); ++i) image_inliers[i] = image_inliers[i] && inlier[i];
  }
  return out;
}

}  // namespace

std::optional<model::PedestalTrack> buildPedestalTrack(
    const std::vector<double>& angles_deg, const std::vector<model::Pedestal>& pedestals,
    const std::vector<double>& noise_sigma, int channels, int degree, double range_margin_deg,
    double capture_min_deg, double capture_max_deg) {
  if (angles_deg.empty()) return std::nullopt;
  model::PedestalTrack track;
  track.angle_min_deg = std::max(
      capture_min_deg, *std::min_element(angles_deg.begin(), angles_deg.end()) - range_margin_deg);
  track.angle_max_deg = std::min(
      capture_max_deg, *std::max_element(angles_deg.begin(), angles_deg.end()) + range_margin_deg);
  const int d = std::min(degree, static_cast<int>(angles_deg.size()) - 1);
  for (int k = 0; k < model::kPedestalTerms * channels; ++k) {
    std::vector<double> values;
    for (const model::Pedestal& p : pedestals) values.push_back(p.coefficients[k]);
    const std::vector<bool> in = polynomialInliers(angles_deg, values, d);
    std::vector<double> a, v, w;
    for (size_t i = 0; i < angles_deg.size(); ++i)
      if (in[i]) {
        a.push_back(angles_deg[i]);
        v.push_back(values[i]);
        w.push_back(noise_sigma[i] > 0 ? 1 / (noise_sigma[i] * noise_sigma[i]) : 1.0);
      }
    track.terms.push_back(expanded(solveCentred(a, v, w, d)));
  }
  return track;
}

model::FlareModel buildFlareModel(const std::vector<GhostTrackFit>& tracks,
                                  const model::CaptureInfo& info, int channels, int degree,
                                  double range_margin_deg, double capture_min_deg,
                                  double capture_max_deg, bool refine_in_image, int joint_sweeps) {
  model::FlareModel m;
  m.capture = info;
  m.channels = channels;
  // For the refinement: every fit rendered on its level (its targets), and each fitted frame's
  // flare peak, its brightest fit there, by which it weighs the frame's error as PSNR does.
  const ImageLevel refine_level(info.image_size, kRefinePixels);
  std::vector<std::vector<cv::Mat>> fit_images(tracks.size());
  std::map<double, double> frame_peaks;
  if (refine_in_image) {
    tbb::parallel_for(size_t{0}, tracks.size(), [&](size_t i) {
      for (const auto& fit : tracks[i].fits)
        fit_images[i].push_back(
            model::renderGhosts(std::span(&fit, 1), refine_level.size, channels, {}, refine_level.view));
    });
    for (size_t i = 0; i < tracks.size(); ++i)
      for (size_t j = 0; j < fit_images[i].size(); ++j) {
        double peak = 0;
        cv::minMaxLoc(fit_images[i][j].reshape(1), nullptr, &peak);
        double& frame_peak = frame_peaks[tracks[i].angles_deg[j]];
        frame_peak = std::max(frame_peak, peak);
      }
  }
  // Each track on its own (in parallel: the refinement renders every frame of a track many times).
  m.ghosts.resize(tracks.size());
  tbb::parallel_for(size_t{0}, tracks.size(), [&](size_t track_index) {
    const GhostTrackFit& t = tracks[track_index];
    PolynomialGhost p = polynomialsThroughFits(t, info.image_size, channels, degree, range_margin_deg,
                                               capture_min_deg, capture_max_deg);
    model::GhostTrack& g = m.ghosts[track_index];
    g = std::move(p.ghost);
    fitIntensitiesInImage(t, p.image_inliers, info.image_size, channels, p.intensity_degree, g);
    if (refine_in_image) refineTrackInImage(t, refine_level, channels, fit_images[track_index], frame_peaks, g);
  });
  if (refine_in_image && joint_sweeps > 0)
    refineTracksTogether(tracks, fit_images, frame_peaks, refine_level, channels, joint_sweeps,
                         m.ghosts);
  return m;
}

namespace {

// Where a track turns from glare into a sharp ghost or back (isGlare) and stays so: the first fit
// i whose min_frames fits before it are all of one kind and min_frames from it on all of the
// other; 0 when there is none. Such a track is two things (a tracked veil joined to the glare
// that took over its frames, or a glare fitted as a sharp veil for a while), and no polynomial
// through both describes either, while their outlines, both wider than the frame, overlap as one
// ghost's. Heliar 640×427, λ × 1: ghost 40 was a sharp veil at 9.2–11.6° (Fo at its 77 px bound)
// and glare at 11.8–14.8° (Fo 479–758 px); its model scored 12–22 dB there, against 29.1–31.0 for
// the frames' fits, and 29.4–30.1 dB split.
int glareChange(const GhostTrackFit& t, cv::Size image_size, int min_frames) {
  const int n = static_cast<int>(t.fits.size());
  std::vector<bool> glare(n);
  for (int i = 0; i < n; ++i) glare[i] = isGlare(t.fits[i], image_size);
  for (int i = min_frames; i <= n - min_frames; ++i) {
    bool persists = glare[i - 1] != glare[i];
    for (int j = i - min_frames; j < i + min_frames && persists; ++j)
      persists = glare[j] == (j < i ? glare[i - 1] : glare[i]);
    if (persists) return i;
  }
  return 0;
}

// Where to cut a track whose polynomials cannot follow it: where consecutive fits differ most
// (where it jumped from one ghost to another); 0 when they follow it.
int polynomialsLoseTrack(const GhostTrackFit& t, const model::CaptureInfo& info, int channels,
                         int degree, int min_frames) {
  constexpr double kSameGhostIoU = 0.5;
  const int n = static_cast<int>(t.fits.size());
  // The outline only, which buildFlareModel's intensities in image space do not move. Solved
  // for every track, one after another, they took 2.1 s of the Tessar 640×427 fit's modelling step
  // (λ × 1: 14.8 → 12.7 s, the model the same bit for bit).
  const model::GhostTrack g =
      polynomialsThroughFits(t, info.image_size, channels, degree, 0, -90, 90).ghost;
  bool follows = true;
  for (int i = 0; i < n && follows; ++i)
    follows = outlineIoU(g.at(t.angles_deg[i], channels), t.fits[i]) >= kSameGhostIoU;
  if (follows) return 0;
  int split = min_frames;
  double worst = 2;
  for (int i = min_frames; i <= n - min_frames; ++i) {
    const double v = outlineIoU(t.fits[i - 1], t.fits[i]);
    if (v < worst) {
      worst = v;
      split = i;
    }
  }
  return split;
}

}  // namespace

std::vector<GhostTrackFit> splitTracksPolynomialsCannotFollow(std::vector<GhostTrackFit> tracks,
                                                              const model::CaptureInfo& info,
                                                              int channels, int degree,
                                                              int min_frames, int first_new_id) {
  std::vector<GhostTrackFit> done;
  int next_id = first_new_id;
  while (!tracks.empty()) {
    GhostTrackFit t = std::move(tracks.back());
    tracks.pop_back();
    const int n = static_cast<int>(t.fits.size());
    if (n < 2 * min_frames) {
      done.push_back(std::move(t));
      continue;
    }
    int split = glareChange(t, info.image_size, min_frames);
    const bool kind_changes = split > 0;
    if (!kind_changes) split = polynomialsLoseTrack(t, info, channels, degree, min_frames);
    if (split == 0) {
      done.push_back(std::move(t));
      continue;
    }
    auto piece = [&](int from, int to) {
      GhostTrackFit p;
      p.key_frame = t.key_frame;
      p.end_low = t.end_low;
      p.end_high = t.end_high;
      for (int i = from; i < to; ++i) {
        p.angles_deg.push_back(t.angles_deg[i]);
        p.fits.push_back(t.fits[i]);
        if (i < static_cast<int>(t.residual_rms.size())) p.residual_rms.push_back(t.residual_rms[i]);
        if (i < static_cast<int>(t.peak.size())) p.peak.push_back(t.peak[i]);
        if (i < static_cast<int>(t.unexplained.size())) p.unexplained.push_back(t.unexplained[i]);
        if (i < static_cast<int>(t.carried.size())) p.carried.push_back(t.carried[i]);
      }
      return p;
    };
    GhostTrackFit low = piece(0, split), high = piece(split, n);
    static const std::string kSplit = "split: its polynomials could not follow the track";
    static const std::string kSplitKind = "split: glare on one side, a sharp outline on the other";
    low.id = t.id;
    low.end_high = kind_changes ? kSplitKind : kSplit;
    high.id = next_id++;
    high.end_low = low.end_high;
    high.key_frame = -1;  // the caller knows the frame positions
    tracks.push_back(std::move(high));
    tracks.push_back(std::move(low));
  }
  std::sort(done.begin(), done.end(), [](const GhostTrackFit& a, const GhostTrackFit& b) { return a.id < b.id; });
  return done;
}

namespace {

double peakOf(const GhostParameters& g) {
  double p = 0;
  for (int c = 0; c < g.channels; ++c) p = std::max({p, g.border[c], g.inside[c]});
  return p;
}

}  // namespace

std::string trackEndReason(const GhostParameters& g, cv::Size image_size, double noise_sigma,
                           const TrackingOptions& options) {
  const bool sank = peakOf(g) < options.min_peak_sigma * noise_sigma;
  if (isGlare(g, image_size)) {
    // Glare's outline is no ghost's: it is the glow's core, and frames at 10–30° on the Heliar
    // 640×427 capture were best drawn by an outline wider than the frame (R 755 px at 10°), one
    // side at its 0.5 px bound, or a centre outside the image with the glow reaching in. Ended by
    // the sharp ghost's rules there, the glare lived 4–19 frames at a time and 53 of the 106
    // frames from 9° on had none (58 counting in the pixel noise; with these rules 18 and 20),
    // though the glow of the veils too faint to see holds most of their flare (one glare fitted to
    // that glow alone, the visible ghosts exact: 31–46 dB at 12–28°; without a glare 4–17 dB).
    // The pixels it reaches: its outline's box grown by its outside fall-off. (The fitter's own
    // glare now holds the frame, fit/cost.h fitBounds, and so ends only in the noise.)
    if ((model::ghostPixelBounds(g) & cv::Rect(cv::Point(), image_size)).empty())
      return "left the image";
    return sank ? "sank into the noise" : "";
  }
  const cv::Rect2d box = model::outlineBounds(g);
  const cv::Rect2d image(0, 0, image_size.width, image_size.height);
  const double inside = (box & image).area();
  if (box.area() <= 0 || inside < options.min_visible_fraction * box.area())
    return "left the image";
  if (sank) return "sank into the noise";
  // A size at its bound ends the track even where that side lies beyond the frame, unseen (7 of
  // the 9 tracks from 16° on end so, Heliar 640×427, λ × 1: large veils whose fits put their
  // centres up to 370 px left of the frame). Ending it only where the side's edge is in the
  // frame, λ × 1 (recall % / precision % / median PSNR dB / median centroid error px): Heliar
  // 83.3 / 88.3 / 25.2 / 6.3 against 76.1 / 86.0 / 25.8 / 7.9, Tessar 75.8 / 58.5 / 25.1 / 13.3
  // against 83.4 / 64.7 / 25.3 / 9.3; with the shape prior tightened on unseen parts too
  // (fit/cost.h), over λ × 0.98–1.02: Heliar 79.0 / 86.6 / 24.9 / 7.4 against
  // 77.2 / 87.0 / 25.4 / 8.0, Tessar 78.1 / 69.7 / 25.0 / 11.7 against 82.9 / 72.5 / 25.2 / 10.9.
  const double diag = std::hypot(image_size.width, image_size.height);
  if (std::max({g.left, g.right, g.height}) > 0.98 * diag ||
      std::min({g.left, g.right, g.height}) < 0.6)
    return "fit broke down (size at its bound)";
  return "";
}

// ── The capture fitter ────────────────────────────────────────────────────────────────────────

namespace {

// Detection runs on a level of about 160 000 pixels (the blobs it seeds are refined at once).
int detectionLevel(cv::Size size) {
  return std::max(1, static_cast<int>(std::floor(std::sqrt(size.area() / 160000.0))));
}

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Track {
  int id = 0;
  int key_frame = 0;                       // position in the fitted frame list
  std::map<int, GhostParameters> fits;     // by position in the fitted frame list
  bool ended_high = false, ended_low = false;
  std::string end_high = "last frame", end_low = "first frame";
  int merged_with = -1;  // the track this one ran onto in the backward sweep (the same ghost)
  std::set<int> carried;  // positions where the ghost was carried into the light (carriedInto)
};

struct SolveStats {
  double cost = 0;
  long long evaluations = 0;
  int iterations = 0;
};

// The same parameters bit for bit (not ==, which takes −0 for +0).
bool sameBits(const GhostParameters& a, const GhostParameters& b) {
  const std::vector<double> va = model::toParameterVector(a), vb = model::toParameterVector(b);
  return a.channels == b.channels && va.size() == vb.size() &&
         std::memcmp(va.data(), vb.data(), va.size() * sizeof(double)) == 0;
}

class CaptureFitter {
 public:
  CaptureFitter(const FrameStack& stack, const FitOptions& options)
      : stack_(stack), options_(options), edge_(options.cost) {
    for (int i = 0; i < static_cast<int>(stack.frames.size()); ++i)
      if (!options.holdout_odd || i % 2 == 0) positions_.push_back(i);
    solver_ = options.solver;
  }

  FitResult run() {
    const auto t0 = Clock::now();
    std::ostringstream silent;
    Progress progress = options_.progress
                            ? Progress("fit", 2 * static_cast<long long>(positions_.size()))
                            : Progress("fit", 2 * static_cast<long long>(positions_.size()), silent, false);
    // Forward sweep: track and detect.
    for (int pos = 0; pos < static_cast<int>(positions_.size()); ++pos) {
      fitFrame(pos, /*forward=*/true);
      progress.advance();
    }
    // Backward sweep: extend every track below its key frame, refit with all ghosts known.
    for (int pos = static_cast<int>(positions_.size()) - 1; pos >= 0; --pos) {
      fitFrame(pos, /*forward=*/false);
      progress.advance();
    }
    progress.finish();
    if (logLevel() >= LogLevel::kDebug)
      logDebug("fit: " + std::to_string(group_resolves_) + " ghost group(s) solved again (others moved onto them)");
    const auto t_model = Clock::now();
    FitResult result = finish();
    FitSummary& s = result.summary;
    s.seconds_fitting = seconds_fitting_;
    s.seconds_detecting = seconds_detecting_;
    s.seconds_modelling = since(t_model);
    s.seconds_total = since(t0);
    return result;
  }

 private:
  const Frame& frame(int pos) const { return stack_.frames[positions_[pos]]; }
  double angle(int pos) const { return frame(pos).angle_deg; }

  // The seed of a track at `pos` from its fits (nearest first).
  GhostParameters seedFor(const Track& t, int pos) const {
    std::vector<double> a;
    std::vector<GhostParameters> f;
    for (const auto& [p, g] : t.fits) {
      a.push_back(angle(p));
      f.push_back(g);
    }
    return extrapolate(a, f, angle(pos), options_.tracking.extrapolation_frames,
                       options_.tracking.extrapolation_degree);
  }

  // The ghost of track `t` carried into frame `pos`, where it lies in the light's own image: there
  // S (detection.h estimateLightImage) takes every part of a ghost that is point-symmetric about
  // the light, and near θ = 0 that is nearly all of it (a ghost's offset from the light shrinks
  // with θ), so its fit sinks into the noise although the ghost is as bright as a frame before.
  // Ended there, the model has no ghost where the flare is brightest. The carried ghost takes the
  // shape and brightness of the track's nearest fit clear of the light and moves its centre
  // towards the image centre, where every ghost is at θ = 0 (the lens is rotationally symmetric):
  // c(θ) = c₀ + k·θ, k by least squares over those clear fits (offsets from the optical axis grow
  // ∝ tan θ ≈ θ near it). The fits beside the light are no template: S took the ghost's side
  // towards the light from them (a 14 px disc fitted with L = 2 px) and pulled their centres away.
  // A ghost that moves with the light is never clear of it and is not carried (data_synthetic
  // Heliar's brightest, of radius 27 px, 3–33 px from the light over 0.5–5°: its tracks end near
  // the light still). A ghost larger than the light's zone is not carried either: S is kept only
  // where it exceeds the level that bounds the zone (light_zone_sigma), so such a ghost keeps its
  // parts beyond in the data and its fits beside the light stand, while a carried copy is frozen
  // at its nearest clear fit, for a veil often degrees away where the light has left the frame
  // (Heliar 640×427, λ × 1.01: a veil of R 213 px fitted at 12–14.8° was carried over 0–11.8°;
  // Tessar, --holdout odd, λ × 1.02: a glare fit of h 0.9 px and inside brightness 1.1, where
  // the other ghosts' are below 1e-3, carried over 0–7.6°, PSNR −34 dB there). nullopt when the
  // ghost is not in the light's zone, is larger than it, or has too few clear fits.
  std::optional<GhostParameters> carriedInto(const Track& t, int pos) {
    const LightImage& light = lightOf(pos);
    if (!light.found) return std::nullopt;
    // Within its size of the light's zone (the light found in that frame).
    auto inLight = [](const GhostParameters& g, const LightImage& l) {
      return l.found && std::hypot(g.center_x - l.center.x, g.center_y - l.center.y) <=
                            std::max({g.left, g.right, g.height}) + l.zone_radius_px;
    };
    const cv::Point2d c0(0.5 * stack_.size.width, 0.5 * stack_.size.height);
    cv::Point2d kt(0, 0);
    double tt = 0;
    int n = 0;
    const GhostParameters* nearest = nullptr;
    for (const auto& [p, g] : t.fits) {
      if (t.carried.count(p) || inLight(g, lightOf(p))) continue;
      if (!nearest) nearest = &g;
      kt += angle(p) * (cv::Point2d(g.center_x, g.center_y) - c0);
      tt += angle(p) * angle(p);
      if (++n == options_.tracking.extrapolation_frames) break;
    }
    if (n < options_.tracking.min_track_frames || !(tt > 0)) return std::nullopt;
    GhostParameters g = *nearest;
    if (std::max({g.left, g.right, g.height}) > light.zone_radius_px) return std::nullopt;
    const cv::Point2d centre = c0 + (angle(pos) / tt) * kt;
    g.center_x = centre.x;
    g.center_y = centre.y;
    if (!inLight(g, light)) return std::nullopt;
    return g;
  }

  std::string endReason(const GhostParameters& g, double noise_sigma) const {
    return trackEndReason(g, stack_.size, noise_sigma, options_.tracking);
  }

  // Fits `ghosts` jointly per overlapping group; updates them in place.
  SolveStats solveFrame(const FramePyramid& data, std::vector<GhostParameters>& ghosts) {
    SolveStats stats;
    const int n = static_cast<int>(ghosts.size());
    if (n == 0) return stats;
    // Groups: ghosts whose regions (grown by the margin and the filter radius) overlap.
    std::vector<int> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    std::function<int(int)> find = [&](int i) { return parent[i] == i ? i : parent[i] = find(parent[i]); };
    const int grow = static_cast<int>(options_.cost.region_margin_px) + edge_.radius();
    std::vector<cv::Rect> boxes;
    for (const auto& g : ghosts) {
      cv::Rect b = model::ghostPixelBounds(g);
      boxes.emplace_back(b.x - grow, b.y - grow, b.width + 2 * grow, b.height + 2 * grow);
    }
    const cv::Rect image(0, 0, stack_.size.width, stack_.size.height);
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j)
        if (!(boxes[i] & boxes[j] & image).empty()) parent[find(i)] = find(j);
    std::map<int, std::vector<int>> by_root;
    for (int i = 0; i < n; ++i) by_root[find(i)].push_back(i);
    std::vector<std::vector<int>> groups;
    for (auto& [root, members] : by_root) groups.push_back(std::move(members));
    // Each group is fitted against the others as they stand when its turn comes: the groups before
    // it already fitted. The groups are solved concurrently all the same, each against the others'
    // seeds, and applied in order; a group whose others moved where its cost sees them (reaches)
    // is solved again, so every group's result is the one the one-by-one order gives, bit for bit.
    // Ceres runs on one thread per problem (group_solver.h): groups are the only way to keep both
    // cores busy through its linear algebra. (Rarely there on the Heliar 640 capture: its frames
    // held one group in 289 of 302 frame fits, a frame-wide veil overlapping every ghost.)
    struct Solved {
      std::unique_ptr<GroupCost> cost;
      GroupFitResult result;
    };
    const std::vector<GhostParameters> seeds_all = ghosts;
    auto solve = [&](const std::vector<int>& members, const std::vector<GhostParameters>& current) {
      std::vector<GhostParameters> seeds, others;
      for (int i : members) seeds.push_back(current[i]);
      for (int i = 0; i < n; ++i)
        if (std::find(members.begin(), members.end(), i) == members.end()) others.push_back(current[i]);
      Solved s;
      s.cost = std::make_unique<GroupCost>(data, edge_, others, seeds, options_.cost);
      s.result = solveGroup(*s.cost, seeds, solver_);
      return s;
    };
    std::vector<Solved> solved(groups.size());
    if (groups.size() > 1)
      tbb::parallel_for(size_t{0}, groups.size(), [&](size_t j) { solved[j] = solve(groups[j], seeds_all); });
    else
      solved[0] = solve(groups[0], seeds_all);
    for (size_t j = 0; j < groups.size(); ++j) {
      bool same_others = true;
      for (size_t i = 0; i < j && same_others; ++i)
        for (int m : groups[i])
          if (!sameBits(ghosts[m], seeds_all[m]) &&
              (!model::isValid(ghosts[m]) || solved[j].cost->reaches(ghosts[m]) ||
               solved[j].cost->reaches(seeds_all[m]))) {
            same_others = false;
            break;
          }
      if (!same_others) {
        ++group_resolves_;
        solved[j] = solve(groups[j], ghosts);
      }
      const GroupFitResult& r = solved[j].result;
      for (size_t k = 0; k < groups[j].size(); ++k) ghosts[groups[j][k]] = r.ghosts[k];
      stats.cost += r.final_cost;
      stats.evaluations += r.evaluations;
      stats.iterations += r.iterations;
    }
    return stats;
  }

  GhostParameters toChannels(const GhostParameters& grey, const cv::Mat& image, cv::Rect blob) const {
    GhostParameters g = grey;
    g.channels = stack_.channels;
    if (stack_.channels == 1) return g;
    const cv::Scalar mean = cv::mean(image(blob & cv::Rect(0, 0, image.cols, image.rows)));
    const double lum = 0.2126 * mean[0] + 0.7152 * mean[1] + 0.0722 * mean[2];
    for (int c = 0; c < 3; ++c) {
      const double ratio = lum > 0 ? std::max(0.0, mean[c] / lum) : 1.0;
      g.border[c] = grey.border[0] * ratio;
      g.inside[c] = grey.inside[0] * ratio;
    }
    return g;
  }

  // The light's image in a frame: found in every frame at the first call, followed where its core
  // is cut by the frame's border (followLight), and kept for both sweeps.
  const LightImage& lightOf(int pos) {
    if (lights_.empty()) {
      std::vector<LightImage> found;
      std::vector<double> angles;
      for (int p = 0; p < static_cast<int>(positions_.size()); ++p) {
        found.push_back(findLight(luminance(frame(p).image), frame(p).valid, noiseOf(p), options_.detection));
        angles.push_back(angle(p));
      }
      lights_ = followLight(std::move(found), angles, stack_.size);
    }
    return lights_[pos];
  }

  // The pixels of a frame the ghosts are fitted to and detected in: its valid ones, but for where
  // the light cannot be told from them (validBesideLight).
  cv::Mat validOf(int pos) { return validBesideLight(frame(pos).valid, lightOf(pos)); }

  // Distance of a point (capture pixels) from the flare axis of a frame.
  double axisOffset(int pos, cv::Point2d p) { return flareAxisOffset(p, lightOf(pos), stack_.size); }

  // The noise σ of a frame (of the frame itself: see FramePyramid).
  double noiseOf(int pos) {
    auto it = noise_.find(pos);
    if (it != noise_.end()) return it->second;
    const Frame& f = frame(pos);
    return noise_[pos] = options_.pixel_noise ? estimatePixelNoiseSigma(f.image, f.valid)
                                              : estimateNoiseSigma(f.image, f.valid);
  }

  // The frame minus the light's own image S (detection.h estimateLightImage, from the frame
  // itself): the data the ghosts are fitted to and detected in. Without a light in the frame (or
  // with light_symmetry off) the frame itself. S is not re-estimated from the frame minus the
  // ghosts fitted so far: a seed a few pixels off then leaves a crescent of the starburst in
  // frame − S, and the ghost's fit chases it (measured on Heliar, every-5th frame: recall
  // 21.7 → 23.3 %, Tessar 29.8 → 40.4 %, median PSNR 14.4 → 20.4 and 12.4 → 19.5 dB).
  cv::Mat withoutLight(int pos) {
    return frameWithoutLight(frame(pos), lightOf(pos), noiseOf(pos), options_.detection);
  }

  void fitFrame(int pos, bool forward) {
    const Frame& f = frame(pos);
    auto t_fit = Clock::now();
    FrameFit& record = frame_fits_[pos];
    record.angle_deg = f.angle_deg;
    record.frame = positions_[pos];

    // The ghosts in this frame and their seeds.
    std::vector<int> ids;
    std::vector<GhostParameters> ghosts;
    for (auto& t : tracks_) {
      if (forward) {
        if (t.ended_high || t.fits.empty()) continue;
        if (t.fits.rbegin()->first >= pos) continue;
        ghosts.push_back(seedFor(t, pos));
      } else {
        auto it = t.fits.find(pos);
        if (it != t.fits.end()) {
          ghosts.push_back(it->second);
        } else {
          if (t.ended_low || t.fits.empty() || t.fits.begin()->first < pos) continue;
          ghosts.push_back(seedFor(t, pos));
        }
      }
      ids.push_back(t.id);
    }
    // Backward, a frame no track is extended onto is refitted all the same: its forward fit came,
    // near a key frame, from a rough detection seed (skipping these refits cost the 12-frame CLI
    // hold-out test 62 → 16 dB).
    const FramePyramid data(withoutLight(pos), validOf(pos), edge_, noiseOf(pos));
    const double noise_sigma = data.full().noise_sigma;
    record.noise_sigma = noise_sigma;
    SolveStats stats = solveFrame(data, ghosts);
    // The ghosts that end here (forward) were fitted with the others, and the others' fits stand.
    // Solving the frame again without them, or first again from the last fit of a ghost whose fit
    // broke down (a size at its bound), did not pay. On the 640×427 captures (recall % / precision
    // % / median PSNR dB / median centroid error px, bench/fit_accuracy.sh): refitted without them,
    // over λ × 0.98–1.02, Heliar 78.0 / 87.7 / 24.7 / 7.0 against 77.2 / 87.0 / 25.4 / 8.0, Tessar
    // 80.4 / 74.8 / 25.7 / 11.7 against 82.9 / 72.5 / 25.2 / 10.9; retried from the last fit,
    // Heliar 77.7 / 80.2 / 25.9 / 8.0 at 44–51 s a fit instead of 33–37 s, and the Tessar
    // 70.0–76.2 % recall over λ × 0.98–1 at up to 70 s.

    // Ends and records.
    std::vector<int> kept_ids;
    std::vector<GhostParameters> kept;
    // Keeps `g` as track t's ghost in this frame; `carried`: not fitted here (carriedInto).
    auto keep = [&](Track& t, const GhostParameters& g, bool carried) {
      t.fits[pos] = g;
      if (carried) t.carried.insert(pos);
      kept_ids.push_back(t.id);
      kept.push_back(g);
    };
    for (size_t i = 0; i < ghosts.size(); ++i) {
      Track& t = track(ids[i]);
      std::string reason = endReason(ghosts[i], noise_sigma);
      if (reason.empty() && axisOffset(pos, {ghosts[i].center_x, ghosts[i].center_y}) >
                                2 * options_.detection.max_axis_offset * stack_.size.height)
        reason = "fit left the flare axis";
      const bool had = t.fits.count(pos) > 0;
      if (!reason.empty()) {
        if (forward) {
          t.ended_high = true;
          t.end_high = reason;
        } else if (!had || t.fits.begin()->first == pos) {
          std::optional<GhostParameters> carried;
          if (!had && reason == "sank into the noise") carried = carriedInto(t, pos);
          if (carried) {
            keep(t, *carried, true);
            continue;
          }
          t.ended_low = true;
          t.end_low = reason;
          t.fits.erase(pos);
        } else {
          t.fits.erase(pos);  // a frame in the middle the ghost cannot be fitted in
        }
        continue;
      }
      // Backward: where the light's image lies inside the ghost's outline, S took the part of the
      // ghost that overlaps its own reflection about the light, and the fit is what S left (a
      // 14 px disc fitted with L = 3 px, test FitCapture.CarriesAGhostIntoTheLightNearTheAxis),
      // which would bend the track's polynomials at their end: the carried ghost takes its place.
      // (With the light outside the outline the reflection misses the ghost, and the fit stands.)
      if (!forward) {
        const std::optional<GhostParameters> carried = carriedInto(t, pos);
        if (carried && model::outlineBounds(*carried).contains(lightOf(pos).center)) {
          keep(t, *carried, true);
          continue;
        }
      }
      // Backward: a ghost extended onto another one (the same ghost found twice) stops.
      if (!forward && !had) {
        for (size_t j = 0; j < ghosts.size() && t.merged_with < 0; ++j)
          if (j != i && sameGhost(ghosts[i], ghosts[j])) t.merged_with = ids[j];
        if (t.merged_with >= 0) {
          t.ended_low = true;
          t.end_low = "merged with another track";
          continue;
        }
      }
      keep(t, ghosts[i], false);
    }
    seconds_fitting_ += since(t_fit);

    // Detection of new ghosts (forward sweep only).
    if (forward && pos % options_.tracking.detect_every == 0) {
      auto t_det = Clock::now();
      detectNew(pos, data, kept_ids, kept, stats);
      seconds_detecting_ += since(t_det);
    }
    record.ghost_ids = kept_ids;
    record.ghosts = kept;
    if (logLevel() >= LogLevel::kDebug) {
      std::ostringstream m;
      m << "fit: " << (forward ? "forward" : "backward") << " θ = " << f.angle_deg << "°: "
        << kept.size() << " ghost(s), " << stats.iterations << " iterations, " << stats.evaluations
        << " evaluations, " << since(t_fit) << " s;";
      for (size_t i = 0; i < kept.size(); ++i)
        m << " #" << kept_ids[i] << " (" << kept[i].center_x << ", " << kept[i].center_y << ") L "
          << kept[i].left << " R " << kept[i].right << " h " << kept[i].height << " Ib "
          << kept[i].border[0] << " Ii " << kept[i].inside[0] << ";";
      logDebug(m.str());
    }
    record.cost = stats.cost;
    record.evaluations += stats.evaluations;
    record.iterations += stats.iterations;
    evaluations_ += stats.evaluations;
    iterations_ += stats.iterations;
  }

  // Two fits of one ghost: outlines whose bounding boxes overlap by IoU ≥ 0.6 (for concentric
  // discs, radii within 23 %). Centre distance alone missed a ghost found twice beside the light,
  // once seeded round and once asymmetric (Heliar 4°: centres 16 px apart, outlines 4–6 px).
  bool sameGhost(const GhostParameters& a, const GhostParameters& b) const {
    return outlineIoU(a, b) >= kOneGhostIoU;
  }
  static constexpr double kOneGhostIoU = 0.6;

  int detectionFactor() const { return detectionLevel(stack_.size); }

  // With the pixel noise, the level detection must also clear where the light is
  // (DetectionOptions::light_residue_fraction): that fraction of the light's estimated image at
  // `level` (the frame there minus the frame without the light), smoothed as detection smooths
  // the residual. Empty otherwise.
  cv::Mat lightResidueFloor(int pos, const FrameData& level) const {
    const double fraction = options_.detection.light_residue_fraction;
    if (!options_.pixel_noise || !(fraction > 0)) return {};
    const int k = level.factor;
    cv::Mat frame_level;
    cv::resize(frame(pos).image(cv::Rect(0, 0, level.image.cols * k, level.image.rows * k)),
               frame_level, level.image.size(), 0, 0, cv::INTER_AREA);
    cv::Mat with_light = luminance(frame_level), without_light = luminance(level.image);
    cv::patchNaNs(with_light, 0);
    cv::patchNaNs(without_light, 0);
    cv::Mat light = with_light - without_light;
    cv::GaussianBlur(light, light, cv::Size(0, 0), options_.detection.smoothing_px);
    return cv::max(light, 0) * fraction;
  }

  // `ghosts` rendered at level `level.factor` (zeros for none).
  cv::Mat renderedAt(const FrameData& level, const std::vector<GhostParameters>& ghosts) const {
    if (ghosts.empty()) return cv::Mat::zeros(level.image.size(), level.image.type());
    model::ViewTransform view;
    view.scale = 1.0 / level.factor;
    return model::renderGhosts(ghosts, level.image.size(), stack_.channels, {}, view);
  }

  // The residual (luminance) of the frame minus `ghosts` at level `level.factor`.
  cv::Mat residualAt(const FrameData& level, const std::vector<GhostParameters>& ghosts) const {
    return luminance(level.image - renderedAt(level, ghosts));
  }

  void detectNew(int pos, const FramePyramid& data, std::vector<int>& ids,
                 std::vector<GhostParameters>& ghosts, SolveStats& stats) {
    const double noise_sigma = data.full().noise_sigma;
    const int kd = detectionFactor();
    const FrameData& level = data.level(kd);
    cv::Mat residual = residualAt(level, ghosts);
    const LightImage& light_full = lightOf(pos);
    FrameFit& record = frame_fits_[pos];
    record.light_found = light_full.found;
    record.light_center = light_full.center;
    record.light_zone_px = light_full.zone_radius_px;
    const LightImage light = light_full.atLevel(kd);
    auto candidates = detectGhosts(residual, level.valid, level.noise_sigma, light,
                                   options_.detection, lightResidueFloor(pos, level));
    if (options_.detection.find_veils)
      for (auto& veil : detectVeilEdges(residual, level.valid, level.noise_sigma, light, options_.detection))
        candidates.push_back(std::move(veil));
    // Glare first: the sharp ghosts are then fitted on top of it, not softened to cover it.
    // Where a glare free to take any outline had taken a faint disc's body (Heliar 640×427,
    // 12–14°: ghost 19; it is held flat now, fit/cost.h isGlare, and cannot), a candidate fitted
    // jointly with the glare, so that the glare could give the disc back, found that disc at
    // λ = 1 (ghost 19 in 22 of 26 frames at 11–16°, against 1) but not at λ × 0.99 or 1.01, and
    // the means over the three (recall / precision / median PSNR / median centroid error) moved
    // both ways: Heliar 71.2 → 69.1 %, 86.5 → 88.1 %, 24.0 → 24.4 dB, 8.8 → 9.6 px; Tessar
    // 51.4 → 52.0 %, 78.0 → 75.3 %, 22.5 → 23.6 dB, 15.6 → 13.5 px. Candidates are fitted against
    // the glare as it stands.
    if (options_.detection.find_glare &&
        std::none_of(ghosts.begin(), ghosts.end(), [&](const GhostParameters& g) { return isGlare(g, stack_.size); }))
      if (auto glare = detectGlare(residual, level.valid, level.noise_sigma, light, options_.detection))
        candidates.insert(candidates.begin(), std::move(*glare));
    for (const auto& c : candidates) {
      GhostParameters grey = c.seed;
      grey.center_x *= kd;
      grey.center_y *= kd;
      grey.left *= kd;
      grey.right *= kd;
      grey.height *= kd;
      grey.inside_falloff *= kd;
      grey.outside_falloff *= kd;
      if (isGlare(grey, stack_.size)) shapeGlareSeed(stack_.size, &grey);
      const cv::Rect blob(c.blob.x * kd, c.blob.y * kd, c.blob.width * kd, c.blob.height * kd);
      GhostParameters seed = toChannels(grey, data.full().image, blob);
      // Measured and not taken: also rejecting a seed whose centre lies inside an existing
      // non-glare ghost of at most 0.2 frame heights (the small rings nested in a ghost) moved
      // the five-λ means (bench/fit_accuracy.sh --lambdas "0.98 0.99 1 1.01 1.02") from recall
      // 74.1 / precision 81.3 % to 71.9 / 83.8 % on the Heliar and from 77.2 / 59.5 % to
      // 73.0 / 68.0 % on the Tessar, PSNR within 0.1 dB, and lengthened the Tessar's fits
      // (54.5–65.1 s against 50.7–62.6 s): precision bought with recall, not a gain.
      bool duplicate = false;
      for (const auto& g : ghosts)
        if (sameGhost(seed, g)) duplicate = true;
      if (duplicate) {
        ++rejected_;
        continue;
      }
      std::vector<GhostParameters> one = {seed};
      GroupCost cost(data, edge_, ghosts, one, options_.cost);
      GhostParameters dark = seed;
      dark.border = {0, 0, 0};
      dark.inside = {0, 0, 0};
      std::vector<GhostParameters> none = {dark};
      const double cost_without = cost.evaluate(none, false);
      GroupFitResult r = solveGroup(cost, one, solver_);
      stats.evaluations += r.evaluations;
      stats.iterations += r.iterations;
      const GhostParameters& g = r.ghosts[0];
      // Does the ghost explain its blob? The median absolute residual over the blob's pixels
      // before and after (the region's cost, or a mean, would be ruled by the light's starburst
      // and neighbours that cross the blob).
      double before = 0, after = 0;
      {
        std::vector<double> b, a;
        model::ViewTransform view;
        view.scale = 1.0 / kd;
        std::vector<GhostParameters> fitted = {g};
        cv::Mat rendered = luminance(model::renderGhosts(fitted, c.blob, stack_.channels, {}, view));
        for (int y = 0; y < c.blob.height; ++y)
          for (int x = 0; x < c.blob.width; ++x) {
            if (!c.mask.at<uchar>(y, x)) continue;
            const double v = residual.at<float>(c.blob.y + y, c.blob.x + x);
            b.push_back(std::abs(v));
            a.push_back(std::abs(v - rendered.at<float>(y, x)));
          }
        before = medianOf(b);
        after = medianOf(a);
      }
      // Ghosts are mirror-symmetric about the axis through the light's image and the image centre
      // (Walch et al. 2018 §3.2): a fit whose centre left the axis drew a starburst line or a
      // piece of the halo, not a ghost.
      const bool on_axis = axisOffset(pos, {g.center_x, g.center_y}) <=
                           options_.detection.max_axis_offset * stack_.size.height;
      const bool explains = on_axis && after <= (1 - options_.tracking.min_cost_reduction) * before;
      bool dup_after = false;
      for (const auto& o : ghosts)
        if (sameGhost(g, o)) dup_after = true;
      if (logLevel() >= LogLevel::kDebug) {
        std::ostringstream m;
        m << "fit: candidate at θ = " << frame(pos).angle_deg << "° level " << c.level_sigma
          << "σ blob " << blob << ": seed (" << seed.center_x << ", " << seed.center_y << ") L "
          << seed.left << " R " << seed.right << " h " << seed.height << " Ib " << seed.border[0]
          << " → (" << g.center_x << ", " << g.center_y << ") L " << g.left << " R " << g.right
          << " h " << g.height << " Ib " << g.border[0] << " Ii " << g.inside[0] << "; cost "
          << cost_without << " → " << r.final_cost << ", blob residual " << before << " → " << after
          << (on_axis ? "" : " (off the axis)") << (explains ? "" : " (does not explain)")
          << (dup_after ? " (duplicate)" : "") << " " << endReason(g, noise_sigma);
        logDebug(m.str());
      }
      if (!explains || dup_after || !endReason(g, noise_sigma).empty()) {
        ++rejected_;
        continue;
      }
      Track t;
      t.id = next_id_++;
      t.key_frame = pos;
      t.fits[pos] = g;
      tracks_.push_back(t);
      ids.push_back(t.id);
      ghosts.push_back(g);
      ++detections_;
    }
  }

  Track& track(int id) {
    for (auto& t : tracks_)
      if (t.id == id) return t;
    throw std::logic_error("unknown track");
  }

  // A track that ran backward onto another one found the same ghost twice: the two become one
  // track, with the other's frames where this one has none. Kept apart, the other (often two
  // frames, detected just below) is dropped as short and the frame where they met is fitted by
  // neither: the Heliar veil at 10.5° was a gap in the model between two tracks. Where both have a
  // fit, two ghosts were modelled on one, and the longer track's fit is kept: the shorter one
  // fitted, for a frame or two, what the other's fit left (test
  // FitCapture.CarriesAGhostIntoTheLightNearTheAxis: a faint candidate, Ib 0.10 against 0.75,
  // on a ghost whose edge was a pixel off). The brighter fit is no guide: such a fit can have a
  // bright spot inside (Ii 3.7 against the ghost's 0.26).
  void joinMergedTracks() {
    for (bool joined = true; joined;) {
      joined = false;
      for (auto& t : tracks_) {
        if (t.merged_with < 0) continue;
        auto other = std::find_if(tracks_.begin(), tracks_.end(),
                                  [&](const Track& o) { return o.id == t.merged_with; });
        t.merged_with = -1;
        if (other == tracks_.end() || other->id == t.id) continue;
        const int lowest = t.fits.empty() ? std::numeric_limits<int>::max() : t.fits.begin()->first;
        const bool other_longer = other->fits.size() > t.fits.size();
        for (const auto& [pos, g] : other->fits) {
          auto [it, inserted] = t.fits.emplace(pos, g);
          if (!inserted && !other_longer) continue;
          it->second = g;
          t.carried.erase(pos);
          if (other->carried.count(pos)) t.carried.insert(pos);  // with its fit, whether it was carried
        }
        if (!other->fits.empty() && other->fits.begin()->first < lowest) {
          t.ended_low = other->ended_low;
          t.end_low = other->end_low;
        }
        t.merged_with = other->merged_with;
        for (auto& o : tracks_)
          if (o.merged_with == other->id) o.merged_with = t.id;
        tracks_.erase(other);
        joined = true;
        break;  // the erase moved the tracks: start over
      }
    }
  }

  // A track that ends where another starts, one frame later or with one frame between, the two
  // fits' outlines the same ghost (sameGhost, the earlier track's last fit carried to the later
  // one's first angle by its extrapolation, or as it is): the same ghost, whose fit broke down or
  // sank into the noise for a frame (a frame-filling veil, tracked, ended and found again). The two
  // become one track. Apart, each ended in a polynomial of its own and the frame between was in
  // neither (Heliar 640×427: one veil in two tracks, to 12.8° and from 13.2°; at 13.0° no ghost in
  // the model, PSNR 2.3 dB). The pairs that overlap most are joined first.
  void joinAbuttingTracks() {
    for (bool joined = true; joined;) {
      joined = false;
      double best_iou = 0;
      Track* best_low = nullptr;
      Track* best_high = nullptr;
      for (auto& a : tracks_) {
        if (a.fits.empty() || !a.ended_high) continue;
        const auto& [a_pos, a_fit] = *a.fits.rbegin();
        for (auto& b : tracks_) {
          if (&a == &b || b.fits.empty() || !b.ended_low) continue;
          const auto& [b_pos, b_fit] = *b.fits.begin();
          if (b_pos - a_pos < 1 || b_pos - a_pos > 2) continue;
          const double iou = std::max(outlineIoU(a_fit, b_fit), outlineIoU(seedFor(a, b_pos), b_fit));
          if (iou >= kOneGhostIoU && iou > best_iou) {
            best_iou = iou;
            best_low = &a;
            best_high = &b;
          }
        }
      }
      if (!best_low) break;
      for (const auto& [pos, g] : best_high->fits) best_low->fits.emplace(pos, g);
      best_low->carried.insert(best_high->carried.begin(), best_high->carried.end());
      best_low->ended_high = best_high->ended_high;
      best_low->end_high = best_high->end_high;
      const int gone = best_high->id;
      tracks_.erase(std::find_if(tracks_.begin(), tracks_.end(), [&](const Track& t) { return t.id == gone; }));
      joined = true;
    }
  }

  FitResult finish() {
    joinMergedTracks();
    joinAbuttingTracks();
    FitResult result;
    FitSummary& s = result.summary;
    s.optimizer = optimizerName(options_.solver.optimizer);
    s.frames_total = static_cast<int>(stack_.frames.size());
    s.frames_fitted = static_cast<int>(positions_.size());
    s.degree = options_.auto_degree ? -1 : options_.degree;
    s.warnings = stack_.warnings;
    // Residual RMS per ghost and frame, against the final fits of every frame; and each frame's
    // pedestal, fitted to what they leave. Frames are independent: measured in parallel, each into
    // its own slot (the light's images and the noise are known by now, so the threads only read).
    const int frame_count = static_cast<int>(positions_.size());
    std::vector<std::vector<std::pair<int, GhostParameters>>> by_frame(frame_count);
    for (const auto& t : tracks_)
      for (const auto& [pos, g] : t.fits) by_frame[pos].push_back({t.id, g});
    for (int pos = 0; pos < frame_count; ++pos) {
      lightOf(pos);
      noiseOf(pos);
    }
    struct FrameLeft {
      std::vector<std::pair<int, double>> rms;  // per ghost id
      model::Pedestal pedestal;
      std::optional<FrameData> level;  // detection's level, for the model's pedestal
    };
    std::vector<FrameLeft> left_of(frame_count);
    tbb::parallel_for(0, frame_count, [&](int pos) {
      const auto& list = by_frame[pos];
      if (list.empty() && !options_.pedestal) return;
      std::vector<GhostParameters> all;
      for (const auto& [id, g] : list) all.push_back(g);
      // Against the frame without the light's image: the light is not a ghost the model failed.
      FramePyramid pyramid(withoutLight(pos), validOf(pos), edge_, noiseOf(pos));
      const int kd = detectionFactor();
      const FrameData& level = pyramid.level(kd);
      const cv::Mat left = level.image - renderedAt(level, all);
      const cv::Mat residual = luminance(left);
      FrameLeft& out = left_of[pos];
      for (const auto& [id, g] : list) {
        const cv::Rect2d b = model::outlineBounds(g);
        const cv::Rect box = cv::Rect(cv::Rect2d(b.x / kd, b.y / kd, b.width / kd, b.height / kd)) &
                             cv::Rect(0, 0, residual.cols, residual.rows);
        if (box.empty()) continue;
        cv::Mat sq;
        cv::multiply(residual(box), residual(box), sq);
        const cv::Scalar mean = cv::mean(sq, level.valid(box));
        out.rms.push_back({id, std::sqrt(mean[0])});
      }
      // The glow is smooth: detection's level samples it finely enough. A coarser one (k = 4 at
      // 640×427) lost, λ × 1: the frames' median PSNR Tessar 27.74 → 27.27 dB, Heliar
      // 29.83 → 29.38 dB.
      if (options_.pedestal) {
        out.pedestal = fitPedestal(left, level.valid, stack_.size, kd, level.noise_sigma,
                                   options_.pedestal_fit);
        out.level = level;
        out.level->edge.release();  // not needed again
        out.level->edge_valid.release();
      }
    });
    std::map<int, std::map<int, double>> rms;  // id → pos → rms
    for (int pos = 0; pos < frame_count; ++pos) {
      const auto& list = by_frame[pos];
      if (list.empty() && !options_.pedestal) continue;
      for (const auto& [id, r] : left_of[pos].rms) rms[id][pos] = r;
      FrameFit& record = frame_fits_[pos];
      record.ghost_ids.clear();
      record.ghosts.clear();
      for (const auto& [id, g] : list) {
        record.ghost_ids.push_back(id);
        record.ghosts.push_back(g);
      }
      record.pedestal = left_of[pos].pedestal;
    }
    for (const auto& t : tracks_) {
      if (static_cast<int>(t.fits.size()) < options_.tracking.min_track_frames) {
        ++s.ghosts_dropped_short;
        continue;
      }
      GhostTrackFit out;
      out.id = t.id;
      out.key_frame = t.key_frame;
      out.end_low = t.end_low;
      out.end_high = t.end_high;
      for (const auto& [pos, g] : t.fits) {
        out.angles_deg.push_back(angle(pos));
        out.fits.push_back(g);
        const double peak = peakOf(g);
        const double r = rms[t.id].count(pos) ? rms[t.id][pos] : 0;
        out.residual_rms.push_back(r);
        out.peak.push_back(peak);
        out.unexplained.push_back(r > options_.tracking.unexplained_fraction * peak);
        out.carried.push_back(t.carried.count(pos) > 0);
      }
      result.tracks.push_back(std::move(out));
    }
    if (result.tracks.empty())
      throw InputError(stack_.source.string(), "no ghost found in any frame: nothing to fit");
    const int degree = options_.auto_degree ? -1 : options_.degree;
    const int first_new_id = next_id_;
    result.tracks = splitTracksPolynomialsCannotFollow(std::move(result.tracks), stack_.info, stack_.channels,
                                                       degree, options_.tracking.min_track_frames,
                                                       first_new_id);
    for (auto& t : result.tracks) {
      if (t.id < first_new_id) continue;
      next_id_ = std::max(next_id_, t.id + 1);
      // A split's later piece: its first frame is its key frame, and the frames' records name it.
      for (size_t i = 0; i < t.angles_deg.size(); ++i)
        for (auto& [pos, record] : frame_fits_) {
          if (record.angle_deg != t.angles_deg[i]) continue;
          if (t.key_frame < 0) t.key_frame = pos;
          for (size_t j = 0; j < record.ghosts.size(); ++j)
            if (model::toParameterVector(record.ghosts[j]) == model::toParameterVector(t.fits[i]))
              record.ghost_ids[j] = t.id;
        }
    }
    for (const auto& t : result.tracks) {
      const int flagged = static_cast<int>(std::count(t.unexplained.begin(), t.unexplained.end(), true));
      if (flagged > 0) s.unexplained.push_back({t.id, double(flagged) / t.fits.size()});
    }
    // Half the spacing of the fitted frames (the median step: holdout doubles it).
    std::vector<double> steps;
    for (int pos = 1; pos < static_cast<int>(positions_.size()); ++pos) steps.push_back(angle(pos) - angle(pos - 1));
    const double margin = steps.empty() ? 0.0 : 0.5 * medianOf(steps);
    result.model = buildFlareModel(result.tracks, stack_.info, stack_.channels, degree, margin,
                                   angle(0), angle(static_cast<int>(positions_.size()) - 1),
                                   options_.refine_in_image, options_.joint_refine_sweeps);
    for (const auto& [pos, fit] : frame_fits_) result.frames.push_back(fit);
    if (options_.pedestal) {
      // The model's pedestal is what the model's ghosts leave, not the fits': the polynomials
      // draw the ghosts otherwise than their fits did, and the glow makes up for it too.
      // Measured and not taken: fitted on a coarser level (about 16 000 pixels, k = 4 at 640×427,
      // where the noise σ is 4× smaller and Tukey's 6σ sets more of a ghost's remains aside), the
      // λ × 1 models gained (median PSNR Tessar 25.96 → 26.55 dB, Heliar 25.71 → 25.76), but over
      // λ × 0.98–1.02 they did not: Heliar 25.6 25.3 25.7 26.4 26.4 → 25.5 25.0 25.8 25.9 26.1 dB,
      // Tessar 27.9 26.2 26.0 26.2 27.7 → 27.9 26.0 26.6 26.2 27.4 dB, recall, precision and
      // centroids the same; the step took about 2 s less.
      std::vector<int> at;  // the frames with a level kept, in order
      for (int pos = 0; pos < frame_count; ++pos)
        if (left_of[pos].level) at.push_back(pos);
      std::vector<double> angles, noise;
      std::vector<model::Pedestal> pedestals(at.size());
      tbb::parallel_for(size_t{0}, at.size(), [&](size_t i) {
        const FrameData& level = *left_of[at[i]].level;
        std::vector<GhostParameters> ghosts;
        for (const auto& g : result.model.ghostsAt(angle(at[i]))) ghosts.push_back(g.parameters);
        pedestals[i] = fitPedestal(level.image - renderedAt(level, ghosts), level.valid, stack_.size,
                                   level.factor, level.noise_sigma, options_.pedestal_fit);
      });
      for (int pos : at) {
        angles.push_back(angle(pos));
        noise.push_back(left_of[pos].level->noise_sigma);
      }
      result.model.pedestal =
          buildPedestalTrack(angles, pedestals, noise, stack_.channels, kPedestalDegree, margin,
                             angle(0), angle(static_cast<int>(positions_.size()) - 1));
    }
    s.ghosts = static_cast<int>(result.tracks.size());
    s.detections = detections_;
    s.detections_rejected = rejected_;
    s.evaluations = evaluations_;
    s.iterations = iterations_;
    return result;
  }

  const FrameStack& stack_;
  FitOptions options_;
  SolverOptions solver_;
  EdgeFilter edge_;
  std::vector<int> positions_;
  std::vector<Track> tracks_;
  std::map<int, FrameFit> frame_fits_;
  std::vector<LightImage> lights_;  // by position in the fitted frame list (lightOf)
  std::map<int, double> noise_;       // noise σ by position
  int next_id_ = 0;
  int detections_ = 0, rejected_ = 0;
  int group_resolves_ = 0;  // groups solved again because the groups before them moved onto them
  long long evaluations_ = 0, iterations_ = 0;
  double seconds_fitting_ = 0, seconds_detecting_ = 0;
};

}  // namespace

cv::Mat frameWithoutLight(const Frame& frame, const LightImage& light, double noise_sigma,
                          const DetectionOptions& options) {
  if (!light.found || !options.light_symmetry) return frame.image;
  return frame.image - estimateLightImage(frame.image, frame.valid, light, noise_sigma, options);
}

std::vector<GhostParameters> detectSeeds(const FramePyramid& data, const LightImage& light_full,
                                         int channels, const FitOptions& options) {
  const int kd = detectionLevel(data.size());
  const FrameData& level = data.level(kd);
  const cv::Mat lum = luminance(level.image);
  const LightImage light = light_full.atLevel(kd);
  std::vector<GhostParameters> seeds;
  for (const auto& c : detectGhosts(lum, level.valid, level.noise_sigma, light, options.detection)) {
    GhostParameters g = c.seed;
    for (double* v : {&g.center_x, &g.center_y, &g.left, &g.right, &g.height, &g.inside_falloff, &g.outside_falloff})
      *v *= kd;
    g.channels = channels;
    for (int k = 1; k < channels; ++k) {
      g.border[k] = g.border[0];
      g.inside[k] = g.inside[0];
    }
    seeds.push_back(g);
  }
  return seeds;
}

FitResult fitCapture(const FrameStack& stack, const FitOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("FitOptions: " + error);
  if (stack.frames.empty()) throw InputError(stack.source.string(), "no frames to fit");
  CaptureFitter fitter(stack, options);
  tbb::task_arena arena(options.threads);
  return arena.execute([&] { return fitter.run(); });
}

}  // namespace flarekit::fit
