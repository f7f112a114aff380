// Calibration from measured runs: the maximum-likelihood fit of model parameters ([Chong97]
// §5.2 done properly) and Borenstein & Feng's UMBmark ([Borenstein96]; [Chong97] eqs. 5-12).
#pragma once

#include <Eigen/Core>

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "odomcov/measurement/comparison.hpp"
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
///
/// A *view* of a cache holds only some experiments of its suite (a cross-validation fold's
/// training runs): its residuals are the parent's restricted to them, so a fit on the view
/// maximises the likelihood of those runs alone, while every model is still propagated once,
/// for the whole suite, in the store the parent and its views share (the held-out runs'
/// predictions come with it).
class ResidualCache {
 public:
  explicit ResidualCache(const Suite& suite);
  /// A view of `parent` (or of the parent's own suite) keeping the experiments `keep` marks
  /// (one flag per experiment of the suite).
  ResidualCache(ResidualCache& parent, std::vector<bool> keep);
  /// The residuals of `model`, computed on the first request (then `counter` is incremented):
  /// of every experiment, or of the view's. The shared store keeps each model's residuals
  /// experiment by experiment and propagates only those no request has computed yet.
  const std::vector<std::vector<RunResidual>>& at(const SuiteModel& model,
                                                  std::atomic<std::int64_t>* counter = nullptr);
  /// The residuals of every experiment of the suite, whatever the view.
  const std::vector<std::vector<RunResidual>>& full(const SuiteModel& model,
                                                    std::atomic<std::int64_t>* counter = nullptr);
  /// The residuals of `model` (of the view's experiments) computed now and not kept: for
  /// evaluations that are not used again (an exact optimiser's).
  std::vector<std::vector<RunResidual>> evaluate(const SuiteModel& model);
  /// compare of `model` against every experiment of the suite, computed on the first request
  /// with these options and kept: a verdict that several steps read (a round's model after, the
  /// next round's model before, calibrate's final account) is calibrated by its referee once.
  /// The referee is seeded (options.seed), so a kept verdict is the one a new compare would give.
  /// The model's training domain is part of the key: the verdict names what lies outside it.
  const Comparison& comparison(const SuiteModel& model, double alpha, const CalibrationOptions& options);
  /// Forgets what was not read since the previous call (for a cache that outlives a round:
  /// what the next round can reuse is what this one read, so memory stays that of two rounds).
  void age();
  /// How many propagations the shared store has run (each of the experiments a request was
  /// missing: the whole suite, or a view's part of it).
  std::int64_t computed() const;
  const Suite& suite() const;

 private:
  struct Store;
  std::shared_ptr<Store> store_;
  std::vector<bool> keep_;  // empty: every experiment
  std::map<std::string, std::vector<std::vector<RunResidual>>> subsets_;
};

/// The residuals of the experiments `keep` marks, in order.
std::vector<std::vector<RunResidual>> select_experiments(
    const std::vector<std::vector<RunResidual>>& residuals, const std::vector<bool>& keep);

/// The value of a fitted parameter in a model, by its fit name: a robot parameter ("k_left")
/// or an effect's ("wheelbase_error.Eb"). Throws std::invalid_argument when the model lacks it.
double& fitted_parameter(SuiteModel& model, const std::string& name);

/// The description (range, neutral value) of an effect's fitted parameter in a model, by its
/// fit name ("wheelbase_error.Eb"); nullptr for a robot parameter or one the model lacks.
const EffectParameterInfo* effect_parameter_info(const SuiteModel& model, const std::string& name);

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
  /// Fast path: true when the exact log-likelihood confirmed the surrogate at the end (its
  /// optimum foretold to within kFitTolerance, or no gain left from a fresh anchor), which makes
  /// the answer the exact model's optimum; false when the surrogate mispredicted and steps had
  /// to be cut (a strongly nonlinear parameter), or the anchors ran out. The exact path: true.
  bool verified = true;
  /// The fitted parameters that ended at a bound of their range that is not their neutral value
  /// (within half a standard error of it, or exactly there when the information is singular):
  /// the data pushed them to the edge of what the fit allows, e.g. Eb_arc = 0.5.
  std::vector<std::string> at_bound;
  std::vector<std::string> warnings;
  SuiteModel model;  // the fitted model
  /// How many directions of the parameters the data determine: the numerical rank of the
  /// observed information scaled to unit diagonal (eigenvalues above kInformationRankTolerance of
  /// the largest; a parameter with no information counts nothing). Below names.size() when some
  /// parameters act only together (a wheelbase and a spin wheelbase on runs that only spin) or
  /// not at all (an arc wheelbase without arcs): the residual degrees of freedom of a fit are the
  /// data's count less this, not less the names.
  int rank = 0;
};

/// FitResult::rank's tolerance: an eigenvalue of the unit-diagonal information below this
/// fraction of the largest is a direction the data do not determine (a correlation within 5e-7
/// of 1 between two parameters; a finite-difference Hessian resolves about 1e-8 of its scale).
inline constexpr double kInformationRankTolerance = 1e-6;

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

/// The exact decision on a fast fit: when `fast` is not verified (its surrogate mispredicted),
/// the parameters `own` (a candidate's own, the nonlinear ones) are refitted on the exact path
/// from its optimum, the others held, and when that raises the exact log-likelihood the fast
/// path runs again from there over every name (for the other parameters and the standard
/// errors at the new optimum). A verified fit comes back unchanged. `cache` is the one the fast
/// fit used (a view for a fold's fit).
FitResult refit_exactly(const FitResult& fast, const std::vector<std::string>& own,
                        Likelihood likelihood, std::atomic<std::int64_t>* evaluations,
                        ResidualCache& cache);
/// The same, also from `start` (a user's candidate at its given values): a strongly nonlinear
/// expression (a time constant) can leave the fast path in another basin of the exact
/// likelihood, from whose optimum no local exact step escapes. `own` is refitted exactly from
/// both points, and the better optimum stands (then the fast path over every name, as above).
FitResult refit_exactly_from_both(const FitResult& fast, const SuiteModel& start, const std::vector<std::string>& own,
                                  Likelihood likelihood, std::atomic<std::int64_t>* evaluations, ResidualCache& cache);

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
