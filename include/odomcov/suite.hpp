// Measurement suites (../shared/SPEC.md, "Measurement suite"): the runs a lab drove, each with
// its measured end pose, to set against the model.
#pragma once

#include <string>
#include <vector>

#include "odomcov/effects.hpp"
#include "odomcov/path.hpp"

namespace odomcov {

/// Std-dev of the external reference (motion capture, sonar): x and y [m] and theta [rad].
struct MeasurementNoise {
  double xy_m = 0.0;
  double theta_rad = 0.0;
  Matrix3 covariance() const;
};

struct SuiteRun {
  std::string id;                   // the CSV's run column, or the log file's name
  Vector3 measured = Vector3::Zero();  // reference end pose, start frame
  Vector3 odometry = Vector3::Zero();  // odometry end pose (from the path or the run's log)
  std::vector<ArcSegment> pieces;   // logged runs: one piece per log row; else empty
  std::string source;               // file (and line) the run came from, for messages

  /// The error as SPEC defines it: measured (true) - odometry, theta wrapped.
  Vector3 error() const;
};

struct SuiteExperiment {
  std::string name;
  bool logged = false;  // runs carry their own encoder logs
  Path path;            // the planned path (path experiments only)
  std::vector<SuiteRun> runs;
};

struct Suite {
  std::string file;
  std::string name;
  Robot robot;  // the nominal model the user believes in
  MeasurementNoise measurement_noise;
  EffectList model_effects;
  std::vector<SuiteExperiment> experiments;
};

/// Reads and validates a suite and every file it names. Throws InputError (file:line: key) for
/// a missing file, an empty CSV, wrong columns, a value that is not a finite number, duplicate
/// run ids, a log without a final reference pose, time that does not increase, ...
Suite load_suite(const std::string& file);

/// The odometry end pose of a sampled path: the encoder samples integrated with the exact arc
/// update at the nominal wheelbase, as the simulator integrates them.
Vector3 sampled_end_pose(const Path& path, double wheelbase_m);

/// The pieces the model propagates for a run: its log's increments, or the experiment's path.
std::vector<ArcSegment> run_pieces(const SuiteExperiment& experiment, const SuiteRun& run,
                                   double wheelbase_m);

}  // namespace odomcov
