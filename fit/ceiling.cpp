// The model's ceiling (fit/evaluation.h, measureModelCeiling): every true ghost fitted alone to
// its own noise-free layer.
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "common/error.h"
#include "common/exr.h"
#include "common/image.h"
#include "fit/cost.h"
#include "fit/detail/truth.h"
#include "fit/evaluation.h"
#include "fit/group_solver.h"
#include "fit/pedestal.h"

namespace flarekit::fit {

using namespace detail;

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
}  // namespace

bool CeilingOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (frame_step < 1) return fail("frame_step must be ≥ 1");
  if (!(fit_factor >= 0)) return fail("fit_factor must be ≥ 0");
  if (!(visible_factor > 0)) return fail("visible_factor must be > 0");
  if (max_iterations < 1) return fail("max_iterations must be ≥ 1");
  return cost.IsValid(error);
}

namespace {

// The starts for a true ghost's ceiling fit, from its own layer (flat: Ib = Ii = the layer's mean
// over the start's area, per channel):
//  - the ellipse of its second moments (half-axes 2σ, exact for a uniform ellipse) at its
//    centroid, with a soft edge (Fo 3 px, Fi 0.3 of its size) and a sharp one (Fo 0.5 px, Fi 0.1);
//  - that ellipse shrunk to 0.85, soft: a ghost with a bright rim has moments that overstate its
//    size, and from an outline well beyond its own Levenberg–Marquardt settles into a flat disc
//    whose border value is 0 (the fit tests' ghost with a rim twice its inside: from a circle of
//    its moment radius, 14.9 dB; from its own outline scaled 0.9–1.1×, exact; scaled 1.2× with a
//    sharp edge, a flat disc again). The 2σ ellipse reaches that ghost itself; the shrunk start is
//    for brighter rims, and its gain on the captures was not measured apart;
//  - the box of its pixels above 5 % of its peak, sharp: ghosts cut by the frame or an aperture.
std::vector<model::GhostParameters> ceilingStarts(const cv::Mat& image, const cv::Mat& lum, const Blob& b) {
  const int channels = image.channels();
  const cv::Scalar sum = cv::sum(image);
  auto start = [&](double x, double y, double l, double r, double h, double fo, double fi_fraction) {
    model::GhostParameters g;
    g.channels = channels;
    g.center_x = x;
    g.center_y = y;
    g.left = std::max(1.0, l);
    g.right = std::max(1.0, r);
    g.height = std::max(1.0, h);
    g.outside_falloff = fo;
    g.inside_falloff = fi_fraction * std::max({g.left, g.right, g.height});
    const double area = M_PI * 0.5 * (g.left + g.right) * g.height;
    for (int c = 0; c < channels; ++c) g.border[c] = g.inside[c] = std::max(0.0, sum[c]) / area;
    return g;
  };
  const double a = 2 * b.sigma_x, h = 2 * b.sigma_y;
  const cv::Rect e = cv::boundingRect(lum > 0.05 * b.peak);
  const double box_x = std::clamp(b.centroid.x, e.x + 1.0, e.x + e.width - 1.0);
  return {start(b.centroid.x, b.centroid.y, a, a, h, 3, 0.3),
          start(b.centroid.x, b.centroid.y, a, a, h, 0.5, 0.1),
          start(b.centroid.x, b.centroid.y, 0.85 * a, 0.85 * a, 0.85 * h, 3, 0.3),
          start(box_x, e.y + 0.5 * e.height, box_x - e.x, e.x + e.width - box_x, 0.5 * e.height, 0.5, 0.1)};
}

// One true ghost's best fit (measureModelCeiling), and its luminance over the frame.
CeilingGhost fitTrueGhost(const GhostTruth& truth, const cv::Mat& lum, const Blob& b, double noise_sigma,
                          const cv::Mat& psnr_mask, const CeilingOptions& options, cv::Mat& best_lum) {
  CeilingGhost best;
  best.id = truth.id;
  best.peak_sigma = noise_sigma > 0 ? b.peak / noise_sigma : kNaN;
  best.radius_px = b.radius;
  best.psnr_db = -std::numeric_limits<double>::infinity();
  // Both stages see the same filtered frame: the filter depends on σ1, σ2 only, λ weighs it in the
  // cost.
  CostOptions mse = options.cost;
  mse.edge_weight = 0;
  const EdgeFilter edge(options.cost);
  const cv::Mat all_valid(lum.size(), CV_8U, cv::Scalar(255));  // the truth has no saturation
  const FramePyramid pyramid(truth.image, all_valid, edge, noise_sigma);
  SolverOptions solver;
  solver.max_iterations = options.max_iterations;
  for (const auto& start : ceilingStarts(truth.image, lum, b)) {
    const std::vector<model::GhostParameters> one = {start};
    GroupCost cost(pyramid, edge, {}, one, options.cost);
    const GroupFitResult with_edges = solveGroup(cost, one, solver);
    GroupCost mse_cost(pyramid, edge, {}, with_edges.ghosts, mse);
    const GroupFitResult plain = solveGroup(mse_cost, with_edges.ghosts, solver);
    for (const auto* fit : {&with_edges, &plain}) {
      cv::Mat fitted = luminance(model::renderGhosts(fit->ghosts, lum.size(), truth.image.channels()));
      const double p = psnr(fitted, lum, psnr_mask);
      if (!(p > best.psnr_db)) continue;
      best.psnr_db = p;
      best.parameters = fit->ghosts[0];
      best.centroid_error_px = cv::norm(describe(fitted, {0, 0}).centroid - b.centroid);
      best_lum = fitted;
    }
  }
  return best;
}

// The quadratic in the pixel's x and y (model/pedestal.h) closest to `rest` in least squares over
// `region`, drawn over the frame and clamped at 0 (light is not negative).
cv::Mat quadraticPedestal(const cv::Mat& rest, const cv::Mat& region) {
  PedestalFitOptions least_squares;
  least_squares.outlier_sigma = 0;
  least_squares.step = 1;
  cv::Mat pedestal = cv::Mat::zeros(rest.size(), CV_32F);
  fitPedestal(rest, region, rest.size(), 1, 0, least_squares).addTo(pedestal, rest.size());
  return pedestal;
}

CeilingFrame ceilingOfFrame(const Frame& f, const CeilingOptions& options) {
  const FrameTruth truth = readFrameTruth(f, luminance(f.image), kNoiseBlockPx);
  CeilingFrame cf;
  cf.angle_deg = f.angle_deg;
  cf.noise_sigma = truth.noise_sigma;
  cv::Mat described = cv::Mat::zeros(truth.flare.size(), CV_32F);
  for (const auto& g : truth.ghosts) {
    const cv::Mat lum = luminance(g.image);
    const Blob b = describe(lum, {0, 0});
    if (!b.present || !(b.peak > options.fit_factor * truth.noise_sigma)) continue;
    cv::Mat fitted;
    CeilingGhost cg = fitTrueGhost(g, lum, b, truth.noise_sigma,
                                   (lum > 0) & (f.valid > 0), options, fitted);
    cg.visible = b.peak > options.visible_factor * truth.noise_sigma;
    if (!fitted.empty()) described += fitted;
    cf.ghosts.push_back(std::move(cg));
  }
  const cv::Mat flare_region = (truth.flare > truth.noise_sigma) & (f.valid > 0);
  // The ghosts left out sum to a glow, which the fitter draws as the frame's pedestal
  // (model/pedestal.h): drawn here as the constant that comes closest to what they leave, in least
  // squares over the flare region (their mean there), or the quadratic that does.
  if (options.fit_factor > 0 && cv::countNonZero(flare_region) > 0) {
    const cv::Mat rest = truth.flare - described;
    if (options.quadratic_pedestal) {
      const cv::Mat pedestal = quadraticPedestal(rest, flare_region);
      cf.pedestal = cv::mean(pedestal, flare_region)[0];
      described += pedestal;
    } else {
      cf.pedestal = std::max(0.0, cv::mean(rest, flare_region)[0]);
      described += cf.pedestal;
    }
  }
  cf.psnr_db = psnr(described, truth.flare, flare_region);
  cf.flare = truth.flare;
  cf.described = described;
  return cf;
}

}  // namespace

ModelCeiling measureModelCeiling(const FrameStack& stack, const CeilingOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("CeilingOptions: " + error);
  if (!stack.has_truth)
    throw InputError(stack.source.string(), "has no ground truth (truth/): the model's ceiling is measured against it");
  auto measured = measureFrames<CeilingFrame>(stack, "fit-ceiling", [&](size_t i) -> std::optional<CeilingFrame> {
    if (i % options.frame_step != 0) return std::nullopt;
    return ceilingOfFrame(stack.frames[i], options);
  });
  ModelCeiling c;
  c.image_size = stack.size;
  c.fit_above_sigma = options.fit_factor;
  c.quadratic_pedestal = options.quadratic_pedestal;
  std::vector<double> psnrs, errors;
  std::map<int, std::vector<const CeilingGhost*>> by_id;
  for (auto& cf : measured) {
    if (!cf) continue;
    c.frames.push_back(std::move(*cf));
  }
  for (const auto& cf : c.frames) {
    psnrs.push_back(cf.psnr_db);
    for (const auto& g : cf.ghosts) {
      if (!g.visible) continue;
      errors.push_back(g.centroid_error_px);
      ++c.visible_ghosts;
      if (g.centroid_error_px <= 0.5) ++c.within_half_px;
      by_id[g.id].push_back(&g);
    }
  }
  for (const auto& [id, seen] : by_id) {
    CeilingGhostSummary s;
    s.id = id;
    s.frames_visible = static_cast<int>(seen.size());
    std::vector<double> p, e;
    for (const CeilingGhost* g : seen) {
      p.push_back(g->psnr_db);
      e.push_back(g->centroid_error_px);
    }
    s.median_psnr_db = medianOf(p);
    s.median_centroid_error_px = medianOf(e);
    s.max_centroid_error_px = *std::max_element(e.begin(), e.end());
    c.ghosts.push_back(s);
  }
  c.median_psnr_db = medianOf(psnrs);
  c.median_centroid_error_px = medianOf(errors);
  return c;
}

nlohmann::json ModelCeiling::toJson() const {
  nlohmann::json j;
  j["format"] = kModelCeilingFormat;
  j["version"] = 1;
  j["image_width"] = image_size.width;
  j["image_height"] = image_size.height;
  j["frames_measured"] = frames.size();
  j["median_psnr_db"] = number(median_psnr_db);
  j["median_centroid_error_px"] = number(median_centroid_error_px);
  j["visible_ghosts"] = visible_ghosts;
  j["within_half_px"] = within_half_px;
  j["fit_above_sigma"] = fit_above_sigma;
  j["pedestal"] = fit_above_sigma > 0 ? (quadratic_pedestal ? "quadratic" : "flat") : "none";
  nlohmann::json fs = nlohmann::json::array();
  for (const auto& f : frames) {
    nlohmann::json gs = nlohmann::json::array();
    for (const auto& g : f.ghosts) {
      nlohmann::json parameters;
      const auto v = model::toParameterVector(g.parameters);
      for (size_t k = 0; k < v.size(); ++k) parameters[model::parameterName(static_cast<int>(k), g.parameters.channels)] = v[k];
      gs.push_back({{"id", g.id},
                    {"peak_sigma", number(g.peak_sigma)},
                    {"radius_px", g.radius_px},
                    {"visible", g.visible},
                    {"psnr_db", number(g.psnr_db)},
                    {"centroid_error_px", g.centroid_error_px},
                    {"parameters", parameters}});
    }
    fs.push_back({{"angle_deg", f.angle_deg},
                  {"noise_sigma", f.noise_sigma},
                  {"psnr_db", number(f.psnr_db)},
                  {"pedestal", f.pedestal},
                  {"ghosts", gs}});
  }
  j["frames"] = fs;
  nlohmann::json ghosts = nlohmann::json::array();
  for (const auto& g : this->ghosts)
    ghosts.push_back({{"id", g.id},
                      {"frames_visible", g.frames_visible},
                      {"median_psnr_db", number(g.median_psnr_db)},
                      {"median_centroid_error_px", number(g.median_centroid_error_px)},
                      {"max_centroid_error_px", number(g.max_centroid_error_px)}});
  j["true_ghosts"] = ghosts;
  return j;
}

std::string ModelCeiling::BriefReport() const {
  std::ostringstream s;
  s.precision(3);
  s << "Model ceiling over " << frames.size() << " frame(s), each true ghost ";
  if (fit_above_sigma > 0) s << "brighter than " << fit_above_sigma << " σ ";
  s << "fitted alone to its noise-free layer";
  if (fit_above_sigma > 0)
    s << ", the fainter ones as a " << (quadratic_pedestal ? "quadratic" : "flat") << " pedestal";
  s << ": median PSNR vs noise-free flare " << median_psnr_db << " dB; median centroid error "
    << median_centroid_error_px << " px over " << visible_ghosts << " visible ghosts, " << within_half_px
    << " within 0.5 px.";
  // The ghosts the model describes worst (lowest PSNR against their own layers), up to three.
  std::vector<CeilingGhostSummary> worst = ghosts;
  std::stable_sort(worst.begin(), worst.end(), [](const CeilingGhostSummary& a, const CeilingGhostSummary& b) {
    return a.median_psnr_db < b.median_psnr_db;
  });
  if (worst.size() > 3) worst.resize(3);
  for (size_t i = 0; i < worst.size(); ++i) {
    const auto& g = worst[i];
    s << (i == 0 ? " Described worst: ghost " : "; ghost ") << g.id << ", its own PSNR " << g.median_psnr_db
      << " dB, centroid error " << g.median_centroid_error_px << " px (up to " << g.max_centroid_error_px
      << "), over " << g.frames_visible << " frame(s)";
  }
  if (!worst.empty()) s << ".";
  return s.str();
}

CeilingCurve parseCeiling(const nlohmann::json& json, cv::Size image_size, const std::string& source) {
  if (!json.is_object() || json.value("format", "") != kModelCeilingFormat)
    throw InputError(
        source, std::string("is not the output of flarekit fit-ceiling --json (no \"format\": \"") +
                    kModelCeilingFormat + "\")");
  try {
    const cv::Size size(json.at("image_width").get<int>(), json.at("image_height").get<int>());
    if (size != image_size)
      throw InputError(source, "was measured on " + std::to_string(size.width) + "x" +
                                   std::to_string(size.height) + " frames, the capture's are " +
                                   std::to_string(image_size.width) + "x" +
                                   std::to_string(image_size.height));
    CeilingCurve curve;
    // Files written before --fit-above existed are the model's ceiling.
    curve.fit_above_sigma = json.value("fit_above_sigma", 0.0);
    curve.quadratic_pedestal = json.value("pedestal", std::string("none")) == "quadratic";
    for (const auto& f : json.at("frames")) {
      // A frame whose ceiling PSNR is null (no flare region) has nothing to compare against.
      if (f.at("psnr_db").is_null()) continue;
      curve.points.push_back({f.at("angle_deg").get<double>(), f.at("psnr_db").get<double>()});
    }
    return curve;
  } catch (const nlohmann::json::exception& e) {
    throw InputError(source, std::string("is not a complete fit-ceiling result: ") + e.what());
  }
}

std::string CeilingCurve::name() const {
  if (!(fit_above_sigma > 0)) return "the model's ceiling (fit-ceiling)";
  std::ostringstream s;
  s << "the ceiling of the ghosts above " << fit_above_sigma << " σ (fit-ceiling --fit-above "
    << fit_above_sigma << (quadratic_pedestal ? " --quadratic-pedestal)" : ")");
  return s.str();
}

std::string CeilingCurve::label() const {
  if (!(fit_above_sigma > 0)) return "the model's ceiling (fit-ceiling)";
  std::ostringstream s;
  s << "ceiling of the ghosts above " << fit_above_sigma << " sigma";
  return s.str();
}

}  // namespace flarekit::fit
