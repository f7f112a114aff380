// What a model's remaining misfit lines up with: each experiment's mean residual (the mean
// part) and its spread about its own mean against the predicted covariance (the scatter part),
// set against features of the path the encoders drove (distance, angle turned, turn direction,
// spin fraction, travel direction, reversals, speed, acceleration, heading, group). The honest
// half of diagnose's verdict: when no catalogue effect is significant but the model is still
// inconsistent, this says what kind of effect is missing, in the catalogue or not.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/likelihood.hpp"

namespace odomcov {

/// Features of the motion of one run, from its encoder travel (and the time of each piece).
struct PathFeatures {
  double distance_m = 0.0;        // mean wheel travel, sum (|dL| + |dR|)/2
  double angle_turned_rad = 0.0;  // signed encoder heading change, sum (dR - dL)/B
  double turn_direction = 0.0;    // sum dtheta / sum |dtheta|: +1 all CCW, -1 all CW, 0 straight
  double spin_fraction = 0.0;     // sum |dR - dL| / sum (|dL| + |dR|): 0 lines, 1 spins
  double travel_direction = 0.0;  // sum d / sum |d| of the centre travel: +1 forwards, -1 backwards
  double reversals = 0.0;         // reversals of either wheel's direction (5 mm hysteresis)
  double speed_mps = 0.0;         // mean wheel speed, weighted by the distance driven at it
  double duration_s = 0.0;        // the run's duration: sum of its pieces' durations
  /// Starts and stops: the total change of the wheels' speeds over the run, from and back to
  /// standstill, sum |dv| averaged over the two wheels [m/s], counting only swings of at least
  /// kAccelerationHysteresis_mps (encoder jitter on logged runs does not count). One start and
  /// one stop at speed v give 2v.
  double acceleration_mps = 0.0;
  /// The direction the robot drives in the reference's frame: the mean of cos and sin of the
  /// absolute heading psi = heading0 + theta over the run (theta the encoder heading), weighted
  /// by the travel (|dL| + |dR|)/2 driven at it. Over a piece whose heading turns linearly from
  /// psi_a by dpsi, the mean is exact: (cos, sin)(psi_a + dpsi/2) sin(dpsi/2)/(dpsi/2). A length
  /// below 1 means the run turned (0 for a whole spin). Only where the run's start heading is
  /// known (heading_known: SuiteRun::heading0_given); 0 otherwise.
  double heading_cos = 0.0, heading_sin = 0.0;
  bool heading_known = false;
};

/// A wheel's speed counts as changed once it has moved this far from its last turning point.
inline constexpr double kAccelerationHysteresis_mps = 0.05;

/// The features of a run: planned paths from their keyframe intervals (constant wheel speeds,
/// the motion the sample schedule follows), logged runs from their pieces and the time of each
/// (SuiteRun::durations_s). The one place that reads a run's motion for the residual analysis.
PathFeatures path_features(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m);

/// Each experiment's value of a path feature (residual_feature_names; not "group"): its runs'
/// mean, as the mean part's test reads it; for a feature of two columns (heading) the column
/// that varies more across the experiments. NaN for an experiment without runs, and for every
/// experiment when the feature is unknown (no such feature, or a heading not every run gives).
std::vector<double> experiment_feature_values(const Suite& suite, double wheelbase_m, const std::string& feature);

/// The group an experiment belongs to, for the between-group test: the suite's `group:` key
/// (group_key: an experiment without one is a group of its own).
std::string experiment_group(const SuiteExperiment& ex);

/// True when some experiment's runs give their start headings and these differ: the suites whose
/// residual alignment has a run part (heading).
bool runs_start_at_different_headings(const Suite& suite);

/// The residual features, in the order of docs/json.md's list (each tested against both parts).
const std::vector<std::string>& residual_feature_names();

/// One test of a feature against one part of the misfit.
struct ResidualAlignment {
  std::string feature;
  /// "mean" (the experiments' mean residuals), "scatter" (their spread) or "run" (each run's
  /// residual about its experiment's mean, for the runs of experiments that started at different
  /// headings)
  std::string part = "mean";
  bool testable = false;   // false: the feature does not vary across experiments (or no dof)
  double statistic = 0.0;  // F
  int dof1 = 0, dof2 = 0;
  double p_value_raw = 1.0;  // F test of this feature and part alone
  double p_value = 1.0;      // Bonferroni over every testable feature and part (family-wise)
  std::string description;   // what kind of physical effect has this signature
};

/// Tests every feature against both parts of the misfit, best (smallest p) first, untestable
/// ones last.
///
/// Mean part. For experiment e with n runs, the mean residual r_e = mean_i (error_i - mean_i) is
/// taken in each run's odometry end frame (along-track, cross-track, heading); its predicted
/// covariance is C_e = sum_i Sigma_i / n^2 (rotated alike), so under the model r_e ~ N(0, C_e).
/// S_e (3x4) is the first-order sensitivity of r_e to the four directions a feature can modulate
/// (wheel scale Es, wheelbase Eb, diameter ratio Ed, a sideways slip per metre), by a forward
/// difference of the model's prediction; V_e (3x2) carries an offset fixed in each run's start
/// frame (its x and y axes in the end frame), I3 one fixed in the end frame: a marker off the
/// axle centre makes both (R(theta) d - d). With f_e the feature averaged over the experiment's
/// runs, centred and scaled, the generalised least-squares fit
///   H1: r_e = X_e c + f_e M_e d,   X_e = [I3 V_e S_e],   M_e = [e_theta V_e S_e]
/// (a factor error, a sideways slip, a heading offset or an offset in the start frame that varies
/// with f) is set against H0: r_e = X_e c (constant ones), and
///   F = ((RSS0 - RSS1)/q) / (RSS1/(3m - p1)) ~ F(q, 3m - p1),   q = p1 - p0,
/// with RSS the C_e^-1-weighted residual sums of squares over the m experiments and p0, p1 the
/// ranks of the stacked designs (9 and 16 where the experiments end at different headings; an
/// offset in the start frame is one in the end frame for a path that ends facing the way it
/// started). H0's constant terms and the estimated scale (RSS1) make the test about variation
/// *with the feature*, not a misfit common to every experiment or an overall variance too small.
/// A floor that pushes every run the same way (runs started aligned) is an offset in the start
/// frame that grows with the distance. heading has two columns (its cos and sin), each
/// modulating the seven terms; it is untestable unless every run's start heading is known. group
/// is the one-way ANOVA: H0's terms per group against common ones.
///
/// Scatter part. For experiment e with n >= 2 runs, d_i = r_i - mean_j r_j (end frame) and
///   W_e = sum_i d_i' Sigma_i^-1 d_i,  E[W_e] = sum_i (3 (1 - 2/n) + tr(Sigma_i^-1 Sigma_bar)/n)
/// (Sigma_bar the mean of the runs' Sigma_i; 3 (n - 1) when they are equal), so s_e = W_e/E[W_e]
/// is ~ chi^2_nu/nu, nu = 3 (n - 1), when the predicted spread is right: a gamma variable of
/// known shape nu/2. A variance that grows with the feature is the gamma GLM with log link
///   H1: log E s_e = a + b f_e   against   H0: log E s_e = a,
/// F = ((D0 - D1)/q) / (X1^2/(m - p1)) ~ F(q, m - p1), D the deviances
/// 2 sum nu_e/2 ((s - mu)/mu - ln(s/mu)) and X1^2 H1's Pearson statistic, the dispersion
/// estimated as in the mean part [McCullagh89, §8.3], so that an overall spread too large or tails
/// heavier than Gaussian do not count (heading: two columns, F(2, m - 3)). group: log E s_e per
/// group against a common one.
/// Run part (heading only, and only for a suite whose runs of one experiment started at
/// different headings: runs_start_at_different_headings). Over the experiments whose runs did,
/// each run's end-frame residual about its experiment's mean, d_i, against the feature's columns
/// about theirs, g_i, in weighted least squares (Sigma_i^-1):
///   H1: d_i = sum_c g_ic a_c (a_c in R^3)   against   H0: d_i = 0,
/// F = ((RSS0 - RSS1)/q) / (RSS1/(nu - q)) ~ F(q, nu - q), q = 3 x columns, nu = 3 sum (n_e - 1):
/// the within-experiment analysis of variance, its scale estimated from RSS1. A spread between
/// the runs that follows their heading is systematic: a random effect cannot explain it.
/// Each p_value is Bonferroni-corrected over every testable feature and part.
///
/// With `simulated`, the scatter part takes its dispersion from the model's own world instead:
/// `replicates` suites simulated from the model (ModelWorld, `seed`) give each experiment's
/// variance of s_e under the model, phi_e / k_e (phi_e = 1 for Gaussian errors, above 1 when the
/// model's errors have heavier tails: bumps, a per-run radius); the GLM's weights are then
/// k_e / phi_e and D0 - D1 ~ chi^2(q) (statistic D0 - D1, dof2 = 0). A spread that varies with
/// the feature more than the model's own sampling lets it counts, and nothing else estimates the
/// dispersion, so a misfit elsewhere does not dilute it: the sharper test, for the decisions
/// that ask whether a candidate explained the shape of the scatter (diagnose's scatter shape
/// rule). Without `simulated`, or when the model's effects cannot be simulated on every run, the
/// F test above.
struct SimulatedDispersion {
  std::uint64_t seed = 1;
  int replicates = 99;
};

std::vector<ResidualAlignment> residual_alignment(
    const Suite& suite, const SuiteModel& model,
    const std::vector<std::vector<RunResidual>>& residuals, const SimulatedDispersion* simulated = nullptr);

/// The same on the suite of `cache`, with the model's residuals and those of the models the
/// mean part nudges along each factor direction read through it: a decision that asks several
/// parts of one model (diagnose's rules ask the base's mean, scatter and run parts) propagates
/// them once. Every part is tested each time, since each p-value is corrected over all of them.
std::vector<ResidualAlignment> residual_alignment(ResidualCache& cache, const SuiteModel& model,
                                                  const SimulatedDispersion* simulated = nullptr);

}  // namespace odomcov
