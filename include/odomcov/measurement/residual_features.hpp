// What a model's remaining misfit lines up with: each experiment's mean residual, whitened by
// its predicted standard error, set against features of the path the encoders drove (distance,
// angle turned, turn direction, spin fraction, travel direction, reversals, speed, group). The
// honest half of diagnose's verdict: when no catalogue effect is significant but the model is
// still inconsistent, this says what kind of effect is missing, in the catalogue or not.
#pragma once

#include <string>
#include <vector>

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
};

/// The features of a run: planned paths from their keyframe intervals (constant wheel speeds,
/// the motion the sample schedule follows), logged runs from their pieces and the time of each
/// (SuiteRun::durations_s). The one place that reads a run's motion for the residual analysis.
PathFeatures path_features(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m);

/// The group an experiment belongs to, for the between-group test: the suite's `group:` key
/// (group_key: an experiment without one is a group of its own).
std::string experiment_group(const SuiteExperiment& ex);

/// The residual features, in the order of docs/json.md's list.
const std::vector<std::string>& residual_feature_names();

/// One feature's alignment with the misfit.
struct ResidualAlignment {
  std::string feature;
  bool testable = false;   // false: the feature does not vary across experiments (or no dof)
  double statistic = 0.0;  // F
  int dof1 = 0, dof2 = 0;
  double p_value_raw = 1.0;  // F test of this feature alone
  double p_value = 1.0;      // Bonferroni over the testable features (family-wise)
  std::string description;   // what kind of physical effect has this signature
};

/// Tests every feature against the mean residuals of the experiments, best (smallest p) first,
/// untestable features last.
///
/// Method. For experiment e with n runs, the mean residual r_e = mean_i (error_i - mean_i) is
/// taken in each run's odometry end frame (along-track, cross-track, heading); its predicted
/// covariance is C_e = sum_i Sigma_i / n^2 (rotated alike), so under the model r_e ~ N(0, C_e).
/// S_e (3x3) is the first-order sensitivity of r_e to the three factor directions a feature can
/// modulate (wheel scale Es, wheelbase Eb, diameter ratio Ed), by a forward difference of the
/// model's prediction. With f_e the feature averaged over the experiment's runs, centred and
/// scaled, the generalised least-squares fit
///   H1: r_e = [I3 S_e] c + f_e [I3 S_e] d      (an offset or factor error varying with f)
/// is set against H0: r_e = [I3 S_e] c (constant ones), and
///   F = ((RSS0 - RSS1)/6) / (RSS1/(3m - 12)) ~ F(6, 3m - 12),
/// with RSS the C_e^-1-weighted residual sums of squares over the m experiments. H0's constant
/// terms and the estimated scale (RSS1) make the test about variation *with the feature*, not a
/// misfit common to every experiment or an overall variance too small. group is the one-way
/// ANOVA: H0's terms per group against common ones, F(6(G - 1), 3m - 6G). Each p_value is
/// Bonferroni-corrected over the testable features.
std::vector<ResidualAlignment> residual_alignment(
    const Suite& suite, const SuiteModel& model,
    const std::vector<std::vector<RunResidual>>& residuals);

}  // namespace odomcov
