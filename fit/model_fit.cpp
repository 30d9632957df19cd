#include "fit/model_fit.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <iterator>
#include <limits>
#include <map>

#include <ceres/ceres.h>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "common/image.h"
#include "common/progress.h"
#include "fit/normal_equations.h"
#include "fit/polynomial.h"
#include "fit/shade.h"
#include "model/model_renderer.h"

namespace flarekit::fit {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// One ghost of the model while it is fitted: a scaled polynomial per parameter over its range.
struct GhostCurves {
  int id = 0;
  double angle_min = 0, angle_max = 0;  // field angles
  std::vector<ScaledPolynomial> parameters;
  std::vector<int> offset;              // where each parameter's coefficients start in the block
  std::vector<double> block;            // all coefficients, parameter after parameter

  bool covers(double angle) const { return angle >= angle_min && angle <= angle_max; }
  std::vector<model::ParameterBounds> bounds;  // the fitter's (fit/cost.h fitBounds)

  // The parameters at θ from the block's current coefficients, within `bounds`.
  model::GhostParameters at(double angle, int channels, const double* coefficients) const {
    std::vector<double> v(parameters.size());
    for (size_t k = 0; k < parameters.size(); ++k) {
      const double u = parameters[k].variable(angle);
      const int n = static_cast<int>(parameters[k].coefficients.size());
      double value = 0;
      for (int m = n - 1; m >= 0; --m) value = value * u + coefficients[offset[k] + m];
      v[k] = std::clamp(value, bounds[k].lower, bounds[k].upper);
    }
    return model::fromParameterVector(v, channels);
  }
  // Whether parameter k at θ lies beyond its bounds (and is held at one).
  bool clamped(int k, double angle, const double* coefficients) const {
    const double u = parameters[k].variable(angle);
    double value = 0;
    for (int m = static_cast<int>(parameters[k].coefficients.size()) - 1; m >= 0; --m)
      value = value * u + coefficients[offset[k] + m];
    return value < bounds[k].lower || value > bounds[k].upper;
  }
  void storeBlock() {
    block.clear();
    offset.clear();
    for (const auto& p : parameters) {
      offset.push_back(static_cast<int>(block.size()));
      block.insert(block.end(), p.coefficients.begin(), p.coefficients.end());
    }
  }
  void loadBlock() {
    for (size_t k = 0; k < parameters.size(); ++k)
      std::copy_n(block.begin() + offset[k], parameters[k].coefficients.size(),
                  parameters[k].coefficients.begin());
  }
};

// The frames the refinement measures the model against.
struct RefineFrame {
  double angle = 0;                  // field angle
  std::vector<int> ghosts;           // indices into the curves, present here
  std::unique_ptr<FramePyramid> pyramid;
  std::unique_ptr<GroupCost> cost;
  std::unique_ptr<NormalEquations> normal;
};

// Renders every refinement frame at the coefficients and sums the normal equations of the
// coefficients: a frame's JᵀJ over its ghosts' parameters, carried to their coefficients by the
// polynomials' powers (the chain rule: ∂q/∂a_m = u^m).
class ModelEquations {
 public:
  ModelEquations(std::vector<GhostCurves>& curves, std::vector<RefineFrame>& frames, int channels)
      : curves_(curves), frames_(frames), channels_(channels) {
    for (auto& c : curves_) {
      start_.push_back(total_);
      total_ += static_cast<int>(c.block.size());
    }
  }
  int total() const { return total_; }
  int start(int g) const { return start_[g]; }

  void evaluate(bool with_jacobians) {
    a_ = Eigen::MatrixXd::Zero(with_jacobians ? total_ : 0, with_jacobians ? total_ : 0);
    b_ = Eigen::VectorXd::Zero(with_jacobians ? total_ : 0);
    c_ = 0;
    const int p = model::parameterCount(channels_);
    for (auto& f : frames_) {
      std::vector<model::GhostParameters> ghosts;
      for (int g : f.ghosts) ghosts.push_back(curves_[g].at(f.angle, channels_, curves_[g].block.data()));
      f.cost->evaluate(ghosts, with_jacobians);
      f.normal->fill(with_jacobians);
      c_ += f.normal->squaredNorm();
      if (!with_jacobians) continue;
      // The powers of each ghost's parameters here: T_g (p × its coefficients).
      std::vector<Eigen::MatrixXd> t(f.ghosts.size());
      for (size_t j = 0; j < f.ghosts.size(); ++j) {
        const GhostCurves& c = curves_[f.ghosts[j]];
        t[j] = Eigen::MatrixXd::Zero(p, static_cast<Eigen::Index>(c.block.size()));
        for (int k = 0; k < p; ++k) {
          if (k == model::param::kMy) continue;  // held on the horizon
          // A parameter held at its bound does not move with its coefficients.
          if (c.clamped(k, f.angle, c.block.data())) continue;
          const double u = c.parameters[k].variable(f.angle);
          double power = 1;
          for (size_t m = 0; m < c.parameters[k].coefficients.size(); ++m, power *= u)
            t[j](k, c.offset[k] + static_cast<int>(m)) = power;
        }
      }
      const Eigen::MatrixXd& a = f.normal->jtj();
      const Eigen::VectorXd& b = f.normal->jtr();
      for (size_t j = 0; j < f.ghosts.size(); ++j) {
        const int gj = f.ghosts[j];
        const auto n_j = t[j].cols();
        b_.segment(start_[gj], n_j) += t[j].transpose() * b.segment(j * p, p);
        for (size_t i = 0; i < f.ghosts.size(); ++i) {
          const int gi = f.ghosts[i];
          a_.block(start_[gj], start_[gi], n_j, t[i].cols()) +=
              t[j].transpose() * a.block(j * p, i * p, p, p) * t[i];
        }
      }
    }
    if (with_jacobians) root_ = squareRootForm(a_, b_, c_);
    with_jacobians_ = with_jacobians;
  }
  void squareRoot(double* residuals, double* const* jacobians) const {
    if (!with_jacobians_) {
      residuals[0] = std::sqrt(c_);
      std::fill(residuals + 1, residuals + total_ + 1, 0.0);
      return;
    }
    std::copy_n(root_.residuals.data(), total_, residuals);
    residuals[total_] = root_.rest;
    if (!jacobians) return;
    for (size_t g = 0; g < curves_.size(); ++g) {
      if (!jacobians[g]) continue;
      const int n = static_cast<int>(curves_[g].block.size());
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> block(
          jacobians[g], total_ + 1, n);
      block.topRows(total_) = root_.jacobian.middleCols(start_[g], n);
      block.row(total_).setZero();
    }
  }

 private:
  std::vector<GhostCurves>& curves_;
  std::vector<RefineFrame>& frames_;
  int channels_;
  std::vector<int> start_;
  int total_ = 0;
  Eigen::MatrixXd a_;
  Eigen::VectorXd b_;
  double c_ = 0;
  bool with_jacobians_ = false;
  SquareRootForm root_;
};

// Renders the model once per evaluation point (as group_solver.cpp's callback does for a frame).
class ModelCallback : public ceres::EvaluationCallback {
 public:
  explicit ModelCallback(ModelEquations& equations) : equations_(equations) {}
  void PrepareForEvaluation(bool evaluate_jacobians, bool new_point) override {
    if (evaluated_ && !new_point && (!evaluate_jacobians || had_jacobians_)) return;
    equations_.evaluate(evaluate_jacobians);
    evaluated_ = true;
    had_jacobians_ = evaluate_jacobians;
  }

 private:
  ModelEquations& equations_;
  bool evaluated_ = false, had_jacobians_ = false;
};

class ModelResidual : public ceres::CostFunction {
 public:
  ModelResidual(const ModelEquations& equations, const std::vector<GhostCurves>& curves)
      : equations_(equations) {
    set_num_residuals(equations.total() + 1);
    for (const auto& c : curves) mutable_parameter_block_sizes()->push_back(static_cast<int>(c.block.size()));
  }
  bool Evaluate(double const* const*, double* residuals, double** jacobians) const override {
    equations_.squareRoot(residuals, jacobians);
    return true;
  }

 private:
  const ModelEquations& equations_;
};

// One fitted frame's shade problem for the model's outlines (fit/shade.h ShadeEquations).
struct ShadeFrame {
  double angle = 0;          // field angle
  std::vector<int> present;  // indices into the curves, in the equations' order
  ShadeEquations equations;
};

// Where each ghost's shade coefficients sit among the unknowns of the joint shade solve: Ib's
// (degree + 1) coefficients from start, then Ii's; degree −1: no unknowns (no frame of it used).
struct ShadeUnknowns {
  std::vector<int> start, degree;
  int total = 0;
  // Where ghost g's Ib (q = 0) or Ii (q = 1) coefficients start.
  int first(int g, int q) const { return start[g] + q * (degree[g] + 1); }
};

// The unknowns of the joint shade solve over the frames `use` selects, at `degree` (each ghost's
// lowered to what its frames there allow).
ShadeUnknowns shadeUnknowns(size_t ghosts, const std::vector<ShadeFrame>& frames,
                            const std::vector<bool>& use, int degree) {
  std::vector<int> count(ghosts, 0);
  for (size_t i = 0; i < frames.size(); ++i)
    if (use[i])
      for (int g : frames[i].present) ++count[g];
  ShadeUnknowns u;
  for (size_t g = 0; g < ghosts; ++g) {
    u.start.push_back(u.total);
    u.degree.push_back(std::min(degree, count[g] - 1));
    u.total += 2 * (u.degree.back() + 1);
  }
  return u;
}

// u⁰ … u^degree at field angle θ, u the ghost's scaled angle: its shade coefficients' weights.
std::vector<double> powers(const GhostCurves& c, double angle, int degree) {
  std::vector<double> p(static_cast<size_t>(std::max(degree + 1, 0)));
  const double u = c.parameters[model::param::kMx].variable(angle);
  double power = 1;
  for (auto& v : p) v = power, power *= u;
  return p;
}

// Least-squares coefficients of every ghost's Ib and Ii in channel c over the frames `use` selects.
Eigen::VectorXd solveShades(const std::vector<GhostCurves>& curves, const std::vector<ShadeFrame>& frames,
                            const std::vector<bool>& use, const ShadeUnknowns& u, int c) {
  Eigen::MatrixXd n = Eigen::MatrixXd::Zero(u.total, u.total);
  Eigen::VectorXd r = Eigen::VectorXd::Zero(u.total);
  for (size_t f = 0; f < frames.size(); ++f) {
    if (!use[f]) continue;
    const auto& sf = frames[f];
    const Eigen::MatrixXd& nf = sf.equations.normal[c];
    const Eigen::VectorXd& rf = sf.equations.rhs[c];
    std::vector<std::vector<double>> pw;
    for (int g : sf.present) pw.push_back(powers(curves[g], sf.angle, u.degree[g]));
    for (size_t j = 0; j < sf.present.size(); ++j) {
      const int gj = sf.present[j], dj = u.degree[gj];
      const auto& pj = pw[j];
      for (int q = 0; q < 2; ++q)
        for (int a = 0; a <= dj; ++a) {
          const int row = u.first(gj, q) + a;
          r(row) += pj[a] * rf(2 * j + q);
          for (size_t i = 0; i < sf.present.size(); ++i) {
            const int gi = sf.present[i], di = u.degree[gi];
            const auto& pi = pw[i];
            for (int p = 0; p < 2; ++p)
              for (int b = 0; b <= di; ++b)
                n(row, u.first(gi, p) + b) += pj[a] * pi[b] * nf(2 * j + q, 2 * i + p);
          }
        }
    }
  }
  // Shades are ≥ 0 (the model file holds them so over each ghost's range): where a polynomial
  // dips below, it is held at its lowest point and all are solved again (with the held points as
  // equality constraints), until none dips. Held a hair above 0, not at it, so that rounding in
  // the model file's powers of θ cannot take it below. Checked where the model file is checked.
  constexpr int kChecks = 129;
  constexpr double kHeldAt = 1e-6;  // of the brightest shade
  std::vector<Eigen::VectorXd> held;
  // A ridge far below any determined direction's weight: what the frames leave undetermined (a
  // ghost's shade where its pixels are all masked, two candidates drawing the same light) stays
  // near 0 instead of taking on the noise, amplified.
  constexpr double kRidge = 1e-9;  // of the mean diagonal
  n.diagonal().array() += kRidge * n.diagonal().mean();
  Eigen::VectorXd x = n.completeOrthogonalDecomposition().solve(r);
  // Polynomial `q` of ghost g at check i.
  auto value = [&](size_t g, int q, int i) {
    const double v = -1 + 2.0 * i / (kChecks - 1);
    double sum = 0;
    for (int a = u.degree[g]; a >= 0; --a) sum = sum * v + x(u.first(g, q) + a);
    return sum;
  };
  double brightest = 0;
  for (size_t g = 0; g < curves.size(); ++g)
    for (int q = 0; q < 2 && u.degree[g] >= 0; ++q)
      for (int i = 0; i < kChecks; ++i) brightest = std::max(brightest, std::abs(value(g, q, i)));
  for (int round = 0; round < u.total; ++round) {
    bool dipped = false;
    for (size_t g = 0; g < curves.size(); ++g) {
      const int d = u.degree[g];
      for (int q = 0; q < 2 && d >= 0; ++q) {
        double lowest = 0;
        int at = 0;
        for (int i = 0; i < kChecks; ++i)
          if (const double v = value(g, q, i); v < lowest) lowest = v, at = i;
        if (lowest >= 0) continue;
        Eigen::VectorXd row = Eigen::VectorXd::Zero(u.total);
        for (int a = 0; a <= d; ++a)
          row(u.first(g, q) + a) = std::pow(-1 + 2.0 * at / (kChecks - 1), a);
        held.push_back(row);
        dipped = true;
      }
    }
    if (!dipped) break;
    const int h = static_cast<int>(held.size());
    Eigen::MatrixXd kkt = Eigen::MatrixXd::Zero(u.total + h, u.total + h);
    kkt.topLeftCorner(u.total, u.total) = n;
    for (int j = 0; j < h; ++j) {
      kkt.block(u.total + j, 0, 1, u.total) = held[j].transpose();
      kkt.block(0, u.total + j, u.total, 1) = held[j];
    }
    Eigen::VectorXd rhs = Eigen::VectorXd::Constant(u.total + h, kHeldAt * brightest);
    rhs.head(u.total) = r;
    x = kkt.completeOrthogonalDecomposition().solve(rhs).head(u.total);
  }
  return x;
}

// The frames' shades (Ib, Ii per present ghost) that coefficients `x` give in channel c.
Eigen::VectorXd shadesAt(const std::vector<GhostCurves>& curves, const ShadeFrame& sf,
                         const ShadeUnknowns& u, const Eigen::VectorXd& x) {
  Eigen::VectorXd v = Eigen::VectorXd::Zero(2 * static_cast<Eigen::Index>(sf.present.size()));
  for (size_t j = 0; j < sf.present.size(); ++j) {
    const int g = sf.present[j], d = u.degree[g];
    const auto p = powers(curves[g], sf.angle, d);
    for (int q = 0; q < 2; ++q)
      for (int a = 0; a <= d; ++a) v(2 * j + q) += p[a] * x(u.first(g, q) + a);
  }
  return v;
}

// Every ghost's shade polynomials at once: the model's image is linear in their coefficients, so
// the frames' shade equations summed over θ solve them by one linear least squares per channel,
// and the light overlapping ghosts share is split as stays smooth over θ (per-frame values,
// traded between them from frame to frame, are not). One degree for all, the one whose fit on
// every other frame predicts the others' pixels best.
void solveShadeCurves(std::vector<GhostCurves>& curves, const std::vector<ShadeFrame>& frames,
                      int channels, int min_degree, int max_degree) {
  const size_t n = frames.size();
  std::vector<bool> all(n);
  for (size_t i = 0; i < n; ++i) all[i] = !frames[i].present.empty();
  int best_degree = min_degree;
  double best_error = std::numeric_limits<double>::infinity();
  for (int degree = min_degree; degree <= max_degree; ++degree) {
    // Held-out error up to a constant: xᵀ N x − 2 xᵀ r over the frames left out.
    double error = 0;
    for (int fold = 0; fold < 2; ++fold) {
      std::vector<bool> fit(n), held(n);
      for (size_t i = 0; i < n; ++i) (i % 2 == static_cast<size_t>(fold) ? fit : held)[i] = all[i];
      const ShadeUnknowns u = shadeUnknowns(curves.size(), frames, fit, degree);
      for (int c = 0; c < channels; ++c) {
        const Eigen::VectorXd x = solveShades(curves, frames, fit, u, c);
        for (size_t i = 0; i < n; ++i)
          if (held[i]) {
            const Eigen::VectorXd v = shadesAt(curves, frames[i], u, x);
            error += v.dot(frames[i].equations.normal[c] * v) - 2 * v.dot(frames[i].equations.rhs[c]);
          }
      }
    }
    if (error < best_error) best_error = error, best_degree = degree;
  }
  const ShadeUnknowns u = shadeUnknowns(curves.size(), frames, all, best_degree);
  const model::ParameterLayout layout{channels};
  for (int c = 0; c < channels; ++c) {
    const Eigen::VectorXd x = solveShades(curves, frames, all, u, c);
    for (size_t g = 0; g < curves.size(); ++g) {
      const int d = u.degree[g];
      if (d < 0) continue;
      for (int q = 0; q < 2; ++q) {
        auto& p = curves[g].parameters[q == 0 ? layout.ib(c) : layout.ii(c)];
        p.centre = curves[g].parameters[model::param::kMx].centre;
        p.scale = curves[g].parameters[model::param::kMx].scale;
        p.coefficients.assign(x.data() + u.first(g, q), x.data() + u.first(g, q) + d + 1);
      }
    }
  }
}

// a + sign·b (sign ±1).
model::Polynomial combined(const model::Polynomial& a, const model::Polynomial& b, double sign) {
  model::Polynomial s = a;
  s.coefficients.resize(std::max(a.coefficients.size(), b.coefficients.size()), 0.0);
  for (size_t i = 0; i < b.coefficients.size(); ++i) s.coefficients[i] += sign * b.coefficients[i];
  return s;
}

// `p` as a polynomial that stays within bounds `b` over [lo, hi] (where the model file is
// checked): where it strays, the least-squares polynomial through its values clamped to the
// bounds, of the highest degree that stays within them.
model::Polynomial withinBounds(const ScaledPolynomial& p, const model::ParameterBounds& b, double lo, double hi) {
  constexpr int kChecks = 129;
  auto inside = [&](const model::Polynomial& q) {
    for (int i = 0; i < kChecks; ++i) {
      const double v = q.evaluate(lo + (hi - lo) * i / (kChecks - 1));
      if (!(v >= b.lower && v <= b.upper)) return false;
    }
    return true;
  };
  model::Polynomial e = p.expanded();
  if (inside(e)) return e;
  std::vector<double> angles, values;
  for (int i = 0; i < kChecks; ++i) {
    angles.push_back(lo + (hi - lo) * i / (kChecks - 1));
    values.push_back(std::clamp(p.evaluate(angles.back()), b.lower, b.upper));
  }
  for (int degree = static_cast<int>(p.coefficients.size()) - 1; degree > 0; --degree) {
    e = leastSquaresPolynomial(angles, values, degree);
    if (inside(e)) return e;
  }
  std::sort(values.begin(), values.end());
  return {{values[values.size() / 2]}};
}

}  // namespace

bool ModelFitOptions::IsValid(std::string* error) const {
  if (!cost.IsValid(error) || !pedestal_fit.IsValid(error)) return false;
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (min_degree < 0 || max_degree < min_degree || max_degree > model::kMaxPolynomialDegree)
    return fail("model fit: need 0 ≤ min_degree ≤ max_degree ≤ 10");
  if (refine_pixels < 1000) return fail("model fit: refine_pixels must be ≥ 1000");
  if (refine_iterations < 1) return fail("model fit: refine_iterations must be ≥ 1");
  if (!(min_peak_sigma >= 0)) return fail("model fit: min_peak_sigma must be ≥ 0");
  if (pedestal_degree < 0 || pedestal_degree > model::kMaxPolynomialDegree)
    return fail("model fit: pedestal_degree must be 0–10");
  if (pedestal_level < 1) return fail("model fit: pedestal_level must be ≥ 1");
  if (!shade.IsValid(error)) return false;
  return true;
}

model::FlareModel fitModel(const FrameStack& stack, const Horizon& horizon, const LightPattern& pattern,
                           const std::vector<GhostCandidate>& candidates,
                           const std::vector<FrameFit>& fits, const OpticalZero& zero,
                           const ModelFitOptions& o, ModelFitSummary* summary) {
  const double horizon_y_px = horizon.y_px;
  // The frames as the fit measures them: the light's image taken out.
  auto withoutLight = [&](size_t i) {
    Frame f = stack.frames[i];
    f.image = f.image.clone();
    f.valid = f.valid.clone();
    pattern.takeOut(horizon.lights[i], f.image, f.valid);
    return f;
  };
  std::string error;
  if (!o.IsValid(&error)) throw std::invalid_argument(error);
  ModelFitSummary sum;
  const int channels = stack.channels;
  const int p = model::parameterCount(channels);
  model::FlareModel m;
  m.capture = stack.info;
  m.capture.angle_zero_deg = zero.angle_zero_deg;
  m.capture.optical_axis_px = cv::Point2d(zero.axis_x_px, horizon_y_px);
  m.channels = channels;
  const double half_step = 0.5 * (stack.info.angle_step_deg > 0 ? stack.info.angle_step_deg : 0);
  const double capture_min = m.capture.fieldAngle(stack.frames.front().angle_deg);
  const double capture_max = m.capture.fieldAngle(stack.frames.back().angle_deg);

  // 1. Each parameter's robust polynomial over the frame fits (for L and R, the borders'), of the
  // degree that predicts held-out fits best.
  const auto t_poly = Clock::now();
  struct Samples {
    std::vector<double> angles;
    std::vector<model::GhostParameters> ghosts;
    std::vector<bool> left_seen, right_seen;  // whether the sweep saw that border in the frame
  };
  std::map<int, const GhostCandidate*> candidate_of;
  for (const auto& c : candidates) candidate_of[c.id] = &c;
  std::map<int, Samples> samples;
  for (const auto& f : fits)
    for (size_t j = 0; j < f.ghost_ids.size(); ++j) {
      const GhostCandidate& c = *candidate_of.at(f.ghost_ids[j]);
      auto& s = samples[f.ghost_ids[j]];
      s.angles.push_back(m.capture.fieldAngle(f.angle_deg));
      s.ghosts.push_back(f.ghosts[j]);
      s.left_seen.push_back(c.present(f.frame) && c.leftSeen(f.frame));
      s.right_seen.push_back(c.present(f.frame) && c.rightSeen(f.frame));
    }
  std::vector<GhostCurves> curves;
  // Each fitted frame's pedestal under the model's ghosts (from the frame fits, then the shades).
  std::map<int, model::Pedestal> pedestal_of_frame;
  for (const auto& f : fits) pedestal_of_frame[f.frame] = f.pedestal;
  for (const auto& c : candidates) {
    auto it = samples.find(c.id);
    if (it == samples.end() || it->second.angles.empty()) continue;
    const auto& [angles, ghosts, left_seen, right_seen] = it->second;
    GhostCurves g;
    g.id = c.id;
    for (int k = 0; k < p; ++k)
      g.bounds.push_back(fitBounds(k, channels, stack.size, model::kUnbounded));
    g.angle_min = std::max(capture_min, m.capture.fieldAngle(stack.frames[c.first_row].angle_deg) - half_step);
    g.angle_max = std::min(capture_max, m.capture.fieldAngle(stack.frames[c.last_row].angle_deg) + half_step);
    auto curveOver = [&](const std::vector<double>& at, const std::vector<double>& values) {
      const int degree = std::min(degreeByValidation(at, values, o.min_degree, o.max_degree),
                                  static_cast<int>(at.size()) - 1);
      return robustPolynomial(at, values, degree);
    };
    auto curve = [&](const std::vector<double>& values) { return curveOver(angles, values); };
    // The borders, not the middle and half-widths, are what a frame measures where a ghost's
    // other border is beyond it: x_L = Mx − L and x_R = Mx + R get curves of their own, each
    // through the frames that saw that border (where enough did; elsewhere a frame's fit places
    // it freely). The middle follows both borders' frames where both were seen; where only one
    // was, it is that border's curve less the half-width's on its side (a frame places the middle
    // of such a ghost freely too, but never beyond its seen border).
    std::vector<double> xl, xr, mx, left, right;
    for (const auto& q : ghosts) {
      xl.push_back(q.center_x - q.left);
      xr.push_back(q.center_x + q.right);
      mx.push_back(q.center_x);
      left.push_back(q.left);
      right.push_back(q.right);
    }
    auto seenEnough = [&](const std::vector<bool>& seen) {
      return std::count(seen.begin(), seen.end(), true) > o.max_degree + 1;
    };
    auto borderCurve = [&](const std::vector<double>& x, const std::vector<bool>& seen) {
      if (!seenEnough(seen)) return curve(x);
      std::vector<double> at, values;
      for (size_t i = 0; i < x.size(); ++i)
        if (seen[i]) {
          at.push_back(angles[i]);
          values.push_back(x[i]);
        }
      return curveOver(at, values);
    };
    const model::Polynomial left_border = borderCurve(xl, left_seen);
    const model::Polynomial right_border = borderCurve(xr, right_seen);
    const bool left_only = seenEnough(left_seen) && !seenEnough(right_seen);
    const bool right_only = seenEnough(right_seen) && !seenEnough(left_seen);
    const model::Polynomial middle = left_only    ? combined(left_border, curve(left), +1)
                                     : right_only ? combined(right_border, curve(right), -1)
                                                  : curve(mx);
    for (int k = 0; k < p; ++k) {
      model::Polynomial poly;
      if (k == model::param::kMy) {
        poly = {{horizon_y_px}};
      } else if (k == model::param::kMx) {
        poly = middle;
      } else if (k == model::param::kL) {
        poly = combined(middle, left_border, -1);
      } else if (k == model::param::kR) {
        poly = combined(right_border, middle, -1);
      } else {
        std::vector<double> values;
        for (const auto& q : ghosts) values.push_back(model::toParameterVector(q)[k]);
        poly = curve(values);
      }
      g.parameters.push_back(ScaledPolynomial::from(poly, g.angle_min, g.angle_max));
    }
    g.storeBlock();
    curves.push_back(std::move(g));
  }
  // The shades again, for the model's own outlines: every fitted frame's shade problem for the
  // polynomials' shapes there (fit/shade.h), then all the shade polynomials at once from them. A
  // frame fit's shade answers to its own outline; the model's to the polynomials'.
  if (o.reshade && !curves.empty()) {
    std::vector<ShadeFrame> frames(fits.size());
    std::vector<model::Pedestal> pedestals(fits.size());
    tbb::parallel_for(size_t{0}, fits.size(), [&](size_t i) {
      ShadeFrame& sf = frames[i];
      sf.angle = m.capture.fieldAngle(fits[i].angle_deg);
      std::vector<model::GhostParameters> ghosts;
      for (size_t g = 0; g < curves.size(); ++g)
        if (curves[g].covers(sf.angle)) {
          sf.present.push_back(static_cast<int>(g));
          ghosts.push_back(curves[g].at(sf.angle, channels, curves[g].block.data()));
        }
      if (ghosts.empty()) return;
      const Frame f = withoutLight(static_cast<size_t>(fits[i].frame));
      fitShades(f.image, f.valid, fits[i].noise_sigma, ghosts, &pedestals[i], o.shade, &sf.equations);
      if (sf.equations.normal.empty()) sf.present.clear();
    });
    solveShadeCurves(curves, frames, channels, o.min_degree, o.max_degree);
    for (auto& c : curves) c.storeBlock();
    for (size_t i = 0; i < fits.size(); ++i) pedestal_of_frame[fits[i].frame] = pedestals[i];
  }
  sum.seconds_polynomials = since(t_poly);

  // 2. The coefficients refined against the frames.
  const auto t_refine = Clock::now();
  if (o.refine && !curves.empty()) {
    CostOptions cost = o.cost;
    cost.prior_fraction = 0;
    cost.max_pixels = o.refine_pixels;
    cost.whole_frame = true;  // the ghosts move while refined: the region must not follow the seeds
    const EdgeFilter edge(cost);
    // The fitted frames: only there is the pedestal under the ghosts known, and a target that
    // kept it would have the ghosts bent to draw the veils the pedestal draws.
    std::vector<RefineFrame> frames;
    for (const auto& fit : fits) {
      const auto i = static_cast<size_t>(fit.frame);
      RefineFrame rf;
      rf.angle = m.capture.fieldAngle(stack.frames[i].angle_deg);
      for (size_t g = 0; g < curves.size(); ++g)
        if (curves[g].covers(rf.angle)) rf.ghosts.push_back(static_cast<int>(g));
      if (rf.ghosts.empty()) continue;
      const Frame f = withoutLight(i);
      const cv::Mat target = f.image - pedestal_of_frame.at(fit.frame).image(stack.size);
      const double sigma = estimatePixelNoiseSigma(stack.frames[i].image, stack.frames[i].valid);
      rf.pyramid = std::make_unique<FramePyramid>(target, f.valid, edge, sigma);
      frames.push_back(std::move(rf));
    }
    // Each frame's cost over the whole frame at one level.
    tbb::parallel_for(size_t{0}, frames.size(), [&](size_t i) {
      RefineFrame& rf = frames[i];
      std::vector<model::GhostParameters> seeds;
      for (int g : rf.ghosts) seeds.push_back(curves[g].at(rf.angle, channels, curves[g].block.data()));
      rf.cost = std::make_unique<GroupCost>(*rf.pyramid, edge, std::vector<model::GhostParameters>{}, seeds, cost);
      rf.normal = std::make_unique<NormalEquations>(*rf.cost);
    });
    sum.refine_frames = static_cast<int>(frames.size());
    ModelEquations equations(curves, frames, channels);
    ModelCallback callback(equations);
    ceres::Problem::Options problem_options;
    problem_options.evaluation_callback = &callback;
    ceres::Problem problem(problem_options);
    std::vector<double*> blocks;
    for (auto& c : curves) blocks.push_back(c.block.data());
    problem.AddResidualBlock(new ModelResidual(equations, curves), nullptr, blocks);
    ceres::Solver::Options so;
    so.minimizer_type = ceres::TRUST_REGION;
    so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = o.refine_iterations;
    so.num_threads = 1;
    so.logging_type = ceres::SILENT;
    so.function_tolerance = 1e-5;
    ceres::Solver::Summary s;
    ceres::Solve(so, &problem, &s);
    sum.refine_iterations = static_cast<int>(s.iterations.size());
    sum.refine_initial_cost = s.initial_cost;
    sum.refine_final_cost = s.final_cost;
    sum.refine_termination = ceres::TerminationTypeToString(s.termination_type);
    for (auto& c : curves) c.loadBlock();
  }
  sum.seconds_refine = since(t_refine);

  // 3. Each ghost's range ends where it draws nothing the frames can show: its brightest value
  // (Ib or Ii, in luminance, as the outlines are fitted and fit-eval counts a ghost visible)
  // below min_peak_sigma × the frame's noise σ (measured at kNoiseBlockPx, as a mono and an RGGB
  // sensor show it alike). The shades decide where a ghost is, not the candidates' traces
  // alone: a trace's ghost whose light the others already draw gets shades of about 0 and is no
  // ghost there.
  std::vector<double> noise(fits.size());
  tbb::parallel_for(size_t{0}, fits.size(), [&](size_t i) {
    const Frame& f = stack.frames[static_cast<size_t>(fits[i].frame)];
    noise[i] = estimatePixelNoiseSigma(f.image, f.valid, kNoiseBlockPx);
  });
  std::vector<GhostCurves> seen;
  for (auto& c : curves) {
    // The fitted frames in its range, and whether it draws light in each.
    std::vector<std::pair<double, bool>> lit;
    for (size_t i = 0; i < fits.size(); ++i) {
      const double angle = m.capture.fieldAngle(fits[i].angle_deg);
      if (!c.covers(angle)) continue;
      const model::GhostParameters q = c.at(angle, channels, c.block.data());
      const double peak = std::max(luminance(q.border.data(), channels), luminance(q.inside.data(), channels));
      lit.emplace_back(angle, peak >= o.min_peak_sigma * noise[i]);
    }
    std::sort(lit.begin(), lit.end());
    auto first = std::find_if(lit.begin(), lit.end(), [](const auto& a) { return a.second; });
    if (first == lit.end()) {
      ++sum.ghosts_unseen;
      continue;
    }
    auto last = std::find_if(lit.rbegin(), lit.rend(), [](const auto& a) { return a.second; });
    // It ends before the first dark fitted frame beyond its lit ones (the frames between, not
    // fitted, are taken as lit); where there is none, where its candidate ends.
    if (first != lit.begin()) c.angle_min = std::max(c.angle_min, std::prev(first)->first + half_step);
    if (last != lit.rbegin()) c.angle_max = std::min(c.angle_max, std::prev(last)->first - half_step);
    seen.push_back(std::move(c));
  }
  curves = std::move(seen);

  for (const auto& c : curves) {
    model::GhostTrack t;
    t.id = c.id;
    t.angle_min_deg = c.angle_min;
    t.angle_max_deg = c.angle_max;
    for (size_t k = 0; k < c.parameters.size(); ++k)
      t.parameters.push_back(withinBounds(c.parameters[k], c.bounds[k], c.angle_min, c.angle_max));
    m.ghosts.push_back(std::move(t));
  }
  sum.ghosts = static_cast<int>(m.ghosts.size());

  // 4. The pedestal: what the model's ghosts leave of each frame, as polynomials.
  const auto t_pedestal = Clock::now();
  if (o.pedestal) {
    const int k = o.pedestal_level;
    std::vector<double> angles(stack.frames.size());
    std::vector<model::Pedestal> pedestals(stack.frames.size());
    std::vector<double> sigmas(stack.frames.size());
    tbb::parallel_for(size_t{0}, stack.frames.size(), [&](size_t i) {
      const Frame f = withoutLight(i);
      angles[i] = m.capture.fieldAngle(f.angle_deg);
      const cv::Size size(stack.size.width / k, stack.size.height / k);
      const cv::Rect whole(0, 0, size.width * k, size.height * k);
      cv::Mat level, valid;
      cv::resize(f.image(whole), level, size, 0, 0, cv::INTER_AREA);
      cv::resize(f.valid(whole), valid, size, 0, 0, cv::INTER_AREA);
      valid = valid >= 255;
      std::vector<model::GhostParameters> ghosts;
      for (const auto& g : m.ghostsAt(angles[i])) ghosts.push_back(g.parameters);
      model::ViewTransform view;
      view.scale = 1.0 / k;
      const cv::Mat drawn = model::renderGhosts(ghosts, size, channels, {}, view);
      sigmas[i] = estimatePixelNoiseSigma(f.image, f.valid);
      pedestals[i] = fitPedestal(level - drawn, valid, stack.size, k, sigmas[i] / k, o.pedestal_fit);
    });
    model::PedestalTrack track;
    track.angle_min_deg = capture_min;
    track.angle_max_deg = capture_max;
    for (int term = 0; term < model::kPedestalTerms * channels; ++term) {
      std::vector<double> values;
      for (const auto& q : pedestals) values.push_back(q.coefficients[term]);
      track.terms.push_back(robustPolynomial(angles, values, std::min<int>(o.pedestal_degree, angles.size() - 1)));
    }
    m.pedestal = track;
  }
  sum.seconds_pedestal = since(t_pedestal);
  if (summary) *summary = sum;
  return m;
}

}  // namespace flarekit::fit
