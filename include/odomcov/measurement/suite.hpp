// Measurement suites (docs/formats.md, "Measurement suite"): the runs a lab drove, each with
// its measured end pose, to set against the model.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"

namespace odomcov {

/// Std-dev of the external reference (motion capture, sonar): x and y [m] and theta [rad].
struct MeasurementNoise {
  double xy_m = 0.0;
  double theta_rad = 0.0;
  Matrix3 covariance() const;
};

/// One measured run. It keeps what was measured and the encoder travel, never an odometry pose:
/// the odometry depends on the wheelbase the model uses, so it is computed where it is needed
/// (odometry_end_pose), at that wheelbase.
struct SuiteRun {
  std::string id;                   // the CSV's run column, or the log file's name
  Vector3 measured = Vector3::Zero();  // reference end pose, start frame
  std::vector<ArcSegment> pieces;   // logged runs: one piece per log row up to the reference
  std::vector<double> durations_s;  // logged runs: the time each piece took (from the t column)
  /// The run's start heading in the reference's own world frame [rad] (the measurements'
  /// `heading0` column, or a log's first-row heading0): what effects that use the absolute
  /// heading see at the start; 0 where the measurements do not give it (heading0_given false).
  double heading0_rad = 0.0;
  bool heading0_given = false;
};

struct SuiteExperiment {
  std::string name;
  bool logged = false;  // runs carry their own encoder logs
  Path path;            // the planned path (path experiments only)
  std::vector<SuiteRun> runs;
  /// The suite's `group:` (a session, a day): experiments with the same group share
  /// group_variation's draw, so their runs are correlated. Empty: the experiment is a group of
  /// its own (group_key).
  std::string group;
  /// The kind of path (`kind:`, e.g. "square", "circular"); the loader fills in the default,
  /// default_kind(name), when the suite does not give one. Kinds are the folds of calibrate's
  /// cross-validation and the rows of its per-kind reports.
  std::string kind;
};

/// An experiment's kind when the suite does not say: its name up to the first '-' (OptiOdom's
/// "square-230620202042-cw" is a "square"); the whole name when it has none.
std::string default_kind(const std::string& experiment_name);
/// The experiment's kind: its `kind`, or default_kind of its name when that is empty (a suite
/// built in code).
std::string experiment_kind(const SuiteExperiment& ex);

/// The key that identifies an experiment's group: "group:<group>" when it has one, else
/// "experiment:<name>" (a group of its own).
std::string group_key(const SuiteExperiment& ex);

/// The training domain of a calibrated model (`model: domain:` in a suite, written by
/// calibrate): the range of each feature over the runs the model was fitted on, per run. A
/// prediction for runs outside it is an extrapolation, and compare says so.
struct Domain {
  struct Range {
    double lo = 0.0, hi = 0.0;
  };
  Range speed_mps;      // `speed`: mean wheel speed, weighted by distance [m/s]
  Range spin_fraction;  // `spin_fraction`: sum |dR - dL| / sum (|dL| + |dR|), 0 lines .. 1 spins
  Range length_m;       // `length`: mean wheel travel [m]
  Range duration_s;     // `duration` [s]
};

struct Suite {
  std::string file;
  std::string name;
  Robot robot;  // the nominal model the user believes in
  MeasurementNoise measurement_noise;
  EffectList model_effects;
  std::optional<Domain> model_domain;  // `model: domain:`, when the model was calibrated
  std::vector<SuiteExperiment> experiments;
};

/// What a model believes about the robot: the nominal robot (wheelbase for the odometry, k's),
/// its effects, and the noise of the external reference.
struct SuiteModel {
  Robot robot;
  EffectList effects;
  MeasurementNoise measurement_noise;
  /// The model order of every prediction (second_order.hpp): 2, exact in the heading noise, is
  /// the default of compare, fit and diagnose; 1 is the first-order engine.
  int order = 2;
  /// Where the model was calibrated (calibrate's `domain`); none for a model given by hand.
  std::optional<Domain> domain = std::nullopt;
};
SuiteModel suite_model(const Suite& suite);

/// The suite YAML of a model's fitted parts: the robot line, then the model block when it has
/// effects (measurement noise is not fitted, so it is left out). Pasted over a suite's own
/// robot line and model block, it makes that suite use this model.
std::string robot_yaml(const Robot& robot);
/// The model block's lines: the robot line, then `model:` with the domain (when the model has
/// one) and the effects.
std::string model_yaml(const SuiteModel& model);
/// The `domain: {speed: [lo, hi], spin_fraction: [..], length: [..], duration: [..]}` line.
std::string domain_yaml(const Domain& domain);

/// The odometry end pose of a run at `wheelbase_m`: its logged encoder travel integrated piece
/// by piece, or the experiment's sampled path.
Vector3 odometry_end_pose(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m);

/// A run's encoder travel as constant-curvature pieces: the logged pieces, or the sampled
/// path's arcs (sample_arcs).
std::vector<ArcSegment> encoder_pieces(const SuiteExperiment& ex, const SuiteRun& run);

/// The error as docs/conventions.md defines it at `wheelbase_m`: measured (true) - odometry, theta wrapped.
Vector3 run_error(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m);

/// The odometry end pose of a sampled path: the encoder samples integrated with the exact arc
/// update at the nominal wheelbase, as the simulator integrates them.
Vector3 sampled_end_pose(const Path& path, double wheelbase_m);

}  // namespace odomcov
