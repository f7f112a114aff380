// calibrate: the whole loop of setting a model against measured runs. Diagnose, adopt the
// effect that predicts runs it was not fitted on, repeat until nothing more does; then fit
// everything jointly, say what the runs cannot separate and what to record next, record the
// training domain, and (with held-out runs) judge the model on runs it never saw.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/measurement/design.hpp"
#include "odomcov/measurement/diagnosis.hpp"

namespace odomcov {

/// At most this many rounds by default: OptiOdom's loops end within 7.
inline constexpr int kCalibrateRounds = 12;

struct CalibrateOptions {
  /// Each round's settings (alpha, the user's candidates, the fit path, cross-validation).
  DiagnoseOptions diagnose;
  /// Stop after this many rounds even if the last one adopted an effect.
  int rounds = kCalibrateRounds;
};

/// The NEES mean per run by kind of experiment (SuiteExperiment::kind), in order of first
/// appearance: of `comparison`, which is of `suite`'s experiments.
using NeesByKind = std::vector<std::pair<std::string, double>>;
NeesByKind nees_by_kind(const Suite& suite, const Comparison& comparison);
/// The same from each experiment's NEES mean per run (one per experiment of `suite`).
NeesByKind nees_by_kind(const Suite& suite, const std::vector<double>& nees_mean);

/// A model judged on runs it was not fitted on.
struct HoldoutSummary {
  /// Where the model cannot predict the held-out runs at all, why: the error it meets on them
  /// (a custom expression of it out of its range there: a noise factor fitted below 1 at the
  /// training runs' speeds, negative at the held-out runs'). The comparison, NEES and fits below
  /// are then empty, and only the experiments and their extrapolation are filled in. "" else.
  std::string cannot_predict;
  Comparison comparison;
  ModelSummary summary;
  std::size_t experiments = 0, consistent = 0;
  NeesByKind nees_by_kind;  // of the held-out runs
  /// "experiment: speed 0.104 m/s is above the training range ..." for every experiment
  /// outside the model's training domain (extrapolation()).
  std::vector<std::string> extrapolation;
  /// The same effects refitted on the held-out runs themselves (every parameter the joint fit
  /// refits, from the model's values): how near 3 the model's effects get on these runs when
  /// they have seen them. A prediction is not expected to come nearer; what lies between the
  /// two is in the sizes the training runs gave the effects, what is left beyond in effects
  /// the model does not have. Empty when the model has nothing to fit.
  struct Refitted {
    FitResult fit;
    double nees_mean = 0.0;  // Gaussian reference (the NEES mean does not depend on it)
    NeesByKind nees_by_kind;
  };
  std::optional<Refitted> refitted;
  /// The held-out runs predicted from the training runs' posterior (predictive_check,
  /// design.hpp): their marginal NEES mean as the model predicts them, from the posterior of what
  /// the training runs size, and with every absent effect they do not size at its prior besides;
  /// and the parameters that matter for these runs.
  struct Predictive {
    double plugin_nees_mean = 0.0, sized_nees_mean = 0.0, nees_mean = 0.0;
    NeesByKind plugin_by_kind, sized_by_kind, nees_by_kind;
    struct Parameter {
      std::string name;
      double prior_sd = 0.0;  // 0: a fitted parameter (no prior)
      double posterior_sd = 0.0;
      double shift = 0.0;     // the posterior mean less the model's value (TrainingUncertainty::shift)
      bool sized = true;      // TrainingUncertainty::sized
      double spread = 0.0;    // PredictiveCheck::spread
    };
    /// Every parameter whose exact value would narrow the held-out prediction by at least
    /// kPredictiveSpreadShown NEES (PredictiveCheck::spread), most first.
    std::vector<Parameter> parameters;
  };
  std::optional<Predictive> predictive;
};

/// HoldoutSummary::Predictive lists the parameters whose exact value would narrow the held-out
/// prediction by at least this much (in NEES, whose plug-in expectation is 3): a tenth of one
/// component's share.
inline constexpr double kPredictiveSpreadShown = 0.1;

/// The calibrated model as ROS 2's diff_drive_controller takes it (docs/calibrate.md):
///  * wheel_separation_multiplier: the corrected odometry's effective wheelbase over the nominal
///    (odometry_correction: the true wheelbase weighted by the rotation the training runs saw);
///  * left_/right_wheel_radius_multiplier: each wheel's true travel per encoder metre;
///  * pose_covariance_diagonal (x, y, z, roll, pitch, yaw): the model's covariance of the
///    end-pose error after `pose_distance_m` of straight line at the training runs' median
///    speed; z, roll and pitch kUnusedVariance, as 2-D publishers do;
///  * twist_covariance_diagonal (vx, vy, vz, wx, wy, wz): the same over one controller period
///    1/rate_hz, divided by the period squared (the variance of the speed and turn rate one
///    update reports); vz, wx, wy kUnusedVariance.
/// One multiplier cannot follow a correction that depends on the motion
/// (turn_dependent_wheelbase): `motion_dependent` says so, and the values are the average over
/// the training runs.
struct DiffDriveParameters {
  double wheel_separation_multiplier = 1.0;
  double left_wheel_radius_multiplier = 1.0, right_wheel_radius_multiplier = 1.0;
  std::vector<double> pose_covariance_diagonal, twist_covariance_diagonal;
  bool motion_dependent = false;
  double nominal_wheelbase_m = 0.0;
  double speed_mps = 0.0;        // the speed the covariances are for
  double pose_distance_m = 1.0;  // the distance the pose covariance is after
  double rate_hz = 50.0;         // the controller's publish rate the twist covariance is for
};
/// The variance written for the axes a planar robot does not observe (z, roll, pitch), large
/// so that a fusing filter (robot_localization) ignores them.
inline constexpr double kUnusedVariance = 1e6;

/// diff_drive_controller's parameters from a calibrated model and its training runs.
DiffDriveParameters diff_drive_parameters(const Suite& suite, const SuiteModel& model);

/// An adopted systematic effect whose size is not the same on the two halves of the training
/// experiments along a feature of the path (stand_ins): it predicts the runs better, so it
/// stays in the model, but a cause would have one size on both sides; it stands in for physics
/// that changes with the feature (a scale error for a scale that fades as the tyres warm).
struct StandIn {
  std::string effect;
  std::string parameter;  // its fit name, e.g. "scale_error.Es"
  std::string feature;    // a residual feature (residual_feature_names)
  std::array<std::string, 2> halves;  // the halves' names (feature_folds), low side first
  std::array<double, 2> value{};      // the parameter fitted on each half (every other parameter refitted too)
  std::array<double, 2> stderr_{};    // their standard errors
  double phi = 1.0;  // the mean dispersion of the halves under their own fits, which scales the variances
  double z = 0.0;    // (value[0] - value[1]) / sqrt(phi (stderr_[0]^2 + stderr_[1]^2))
  double p_value = 1.0;  // two-sided
  double level = 0.0;    // the family-wise alpha over every (feature, parameter) pair tested
  std::string text;      // the finding in words
};

struct CalibrateResult {
  std::vector<Diagnosis> rounds;
  /// The adopted candidates, in order; an effect the final nested check replaced by a simpler
  /// one it contains (`simplified`) under the simpler one's name, and without those the check
  /// after the rounds took out (the other effects made them unnecessary).
  std::vector<std::string> named;
  /// What the checks after the rounds did, in words (before the joint fit): the nested check's
  /// replacements, then the effects taken out.
  std::vector<std::string> simplified;
  SuiteModel loop_model;           // the model after the last adoption (everything refitted)
  /// The joint fit of every fitted parameter of the final model's effects (and the wheel
  /// noise when wheel_noise_level was adopted) on the full likelihood.
  FitResult joint;
  /// True when the joint fit is the final model; false when it was not taken, and why.
  bool joint_adopted = false;
  std::string joint_note;
  /// The final model, with its training domain (SuiteModel::domain).
  SuiteModel model;
  ModelSummary after;  // the final model against the training runs
  NeesByKind nees_by_kind;  // ... by kind of experiment
  bool explained = false;  // compare finds the final model consistent with the training runs
  /// When the final model is not explained: its systematic effects whose size changes along a
  /// feature (StandIn), at most one per effect (its most significant).
  std::vector<StandIn> stand_ins;
  std::vector<ResidualAlignment> residuals;  // when not explained
  std::optional<OdometryCorrection> odometry_correction;
  /// Effects the last round stopped as confounded with the model's: not adopted, not ruled
  /// out. `confounded` and `next_experiments` count their parameters beside the model's.
  std::vector<std::string> unresolved;
  std::vector<ConfoundedPair> confounded;
  std::vector<NextExperiment> next_experiments;  // best first
  std::vector<UnpredictableExperiment> unpredictable_experiments;  // menu items it cannot predict
  DiffDriveParameters diff_drive;
  std::optional<HoldoutSummary> holdout;
};

/// The loop on `suite` from `start`: diagnose rounds (each a DiagnoseOptions round, which
/// adopts only a candidate that predicts its held-out folds better), until a round adopts
/// nothing or `options.rounds` rounds; the joint fit (kept when no parameter ends at a bound
/// and the NEES mean does not move further from 3 than the loop's model); compare, the
/// residual alignment, the corrected odometry, the confounded pairs and the next experiments
/// of the final model; its training domain; and, given `holdout` runs, the final model against
/// them (with the holdout suite's measurement noise). Throws Cancelled when `progress->cancel`
/// is set.
CalibrateResult calibrate(const Suite& suite, const SuiteModel& start, const CalibrateOptions& options,
                      const Suite* holdout = nullptr, DiagnoseProgress* progress = nullptr);

/// The model against held-out runs: compare, the NEES per kind, and the experiments outside
/// the model's training domain.
HoldoutSummary judge_holdout(const Suite& holdout, const SuiteModel& model, double alpha,
                             const CalibrationOptions& calibration = {});

/// The parameters calibrate's joint fit refits in a model: each effect's fitted ones
/// (EffectInfo; group_variation's sd), and k_left, k_right when `noise_level`.
std::vector<std::string> joint_parameters(const SuiteModel& model, bool noise_level);

}  // namespace odomcov
