#pragma once
// Fits the parameters of a group of overlapping ghosts in one frame by minimising a GroupCost
// (fit/cost.h), with either optimizer:
//
//  - kCeres (default): Ceres's Levenberg–Marquardt trust region with the parameters' bounds,
//    Cauchy's loss per pixel (GroupCost::robustSample weights each pixel
//    as Ceres's own loss would), analytic Jacobians from model/'s derivative images (the edge part
//    is E applied to them), a dense Cholesky solve of the normal equations. The model is rendered
//    once per evaluation point through a ceres::EvaluationCallback, and the pixels' normal
//    equations formed tile by tile on every thread (TBB); Ceres sees them as one residual block of
//    their square root (fit/normal_equations.h), which gives it the steps, gradient and cost of one
//    block per pixel. Ceres itself runs on one thread: it sums its blocks' costs per thread, so
//    with more threads the cost's rounding, the steps it accepts and so the whole capture's fit
//    would depend on the machine's thread count.
//  - kWalchGd: the paper's optimizer (Walch et al. 2018 §3.3.2) as the baseline: gradient descent
//    with central-difference gradients, one step size per parameter, a global learning rate
//    multiplied by 0.8 every 100 iterations, online updates in a fixed order, shape before shade.

#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fit/cost.h"
#include "model/ghost_shape.h"

namespace ceres {
class CostFunction;
}

namespace flarekit::fit {

enum class Optimizer {
  kCeres,    // Levenberg–Marquardt (Ceres)
  kWalchGd,  // Walch 2018 §3.3.2 gradient descent
};
// "ceres" / "walch-gd"; parseOptimizer throws InputError for other names.
std::string optimizerName(Optimizer optimizer);
Optimizer parseOptimizer(const std::string& name);

struct SolverOptions {
  Optimizer optimizer = Optimizer::kCeres;
  // Ceres: maximum Levenberg–Marquardt iterations per group and frame (≥ 1).
  int max_iterations = 15;
  // Ceres: stop when a step's actual and predicted decrease are both below this fraction of the
  // cost (MINPACK's ftol) (> 0).
  double function_tolerance = 1e-5;
  // Ceres: stop when the relative parameter change of a step is below this (> 0).
  double parameter_tolerance = 1e-7;
  // Walch GD: iterations (one iteration updates every parameter once) (≥ 1).
  int gd_max_iterations = 400;
  // Walch GD: initial learning rate (> 0), multiplied by gd_decay every gd_decay_every iterations
  // (the paper: 0.8 every 100).
  double gd_learning_rate = 1.0;
  double gd_decay = 0.8;
  int gd_decay_every = 100;
  // Walch GD: stop early after this many iterations in a row without any improvement (≥ 1).
  int gd_patience = 150;
  // Record (time, evaluations, cost) after every iteration (for benchmarks).
  bool record_trace = false;
  // Indices (ghost_shape.h order) of parameters held at their seeds, e.g. My on the horizon.
  std::vector<int> held_parameters;

  bool IsValid(std::string* error) const;
};

struct TracePoint {
  double seconds = 0;        // since the start of the solve
  long long evaluations = 0; // cost evaluations so far
  double cost = 0;
};

struct GroupFitResult {
  std::vector<model::GhostParameters> ghosts;
  double initial_cost = 0;
  double final_cost = 0;
  int iterations = 0;
  long long evaluations = 0;  // cost evaluations (each renders the model once)
  double seconds = 0;
  std::string termination;    // Ceres's termination type, or "max iterations" / "no progress"
  std::vector<TracePoint> trace;  // when record_trace
};

// Minimises `cost` starting at `seeds` (one per ghost of the cost's group, same channel count).
// Seeds are clamped into the fit bounds (fit/cost.h fitBounds) first.
GroupFitResult solveGroup(GroupCost& cost, std::span<const model::GhostParameters> seeds,
                          const SolverOptions& options);

// Sends the messages Ceres logs (through glog) to FlareKit's log (common/log.h): glog's warnings
// and below at debug level, its errors as warnings. Without it glog writes every message to stderr
// past --quiet, such as Levenberg–Marquardt's "Linear solver failure ... dense Cholesky
// factorization", after which Ceres raises its damping and goes on. solveGroup calls it before each
// Ceres solve; calling it again does nothing. A program that initialised glog itself keeps its own
// setup.
void routeSolverLogging();

// The whole group cost as one ceres::CostFunction of the ghosts' parameter blocks (one block per
// ghost, parametersPerGhost() each; residuals: samples × residualsPerSample()), evaluating the
// cost itself at the parameters it is given, without a loss. Slower than solveGroup's normal
// equations; for ceres::GradientChecker and tests. `cost` must outlive the function.
std::unique_ptr<ceres::CostFunction> makeGroupCostFunction(GroupCost& cost);

// The step size of parameter `index` for the GD baseline and for finite-difference checks:
// lengths 0.5 px, curvatures 0.02, intensities 2 % of the region scale, exponents 0.05.
double parameterStep(int index, int channels, double scale);

}  // namespace flarekit::fit
