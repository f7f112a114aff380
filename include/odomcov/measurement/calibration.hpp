// Calibration from measured runs: the maximum-likelihood fit of model parameters ([Chong97]
// §5.2 done properly) and Borenstein & Feng's UMBmark ([Borenstein96]; [Chong97] eqs. 5-12).
#pragma once

#include <Eigen/Core>

#include <atomic>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "odomcov/measurement/likelihood.hpp"

namespace odomcov {

/// A robot parameter a fit can move ("k_left", "k_right", "wheelbase"): where it lives and its
/// coordinate (src/effects/candidates.cpp, beside the effects' own parameters).
struct RobotParameter {
  std::string name;
  double& (*ref)(Robot& robot);
  FitCoordinate (*coordinate)(const Robot& robot);
};
const std::vector<RobotParameter>& robot_parameters();

/// Names a fit can take: "k_left", "k_right", "wheelbase" (the nominal one, which the odometry
/// uses) and "<effect>.<parameter>" for any catalogue effect. An effect not yet in the model is
/// added, starting from its typical size. Returns "" or what is wrong.
/// `context`: the model's effects, whose custom effects' parameters may also be fitted.
std::string check_fit_parameter(const std::string& name, const EffectList& context = {});

/// What a fit maximises: the full Gaussian likelihood, or its scatter part only
/// (scatter_log_likelihood), for parameters that act on the covariance alone.
enum class Likelihood { full, scatter };

/// How a fit evaluates the likelihood.
///  * `fast` (the default): linearise, optimise, re-anchor. At an anchor (the start, then each
///    accepted point) every run's residual and covariance are computed exactly, and so are they
///    at a few finite-difference points around it; from these each run's residual and covariance
///    become a quadratic in the fitted values (per-parameter slope and curvature, and the
///    pairwise cross terms), so a likelihood evaluation costs O(runs) instead of a propagation
///    of every log. The optimum of that surrogate is evaluated exactly and becomes the next
///    anchor when it raises the exact log-likelihood (else the step is halved); the loop ends
///    when the exact log-likelihood stops improving (gain below kFitTolerance) or when the
///    surrogate foretold the exact log-likelihood at its optimum to within kFitTolerance (a
///    re-anchor could then gain no more than that: ~sqrt(2 kFitTolerance) = 0.045 standard
///    errors in the parameters). At a fixed point
///    the surrogate's gradient is the exact model's, so the answer is the exact model's optimum.
///    Standard errors come from the last surrogate's derivatives.
///  * `exact`: every likelihood evaluation propagates every run (the reference; slow).
enum class FitPath { fast, exact };

/// The fast path's tolerance in log-likelihood (see FitPath).
inline constexpr double kFitTolerance = 1e-3;

/// Exact residuals of one suite by model, each computed once: the fast path's anchors and
/// difference points. Shared by fits from the same model (diagnose's candidates), so a
/// parameter's sensitivity is propagated once per round. Effects whose values are all neutral
/// do nothing and are left out of the key. Not thread-safe.
class ResidualCache {
 public:
  explicit ResidualCache(const Suite& suite) : suite_(&suite) {}
  /// The residuals of `model`, computed on the first request (then `counter` is incremented).
  const std::vector<std::vector<RunResidual>>& at(const SuiteModel& model,
                                                  std::atomic<std::int64_t>* counter = nullptr);
  /// How many propagations of the whole suite the cache has run.
  std::int64_t computed() const { return computed_; }

 private:
  const Suite* suite_;
  std::map<std::string, std::vector<std::vector<RunResidual>>> by_model_;
  std::int64_t computed_ = 0;
};

struct FitResult {
  std::vector<std::string> names;
  Eigen::VectorXd values;
  Eigen::VectorXd stderrs;  // NaN where not identifiable or at a bound
  Eigen::MatrixXd covariance;  // of the estimates, from the observed information
  /// Sandwich (Huber-White) standard errors, H^-1 J H^-1 with J the sum of the runs' score
  /// outer products: valid when the errors are not Gaussian (bumps), where the observed
  /// information understates the uncertainty of a variance.
  Eigen::VectorXd robust_stderrs;
  double log_likelihood_before = 0.0;  // the starting model (added effects at neutral)
  double log_likelihood_after = 0.0;   // of the kind maximised
  int evaluations = 0;  // exact likelihood evaluations (propagations of every run)
  int anchors = 0;      // fast path: the points it linearised at
  std::vector<std::string> warnings;
  SuiteModel model;  // the fitted model
};

/// Maximises the suite's Gaussian log-likelihood over the named parameters with NLopt's
/// BOBYQA (bounded, derivative-free), each parameter in a transformed coordinate in which it is
/// unbounded or simply bounded (log for positive scales, atanh for a correlation, square root
/// for variance-like sizes that may be 0). Standard errors come from the observed information:
/// the inverse of the numerical Hessian of -log L at the optimum, by central differences with
/// steps set to a fifth of a first estimate of each standard error; and robust ones from the
/// sandwich with the runs' numerical scores.
/// `evaluations`, when given, is incremented at every likelihood evaluation (for a progress
/// display; the library itself prints nothing).
/// `path` chooses the fast (linearised, re-anchored) or the exact evaluation (see FitPath);
/// `cache`, when given, must belong to `suite` and is shared with other fast fits. On the fast
/// path an effect named but absent joins at its typical size unless `cache` is given: then its
/// fitted parameters start at their neutral values (the effect does nothing, so the start is
/// the model the cache's sensitivities were taken around) and the others at their typical ones.
/// `evaluations` counts the propagations of the whole suite (the exact likelihood evaluations).
FitResult fit(const Suite& suite, const SuiteModel& start, const std::vector<std::string>& names,
              Likelihood likelihood = Likelihood::full,
              std::atomic<std::int64_t>* evaluations = nullptr, FitPath path = FitPath::fast,
              ResidualCache* cache = nullptr);

struct UmbmarkResult {
  double side_m = 0.0;
  Eigen::Vector2d cg_cw = Eigen::Vector2d::Zero();   // centres of gravity of the x-y errors
  Eigen::Vector2d cg_ccw = Eigen::Vector2d::Zero();
  Eigen::Vector2d cg_cw_after = Eigen::Vector2d::Zero();
  Eigen::Vector2d cg_ccw_after = Eigen::Vector2d::Zero();
  double alpha = 0.0;  // rad, turning error per 90 deg turn: > 0 when the robot under-turns
  double beta = 0.0;   // rad, heading change over one straight side: > 0 when it curves left
  double Ed = 1.0, Eb = 1.0;
  double c_left = 1.0, c_right = 1.0;
  double wheelbase_corrected = 0.0;
  double emax_before = 0.0, emax_after = 0.0;
  std::int64_t runs_cw = 0, runs_ccw = 0;
  // The maximum-likelihood cross-check on the same runs (fit of Ed and Eb, full model) and the
  // Emax,sys left after re-integrating with its corrections.
  double ml_Ed = 1.0, ml_Eb = 1.0, ml_Ed_stderr = 0.0, ml_Eb_stderr = 0.0;
  double ml_emax_after = 0.0;
};

/// UMBmark from the CW and CCW square runs (each a comma-separated list of experiment names):
///   alpha = mean((x_cw + x_ccw)/(-4L), (y_cw - y_ccw)/(-4L))
///   beta  = mean((x_cw - x_ccw)/(-4L), (y_cw + y_ccw)/(-4L))
///   R = (L/2)/sin(beta/2),  Ed = (R + b/2)/(R - b/2),  Eb = (pi/2)/(pi/2 - alpha),
///   c_L = 2/(Ed + 1), c_R = 2/(1/Ed + 1), b_new = Eb b,  Emax = max(|cg_cw|, |cg_ccw|).
/// Errors are true - odometry in the start frame (x along the initial heading, y to its left),
/// the convention of [Borenstein96]. "After" re-integrates each run's encoder travel with the
/// corrections. The side L is the planned paths' line length unless given; logged runs must
/// give it (their turns need not be on the spot, so the travel does not tell it). The result
/// includes the maximum-likelihood cross-check.
UmbmarkResult umbmark(const Suite& suite, const std::string& cw, const std::string& ccw,
                      std::optional<double> side_m);


}  // namespace odomcov
