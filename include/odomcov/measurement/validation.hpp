// One validation: the Monte-Carlo simulation of a config against its theory, with the tests of
// [Kleeman95] §7 made proper (docs/json.md, "run").
#pragma once

#include <string>
#include <vector>

#include "odomcov/measurement/config.hpp"
#include "odomcov/engine/simulator.hpp"
#include "odomcov/engine/statistics.hpp"

namespace odomcov {

inline constexpr double kDefaultAlpha = 0.001;

/// The theory of one model order set against the simulation.
///  * order 1: the first-order closed form (or engine); covariance test = Bartlett-corrected LRT.
///  * order 2: the exact-moment model (second_order.hpp); covariance test = Browne's ADF test,
///    whose size does not assume a Gaussian error (the LRT is kept beside it for information).
struct OrderResult {
  int order = 1;
  Vector3 theory_mean = Vector3::Zero();
  Matrix3 theory_cov = Matrix3::Zero();
  std::string theory_source;
  TestResult mean_test;
  TestResult cov_test;
  TestResult cov_lrt;  // order 2: the Gaussian LRT against the order-2 covariance (information)
  double nees_mean = 0.0;
  Verdict verdict;
};

/// The simulation against the theory. Its OrderResult part (theory, tests, verdict) is the order
/// chosen with --order; `other` holds the other order's, computed on the same simulation.
struct Validation : OrderResult {
  std::int64_t runs = 0;
  std::uint64_t seed = 0;
  double alpha = kDefaultAlpha;
  SampleMoments simulation;
  OrderResult other;
  // Beyond the continuous first-order theory (information only, not part of the verdict):
  // the noise-induced mean of propagation.hpp with the chi^2 mean test against it, and the
  // first-order covariance of the sampled odometry ([Wang88], sampled_covariance) with the
  // covariance test against it, which accounts for noise lumped per sample at low rates.
  Vector3 noise_induced_mean = Vector3::Zero();  // added to theory_mean for its test
  TestResult noise_induced_mean_test;
  Matrix3 sampled_cov = Matrix3::Zero();
  TestResult sampled_cov_test;
  // Optional: the errors of the first runs (for scatter plots) and the odometry end pose.
  std::vector<Vector3> samples;
  Vector3 odometry_end_pose = Vector3::Zero();
};

/// Simulates config.simulation.runs runs with config.simulation.seed and tests the end-pose
/// error against the theory at level alpha. `progress` (optional) counts finished runs.
/// `keep_samples` asks for the errors of runs 0 .. keep_samples-1 as well. `order` (1 or 2)
/// chooses the theory of the verdict; the other order is computed too (Validation::other).
Validation validate(const Config& config, double alpha, int threads = 0,
                    Progress* progress = nullptr, std::int64_t keep_samples = 0, int order = 1);

}  // namespace odomcov
