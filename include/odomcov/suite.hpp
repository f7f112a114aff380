// Measurement suites (../shared/SPEC.md, "Measurement suite"): the runs a lab drove, each with
// its measured end pose, to set against the model.
#pragma once

#include <string>
#include <vector>

#include "odomcov/effects.hpp"
#include "odomcov/path.hpp"
#include "odomcov/statistics.hpp"

namespace YAML {
class Node;
}

namespace odomcov {

/// Std-dev of the external reference (motion capture, sonar): x and y [m] and theta [rad].
struct MeasurementNoise {
  double xy_m = 0.0;
  double theta_rad = 0.0;
  Matrix3 covariance() const;
};

/// Parses a `measurement_noise` block {xy [m], theta_deg}, both optional (0) and >= 0; `key`
/// for messages. Suites and worlds share it.
MeasurementNoise parse_measurement_noise(const YAML::Node& node, const std::string& file,
                                         const std::string& key);

struct SuiteRun {
  std::string id;                   // the CSV's run column, or the log file's name
  Vector3 measured = Vector3::Zero();  // reference end pose, start frame
  Vector3 odometry = Vector3::Zero();  // odometry end pose (from the path or the run's log)
  std::vector<ArcSegment> pieces;   // logged runs: one piece per log row; else empty

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

/// What a model believes about the robot: the nominal robot (wheelbase for the odometry, k's),
/// its effects, and the noise of the external reference.
struct SuiteModel {
  Robot robot;
  EffectList effects;
  MeasurementNoise measurement_noise;
};
SuiteModel suite_model(const Suite& suite);

/// The suite YAML of a model's fitted parts: the robot line, then the model block when it has
/// effects (measurement noise is not fitted, so it is left out). Pasted over a suite's own
/// robot line and model block, it makes that suite use this model.
std::string robot_yaml(const Robot& robot);
std::string model_yaml(const SuiteModel& model);

/// One run set against the model: its error (measured - odometry at the model's wheelbase) and
/// the predicted mean and covariance, measurement noise included. The predicted mean is the
/// systematic mean plus the noise-induced mean (propagation.hpp).
struct RunResidual {
  Vector3 error = Vector3::Zero();
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
};

/// Residuals of every run of every experiment (runs with logs are predicted one by one, in
/// parallel).
std::vector<std::vector<RunResidual>> residuals(const Suite& suite, const SuiteModel& model);

/// Each run's term of the log-likelihood, in order (experiment by experiment): the Gaussian
/// log-density of its error, or with `scatter` its term of scatter_log_likelihood.
std::vector<double> run_log_likelihoods(const std::vector<std::vector<RunResidual>>& residuals,
                                        bool scatter);

/// Sum over runs of the Gaussian log-density of the error under its prediction.
double log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

/// The scatter part of the log-likelihood: only the spread of each experiment's runs about
/// their own mean counts (Wishart likelihood of the within-experiment scatter, [Anderson03]
/// §7.2): for residuals r_i = e_i - mu_i,
///   sum_i -1/2 (r_i - r_bar)' Sigma_i^-1 (r_i - r_bar) - 1/2 ((n-1)/n) ln det(2 pi Sigma_i).
/// A misfit of the mean does not enter, so a variance effect cannot gain by absorbing one.
double scatter_log_likelihood(const std::vector<std::vector<RunResidual>>& residuals);

/// compare for one experiment (SPEC "JSON of compare").
struct ExperimentComparison {
  std::string name;
  std::int64_t n = 0;
  SampleMoments measured;                 // of the errors
  Vector3 predicted_mean = Vector3::Zero();  // for a run drawn from the experiment
  Matrix3 predicted_cov = Matrix3::Zero();   // (mixture over runs for logged experiments)
  TestResult mean_test;   // Hotelling's T^2 on whitened residuals (chi^2 when n <= 3)
  TestResult cov_test;    // LRT of cov = I on whitened residuals (NEES test when n < 10)
  std::string cov_method;  // "lrt" or "nees"
  double nees_mean = 0.0;
  double outside_95 = 0.0;  // fraction of runs with NEES above the chi^2_3 95% point
  double log_likelihood = 0.0;
  std::string verdict;
  std::vector<Vector3> errors;  // each run's error (measured - odometry), in order
  // Per component (x, y, theta), for the plain-words failures:
  Vector3 mean_t = Vector3::Zero();        // (measured - predicted mean)/standard error
  Vector3 mean_p = Vector3::Ones();        // Student-t p-values
  Vector3 variance_ratio = Vector3::Ones();  // measured / predicted variance
  Vector3 variance_p = Vector3::Ones();    // chi^2 p-values (two-sided)
};

struct Comparison {
  double alpha = 0.0;           // family-wise level of the suite
  double alpha_per_test = 0.0;  // Bonferroni over 2 tests per experiment + kurtosis
  std::vector<ExperimentComparison> experiments;
  TestResult kurtosis;  // Mardia's b2, each experiment standardised by its own covariance
  double mardia_b2 = 0.0;        // run-weighted mean of the experiments' b2
  double mardia_expected = 0.0;  // its expectation for Gaussian errors (15 (n-1)/(n+1))
  double kurtosis_scale = 1.0;   // pooled b2/E b2 when the covariance LRTs were kurtosis-scaled
  double log_likelihood = 0.0;
  std::string verdict;
  std::vector<std::string> failures;  // plain words, worst experiment first
};

/// The model against every experiment of the suite ("where it fails" included). The kurtosis
/// test joins the verdict unless the model has a heavy-tailed effect (bumps), which predicts it;
/// such a model's covariance LRTs are then scaled by each experiment's measured kurtosis
/// ([Browne84]).
Comparison compare(const Suite& suite, const SuiteModel& model, double alpha);

/// The odometry end pose of a sampled path: the encoder samples integrated with the exact arc
/// update at the nominal wheelbase, as the simulator integrates them.
Vector3 sampled_end_pose(const Path& path, double wheelbase_m);

}  // namespace odomcov
