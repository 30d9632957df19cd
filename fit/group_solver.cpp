#include "fit/group_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <mutex>

#include <ceres/ceres.h>
#include <glog/logging.h>

#include "common/error.h"
#include "common/log.h"
#include "fit/normal_equations.h"

namespace flarekit::fit {

std::string optimizerName(Optimizer optimizer) {
  return optimizer == Optimizer::kCeres ? "ceres" : "walch-gd";
}

Optimizer parseOptimizer(const std::string& name) {
  if (name == "ceres") return Optimizer::kCeres;
  if (name == "walch-gd") return Optimizer::kWalchGd;
  throw InputError("unknown optimizer \"" + name + "\" (use ceres or walch-gd)");
}

bool SolverOptions::IsValid(std::string* error) const {
  auto fail = [&](const char* m) {
    if (error) *error = m;
    return false;
  };
  if (max_iterations < 1) return fail("max_iterations must be ≥ 1");
  if (!(function_tolerance > 0)) return fail("function_tolerance must be > 0");
  if (!(parameter_tolerance > 0)) return fail("parameter_tolerance must be > 0");
  if (gd_max_iterations < 1) return fail("gd_max_iterations must be ≥ 1");
  if (!(gd_learning_rate > 0)) return fail("gd_learning_rate must be > 0");
  if (!(gd_decay > 0 && gd_decay <= 1)) return fail("gd_decay must be in (0, 1]");
  if (gd_decay_every < 1) return fail("gd_decay_every must be ≥ 1");
  if (gd_patience < 1) return fail("gd_patience must be ≥ 1");
  return true;
}

double parameterStep(int index, int channels, double scale) {
  using namespace model::param;
  const model::ParameterLayout layout{channels};
  if (index <= kH) return 0.5;
  if (index <= kCr) return 0.02;
  if (index < layout.fi()) return 0.02 * scale;
  if (index == layout.fi() || index == layout.fo()) return 0.5;
  return 0.05;
}

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Each seed's fit bounds (fit/cost.h fitBounds), in the seeds' order.
using GroupBounds = std::vector<std::vector<model::ParameterBounds>>;
GroupBounds boundsOf(const GroupCost& cost, std::span<const model::GhostParameters> seeds) {
  return GroupBounds(seeds.size(), fitBounds(cost));
}

// The seeds as parameter blocks, within their bounds.
std::vector<std::vector<double>> clampedSeeds(std::span<const model::GhostParameters> seeds,
                                              const GroupBounds& bounds) {
  std::vector<std::vector<double>> blocks;
  for (size_t g = 0; g < seeds.size(); ++g) {
    auto v = model::toParameterVector(model::clampToBounds(seeds[g]));
    for (size_t k = 0; k < v.size(); ++k) v[k] = std::clamp(v[k], bounds[g][k].lower, bounds[g][k].upper);
    blocks.push_back(std::move(v));
  }
  return blocks;
}

// Renders once per evaluation point and fills the normal equations. A point the last rendering
// was made at is not rendered again, whatever Ceres says of it: with bounds, each
// Levenberg–Marquardt iteration of Ceres (2.1) runs a projected Armijo line search, whose accepted
// sample is then evaluated again as the candidate (bit for bit the same point: a step of 1 scales
// the step by 1.0), so that rendering is reused. The line search interpolates quadratically
// (solveCeres) and asks only for costs; derivatives are rendered once the step is taken, for its
// Jacobian.
class RenderCallback : public ceres::EvaluationCallback {
 public:
  RenderCallback(GroupCost& cost, NormalEquations& normal, std::vector<std::vector<double>>& blocks)
      : cost_(cost), normal_(normal), blocks_(blocks) {}
  void PrepareForEvaluation(bool evaluate_jacobians, bool new_evaluation_point) override {
    const bool have_derivatives = !evaluate_jacobians || cost_.hasJacobians();
    if (evaluated_ && have_derivatives && (!new_evaluation_point || sameBitsAsRendered())) return;
    std::vector<const double*> p;
    for (const auto& b : blocks_) p.push_back(b.data());
    cost_.prepare(p, evaluate_jacobians);
    normal_.fill(evaluate_jacobians);
    rendered_ = blocks_;
    evaluated_ = true;
  }

 private:
  // Bits, not ==: −0 and +0 are equal but need not render alike.
  bool sameBitsAsRendered() const {
    for (size_t g = 0; g < blocks_.size(); ++g)
      if (std::memcmp(blocks_[g].data(), rendered_[g].data(), blocks_[g].size() * sizeof(double)) != 0)
        return false;
    return true;
  }

  GroupCost& cost_;
  NormalEquations& normal_;
  std::vector<std::vector<double>>& blocks_;
  std::vector<std::vector<double>> rendered_;  // the parameters of the last rendering
  bool evaluated_ = false;
};

// The region's samples as the square-root form of their normal equations (normal_equations.h),
// as filled by the callback.
class SquareRootResidual : public ceres::CostFunction {
 public:
  SquareRootResidual(const GroupCost& cost, const NormalEquations& normal) : normal_(normal) {
    set_num_residuals(normal.squareRootRows());
    for (int g = 0; g < cost.ghostCount(); ++g)
      mutable_parameter_block_sizes()->push_back(cost.parametersPerGhost());
  }
  bool Evaluate(double const* const* /*parameters*/, double* residuals,
                double** jacobians) const override {
    normal_.squareRoot(residuals, jacobians);
    return true;
  }

 private:
  const NormalEquations& normal_;
};

// The shape prior of one ghost (fit/cost.h), an analytic block on that ghost's parameters.
class PriorResidual : public ceres::CostFunction {
 public:
  PriorResidual(const GroupCost& cost, int ghost) : cost_(cost), ghost_(ghost) {
    set_num_residuals(cost.priorResidualCount());
    mutable_parameter_block_sizes()->push_back(cost.parametersPerGhost());
  }
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
    cost_.priorResiduals(ghost_, parameters[0], residuals, jacobians ? jacobians[0] : nullptr);
    return true;
  }

 private:
  const GroupCost& cost_;
  int ghost_;
};

class TraceCallback : public ceres::IterationCallback {
 public:
  TraceCallback(const GroupCost& cost, Clock::time_point t0, std::vector<TracePoint>& trace)
      : cost_(cost), t0_(t0), trace_(trace) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    if (s.step_is_successful || s.iteration == 0)
      trace_.push_back({since(t0_), cost_.evaluations(), s.cost});
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const GroupCost& cost_;
  Clock::time_point t0_;
  std::vector<TracePoint>& trace_;
};

// Ceres's function tolerance ends a solve on any candidate whose cost is within the tolerance of
// the current one, rejected and line-searched ones included, so a step that the projection onto
// the bounds and the line search cut to almost nothing ends a solve mid-descent, and whether such
// a candidate comes up depends on the rounding. The tolerance is therefore MINPACK's (lmder's
// ftol, Moré 1978): the solve has converged when both the actual and the predicted decrease are
// within it, and the actual is no more than twice the predicted; a step whose model promised much
// and gave nothing shrinks the trust region instead.
class RelativeReductionTolerance : public ceres::IterationCallback {
 public:
  explicit RelativeReductionTolerance(double function_tolerance) : tolerance_(function_tolerance) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& s) override {
    // Accepted or not, s.cost + s.cost_change is the cost before the step, and the step quality
    // s.relative_decrease its actual over its predicted decrease.
    if (s.iteration == 0 || !s.step_is_valid || s.relative_decrease == 0) return ceres::SOLVER_CONTINUE;
    const double before = s.cost + s.cost_change;
    const double predicted = s.cost_change / s.relative_decrease;
    const bool converged = std::abs(s.cost_change) <= tolerance_ * before &&
                           std::abs(predicted) <= tolerance_ * before && s.relative_decrease <= 2;
    return converged ? ceres::SOLVER_TERMINATE_SUCCESSFULLY : ceres::SOLVER_CONTINUE;
  }

 private:
  double tolerance_;
};

GroupFitResult solveCeres(GroupCost& cost, std::span<const model::GhostParameters> seeds,
                          const SolverOptions& options) {
  routeSolverLogging();
  const auto t0 = Clock::now();
  const long long evaluations0 = cost.evaluations();
  GroupFitResult result;
  const GroupBounds bounds = boundsOf(cost, seeds);
  auto blocks = clampedSeeds(seeds, bounds);
  const int channels = cost.channels();
  if (cost.samples().empty()) {
    for (const auto& b : blocks) result.ghosts.push_back(model::fromParameterVector(b, channels));
    result.termination = "no valid pixels";
    return result;
  }
  NormalEquations normal(cost);
  RenderCallback render(cost, normal, blocks);
  ceres::Problem::Options problem_options;
  problem_options.evaluation_callback = &render;
  ceres::Problem problem(problem_options);
  std::vector<double*> pointers;
  for (auto& b : blocks) pointers.push_back(b.data());
  // The samples' rows as their normal equations' square root, the loss per pixel inside them
  // (GroupCost::robustSample; per-pixel Cauchy is robust against
  // unmodelled blobs): the steps of blocks of one pixel each, without Ceres's bookkeeping per
  // block, and the products formed on every thread.
  problem.AddResidualBlock(new SquareRootResidual(cost, normal), nullptr, pointers);
  if (cost.priorResidualCount() > 0)
    for (size_t g = 0; g < blocks.size(); ++g)
      problem.AddResidualBlock(new PriorResidual(cost, static_cast<int>(g)), nullptr, pointers[g]);
  // On its bounds Ceres projects each step onto the box; where a parameter sits on its bound and
  // the step points out, the projection can go nowhere, and the solve may end at its seed by the
  // parameter tolerance (describeCeresEnd in fit/optimizer_bench.h tells such a stall).
  for (size_t g = 0; g < blocks.size(); ++g) {
    if (!options.held_parameters.empty())
      problem.SetManifold(pointers[g], new ceres::SubsetManifold(static_cast<int>(blocks[g].size()),
                                                                 options.held_parameters));
    for (size_t k = 0; k < blocks[g].size(); ++k) {
      problem.SetParameterLowerBound(pointers[g], static_cast<int>(k), bounds[g][k].lower);
      if (bounds[g][k].upper < model::kUnbounded)
        problem.SetParameterUpperBound(pointers[g], static_cast<int>(k), bounds[g][k].upper);
    }
  }
  ceres::Solver::Options so;
  so.minimizer_type = ceres::TRUST_REGION;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  // The normal equations JᵀJ by Cholesky rather than J by QR: Ceres's linear algebra runs on one
  // thread (see the header), so it is the serial part of a solve, and Cholesky is the cheaper of
  // the two.
  so.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  // Ceres's projected line search along each step (used with bounds) interpolates quadratically:
  // from the cost and slope at the start and the cost at the trial point. Its default, cubic, also
  // asks for the gradient at every trial point, so every trial would render all the derivative
  // images and form JᵀJ; this way a trial costs a plain render, and derivatives are rendered where
  // a step is taken. The line search itself stays: without it, projected steps stall on bounds.
  so.line_search_interpolation_type = ceres::QUADRATIC;
  so.max_num_iterations = options.max_iterations;
  // Only a candidate of exactly the current cost ends the solve in Ceres; the tolerance is
  // RelativeReductionTolerance's.
  so.function_tolerance = 0;
  so.parameter_tolerance = options.parameter_tolerance;
  so.num_threads = 1;  // the fit must not depend on the thread count (see the header)
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  std::unique_ptr<TraceCallback> trace;
  if (options.record_trace) {
    trace = std::make_unique<TraceCallback>(cost, t0, result.trace);
    so.callbacks.push_back(trace.get());
    so.update_state_every_iteration = true;
  }
  RelativeReductionTolerance relative_reduction_tolerance(options.function_tolerance);
  so.callbacks.push_back(&relative_reduction_tolerance);  // after the trace, which records the step
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  for (const auto& b : blocks) result.ghosts.push_back(model::fromParameterVector(b, channels));
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  result.iterations = static_cast<int>(summary.iterations.size());
  result.evaluations = cost.evaluations() - evaluations0;
  result.seconds = since(t0);
  result.termination = summary.termination_type == ceres::USER_SUCCESS
                           ? "CONVERGENCE"  // RelativeReductionTolerance
                           : ceres::TerminationTypeToString(summary.termination_type);
  if (!summary.IsSolutionUsable()) result.termination += ": " + summary.message;
  return result;
}

GroupFitResult solveWalchGd(GroupCost& cost, std::span<const model::GhostParameters> seeds,
                            const SolverOptions& options) {
  const auto t0 = Clock::now();
  const long long evaluations0 = cost.evaluations();
  GroupFitResult result;
  const GroupBounds bounds = boundsOf(cost, seeds);
  auto blocks = clampedSeeds(seeds, bounds);
  const int channels = cost.channels();
  const int n = cost.parametersPerGhost();
  auto evaluate = [&] {
    std::vector<const double*> p;
    for (const auto& b : blocks) p.push_back(b.data());
    return cost.evaluate(p, false);
  };
  double current = evaluate();
  result.initial_cost = current;
  if (options.record_trace) result.trace.push_back({since(t0), cost.evaluations() - evaluations0, current});
  double learning_rate = options.gd_learning_rate;
  int since_improvement = 0;
  int iteration = 0;
  result.termination = "max iterations";
  for (; iteration < options.gd_max_iterations; ++iteration) {
    // §3.3.2: "the learning rate is reduced after every 100 iterations by 20 %".
    if (iteration > 0 && iteration % options.gd_decay_every == 0) learning_rate *= options.gd_decay;
    bool improved = false;
    // Fixed order, shape before shade: parameter index order is shape (Mx..Cr) then intensity.
    for (size_t g = 0; g < blocks.size(); ++g) {
      for (int k = 0; k < n; ++k) {
        if (std::find(options.held_parameters.begin(), options.held_parameters.end(), k) !=
            options.held_parameters.end())
          continue;
        const model::ParameterBounds& b = bounds[g][k];
        const double h = learning_rate * parameterStep(k, channels, cost.scale());
        const double q = blocks[g][k];
        const double plus = std::min(q + h, b.upper), minus = std::max(q - h, b.lower);
        blocks[g][k] = plus;
        const double c_plus = evaluate();
        blocks[g][k] = minus;
        const double c_minus = evaluate();
        // The central difference says which way the cost falls; the online update takes that
        // step at once when it lowers the cost (the next parameter sees the new value).
        const double gradient = (c_plus - c_minus) / std::max(plus - minus, 1e-300);
        const double candidate = gradient > 0 ? minus : plus;
        const double c_candidate = gradient > 0 ? c_minus : c_plus;
        if (c_candidate < current) {
          blocks[g][k] = candidate;
          current = c_candidate;
          improved = true;
        } else {
          blocks[g][k] = q;
        }
      }
    }
    if (options.record_trace)
      result.trace.push_back({since(t0), cost.evaluations() - evaluations0, current});
    since_improvement = improved ? 0 : since_improvement + 1;
    if (since_improvement >= options.gd_patience) {
      result.termination = "no progress";
      ++iteration;
      break;
    }
  }
  evaluate();  // leave the cost's images at the result
  for (const auto& b : blocks) result.ghosts.push_back(model::fromParameterVector(b, channels));
  result.final_cost = current;
  result.iterations = iteration;
  result.evaluations = cost.evaluations() - evaluations0;
  result.seconds = since(t0);
  return result;
}

class WholeGroupCost : public ceres::CostFunction {
 public:
  explicit WholeGroupCost(GroupCost& cost) : cost_(cost) {
    set_num_residuals(static_cast<int>(cost.samples().size()) * cost.residualsPerSample() +
                      cost.ghostCount() * cost.priorResidualCount());
    for (int g = 0; g < cost.ghostCount(); ++g)
      mutable_parameter_block_sizes()->push_back(cost.parametersPerGhost());
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    std::vector<const double*> p(parameters, parameters + cost_.ghostCount());
    cost_.prepare(p, jacobians != nullptr);
    const int m = cost_.residualsPerSample(), n = cost_.parametersPerGhost();
    std::vector<double> row(static_cast<size_t>(m) * n);
    for (size_t i = 0; i < cost_.samples().size(); ++i) {
      cost_.sampleResiduals(static_cast<int>(i), residuals + i * m);
      if (jacobians == nullptr) continue;
      for (int g = 0; g < cost_.ghostCount(); ++g) {
        if (jacobians[g] == nullptr) continue;
        cost_.sampleJacobian(static_cast<int>(i), g, jacobians[g] + i * m * n);
      }
    }
    // The shape prior's residuals after the pixels', each depending on its own ghost only.
    const size_t pixels = cost_.samples().size() * m;
    const int q = cost_.priorResidualCount();
    std::vector<double> prior_jacobian(static_cast<size_t>(q) * n);
    for (int g = 0; g < cost_.ghostCount(); ++g) {
      const size_t first = pixels + static_cast<size_t>(g) * q;
      cost_.priorResiduals(g, parameters[g], residuals + first, prior_jacobian.data());
      if (jacobians == nullptr) continue;
      for (int h = 0; h < cost_.ghostCount(); ++h) {
        if (jacobians[h] == nullptr) continue;
        double* rows = jacobians[h] + first * n;
        if (h == g) std::copy(prior_jacobian.begin(), prior_jacobian.end(), rows);
        else std::fill(rows, rows + static_cast<size_t>(q) * n, 0.0);
      }
    }
    return true;
  }

 private:
  GroupCost& cost_;
};

// Ceres's glog messages, to common/log (see routeSolverLogging).
class GlogToLog : public google::LogSink {
 public:
  void send(google::LogSeverity severity, const char* /*full_filename*/, const char* base_filename,
            int line, const google::LogMessageTime& /*time*/, const char* message,
            size_t message_len) override {
    const std::string text = std::string("Ceres (") + base_filename + ":" + std::to_string(line) +
                             "): " + std::string(message, message_len);
    if (severity >= google::GLOG_ERROR)
      logWarning(text);
    else
      logDebug(text);
  }
};
}  // namespace

void routeSolverLogging() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (google::IsGoogleLoggingInitialized()) return;
    google::InitGoogleLogging("flarekit");
    // No log files (glog writes them to /tmp once initialised), nothing on stderr short of a
    // fatal error (which aborts): the sink has every message.
    for (google::LogSeverity s = google::GLOG_INFO; s <= google::GLOG_FATAL; ++s)
      google::SetLogDestination(s, "");
    FLAGS_logtostderr = false;
    FLAGS_alsologtostderr = false;
    google::SetStderrLogging(google::GLOG_FATAL);
    static GlogToLog sink;
    google::AddLogSink(&sink);
  });
}

std::unique_ptr<ceres::CostFunction> makeGroupCostFunction(GroupCost& cost) {
  return std::make_unique<WholeGroupCost>(cost);
}

GroupFitResult solveGroup(GroupCost& cost, std::span<const model::GhostParameters> seeds,
                          const SolverOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("SolverOptions: " + error);
  return options.optimizer == Optimizer::kCeres ? solveCeres(cost, seeds, options)
                                                : solveWalchGd(cost, seeds, options);
}

}  // namespace flarekit::fit
