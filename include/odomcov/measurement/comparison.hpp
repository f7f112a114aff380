// compare: a model set against every experiment of a measurement suite, with the statistical
// tests of each experiment, the suite's kurtosis test and the verdict.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/engine/statistics.hpp"

namespace odomcov {

/// compare for one experiment (docs/json.md, "compare").
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
  Verdict verdict;
  std::vector<Vector3> errors;  // each run's error (measured - odometry), in order
  // Per component (x, y, theta), for the failures:
  Vector3 mean_t = Vector3::Zero();        // (measured - predicted mean)/standard error
  Vector3 mean_p = Vector3::Ones();        // Student-t p-values
  Vector3 variance_ratio = Vector3::Ones();  // measured / predicted variance
  Vector3 variance_p = Vector3::Ones();    // chi^2 p-values (two-sided)
  /// With a model that records its training domain (SuiteModel::domain): where this
  /// experiment's runs lie outside it, in words (extrapolation()); empty inside.
  std::vector<std::string> extrapolation;

  /// Correlation of components a and b (0 x, 1 y, 2 theta), measured and predicted.
  double measured_correlation(int a, int b) const;
  double predicted_correlation(int a, int b) const;
};

/// One way the model fails the data, as data; the command line and the Python module put it
/// in words (src/cli/failures.cpp). Components: 0 x, 1 y, 2 theta.
struct Failure {
  enum class Kind {
    mean,         // experiment's mean of `component` off the prediction (mean_t, mean_p)
    variance,     // its variance off (variance_ratio, variance_p)
    correlation,  // the covariance test fails with no variance off: the correlation of
                  // (component, other) differs most
    spread,       // the NEES test fails (fewer than 10 runs): the errors' overall spread
    tails         // the suite's Mardia kurtosis (experiment = -1)
  };
  Kind kind = Kind::mean;
  int experiment = -1;  // index into Comparison::experiments
  int component = 0;
  int other = 0;
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
  Verdict verdict;
  std::vector<Failure> failures;  // worst experiment first
};

/// The model against every experiment of the suite ("where it fails" included). The kurtosis
/// test joins the verdict unless the model has a heavy-tailed effect (bumps), which predicts it;
/// such a model's covariance LRTs are then scaled by each experiment's measured kurtosis
/// ([Browne84]).
Comparison compare(const Suite& suite, const SuiteModel& model, double alpha);
/// The same from the model's residuals(suite, model), already computed (diagnose's cache).
Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::vector<RunResidual>>& residuals);

}  // namespace odomcov
