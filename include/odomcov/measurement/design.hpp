// What the experiments determine and what to record next: the pairs of fitted parameters the
// suite does not separate (their estimates correlate), and a menu of standard experiments
// ranked by the information each would add to the current model's (D-optimality), with the
// standard errors to expect after it.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/measurement/calibration.hpp"

namespace odomcov {

/// Estimates whose correlation exceeds this in magnitude are reported as confounded: at 0.9
/// the standard error of either, given the other, is sqrt(1 - 0.81) = 0.44 of its own, so
/// most of what the data say about one is said about the pair.
inline constexpr double kConfoundedCorrelation = 0.9;

struct ConfoundedPair {
  std::string a, b;
  double correlation = 0.0;
};

/// The pairs of parameters whose estimates correlate beyond kConfoundedCorrelation, from the
/// estimates' covariance (a fit's, or the inverse of fisher_information), most correlated first.
std::vector<ConfoundedPair> confounded_pairs(const std::vector<std::string>& names,
                                             const Eigen::MatrixXd& covariance);

/// The covariance of a fit's estimates for confounded_pairs: the fit's own (observed
/// information) when it has one, else the inverse of the expected information at its model
/// with a relative ridge of 1e-9 (a singular information: parameters the suite cannot tell
/// apart at all, correlation +-1).
Eigen::MatrixXd estimate_covariance(const Suite& suite, const FitResult& fit);

/// In words: "these experiments do not separate scale_error.Es from
/// turn_dependent_wheelbase.Eb_arc (correlation 0.97): ...".
std::string confounded_text(const ConfoundedPair& pair);

/// One experiment a lab could record next.
struct MenuExperiment {
  std::string name;       // e.g. "line-10m-0.3mps"
  Path path;
  std::string path_yaml;  // the suite's path block, one line, e.g. "{sample_rate: 50, speed: 0.3, segments: [{line: 10}]}"
  std::int64_t runs = 0;
};

/// The standard menu for a suite: lines of 2, 5 and 10 m, a 3 m forward-back line, spins of
/// +360, -360 and +1080 deg, arcs of radius 0.5, 1 and 2 m to the left and to the right (180
/// deg), and UMBmark squares of 1 m driven CW and CCW; each at the suite's speed (the median
/// of its runs' mean wheel speed; each distinct planned speed when there are at most three),
/// at half the slowest and at twice the fastest; sampled at the suite's rate (its planned
/// paths', else its logs' median); each with the median number of runs of the suite's
/// experiments (at least 5).
std::vector<MenuExperiment> experiment_menu(const Suite& suite);

/// A menu experiment with what it would bring.
struct NextExperiment {
  MenuExperiment experiment;
  /// 1/2 ln det(I + I_e) - 1/2 ln det(I) [nats]: the D-optimality gain, with I the current
  /// information about the fitted parameters and I_e the experiment's.
  double information_gain = 0.0;
  /// The standard errors to expect after it, sqrt(diag((I + I_e)^-1)), by parameter name.
  std::vector<std::pair<std::string, double>> expected_stderr;
};

/// The Fisher information of the fitted parameters `names` at `model`: of the runs of `suite`
/// (runs of one group jointly: blockdiag(cov) + U U^T with group_variation's columns), or of a
/// menu experiment of n runs as a new group. Central differences of the predicted means,
/// covariances and group columns; Gaussian, I_kl = dmu_k' S^-1 dmu_l + tr(S^-1 dS_k S^-1 dS_l)/2.
Eigen::MatrixXd fisher_information(const Suite& suite, const SuiteModel& model,
                                   const std::vector<std::string>& names);

/// An absent effect's parameter counts as sized by the training runs when its posterior standard
/// deviation is at most this fraction of its prior's (the runs cut its variance at least
/// fourfold); beyond it, what a prediction carries of the parameter is mostly the prior.
inline constexpr double kSizedPosteriorRatio = 0.5;

/// What the training runs leave unknown about the mean a model predicts: the posterior covariance
/// of the model's fitted parameters and of the parameters of every systematic catalogue effect the
/// model does not have (each at its neutral value, so the model's predictions do not change; not
/// one that an effect of the model contains, whose parameters the model's span), from the
/// training runs' Fisher information. The fitted parameters have no prior; an absent effect's
/// parameter has a normal prior at its neutral value with its catalogue typical size as the
/// standard deviation (EffectParameterInfo::typical - neutral: Es 0.005, a reference offset
/// 10 mm, ...), so a parameter the training runs do not size keeps about its prior, and one they
/// size gets their standard error:
///   covariance = (I_train + diag(1 / prior_sd^2))^-1.
/// `covariance_sized` is the same given that every unsized parameter is at its neutral value (the
/// conditional covariance; their rows and columns zero): the uncertainty the training runs
/// themselves leave, whatever the priors of what they could not see.
struct TrainingUncertainty {
  SuiteModel model;                // the model with every absent effect added at its neutral values
  std::vector<std::string> names;  // the fitted parameters, then the absent effects'
  std::vector<double> prior_sd;    // 0 for a fitted parameter (no prior)
  std::vector<bool> sized;         // fitted, or posterior sd <= kSizedPosteriorRatio x prior sd
  Eigen::MatrixXd covariance, covariance_sized;
  /// The posterior means less the model's values (one Newton step of the log-posterior from the
  /// model, covariance x the training log-likelihood's gradient there): where the training runs
  /// put the parameters that the model fixed (an absent effect is at neutral in the model, not
  /// in the runs). `shift_sized` with the unsized ones at neutral.
  Eigen::VectorXd shift, shift_sized;
};

/// training_uncertainty of `fitted` (parameter names of `model`, e.g. the joint fit's) on the
/// runs of `training`.
TrainingUncertainty training_uncertainty(const Suite& training, const SuiteModel& model,
                                         const std::vector<std::string>& fitted);

/// A model's prediction of runs it was not fitted on, as it is and from the training runs'
/// posterior: each run's NEES against its marginal predicted mean and covariance C (the run's
/// own and its group's, no conditioning on other runs), and, to first order in the parameters,
/// against the posterior predictive: mean + J shift, C + J Sigma J^T, J the derivative of the
/// run's predicted mean in the parameters, (shift, Sigma) the training posterior's:
/// (shift_sized, covariance_sized) for `sized`, (shift, covariance) for `predictive`. The first
/// is the plug-in prediction; the others say what the training could not tell it, the last also
/// what the priors say of what it could not see.
struct PredictiveCheck {
  std::vector<double> plugin, sized, predictive;  // per experiment, the mean NEES of its runs
  double plugin_mean = 0.0, sized_mean = 0.0, predictive_mean = 0.0;  // per run, over every experiment
  /// Per parameter of the TrainingUncertainty (same order): its posterior standard deviation, and
  /// how much knowing it exactly would narrow the prediction of these runs (with `covariance`),
  /// in units of NEES: the mean over the runs of v' C^-1 v / Sigma_kk, v = J Sigma e_k (the part
  /// of the widening its estimate carries, with its correlations to the other parameters).
  std::vector<double> posterior_sd, spread;
};

/// The check of `runs` (with its own measurement noise) against `uncertainty.model`.
PredictiveCheck predictive_check(const Suite& runs, const TrainingUncertainty& uncertainty);

/// A menu item the model cannot predict, and the error it meets there (a custom expression of
/// it out of its range: a noise factor fitted below 1 at the suite's speeds, negative at a
/// faster one).
struct UnpredictableExperiment {
  std::string name, why;
};

/// The menu ranked by information_gain for the fit's parameters at its model (the current
/// information: fisher_information of the suite), best first; experiments that add the same
/// information as one ranked earlier (a speed the model does not depend on) are left out, and
/// so are those the model cannot predict (listed in `unpredictable` when given).
std::vector<NextExperiment> next_experiments(const Suite& suite, const FitResult& fit,
                                             std::vector<UnpredictableExperiment>* unpredictable = nullptr);

}  // namespace odomcov
