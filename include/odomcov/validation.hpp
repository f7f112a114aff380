// One validation: the Monte-Carlo simulation of a config against its theory, with the tests of
// [Kleeman95] §7 made proper (../shared/SPEC.md, "JSON of run").
#pragma once

#include <string>

#include "odomcov/config.hpp"
#include "odomcov/simulator.hpp"
#include "odomcov/statistics.hpp"

namespace odomcov {

inline constexpr double kDefaultAlpha = 0.001;

struct Validation {
  std::int64_t runs = 0;
  std::uint64_t seed = 0;
  double alpha = kDefaultAlpha;
  SampleMoments simulation;
  Vector3 theory_mean = Vector3::Zero();
  Matrix3 theory_cov = Matrix3::Zero();
  std::string theory_source;  // which model produced the theory
  TestResult mean_test;       // chi^2 with the theory covariance
  TestResult cov_test;        // LRT of Sigma = Sigma_theory
  double nees_mean = 0.0;
  std::string verdict;
  // Beyond first order (information only, not part of the verdict): the noise-induced mean of
  // propagation.hpp and the chi^2 mean test against it.
  Vector3 noise_induced_mean = Vector3::Zero();
  TestResult noise_induced_mean_test;
};

/// Simulates config.simulation.runs runs with config.simulation.seed and tests the end-pose
/// error against the theory at level alpha. `progress` (optional) counts finished runs.
Validation validate(const Config& config, double alpha, int threads = 0,
                    Progress* progress = nullptr);

}  // namespace odomcov
