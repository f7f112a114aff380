#include "odomcov/validation.hpp"

#include <algorithm>

#include "odomcov/propagation.hpp"

namespace odomcov {

Validation validate(const Config& config, double alpha, int threads, Progress* progress,
                    std::int64_t keep_samples) {
  Validation v;
  v.runs = config.simulation.runs;
  v.seed = config.simulation.seed;
  v.alpha = alpha;

  // First-order theory of white wheel noise: zero mean, the closed-form covariance.
  v.theory_mean = Vector3::Zero();
  v.theory_cov = path_covariance(config.path, config.robot).end().P_world;
  v.theory_source = "closed form [Kleeman95], first order";

  const Simulator simulator(config.robot, config.path);
  v.simulation = moments(simulator.simulate(v.runs, v.seed, threads, progress));
  v.odometry_end_pose = simulator.odometry_end_pose();
  if (keep_samples > 0) {
    v.samples = simulator.errors(v.seed, 0, std::min(keep_samples, v.runs), threads);
  }
  v.mean_test = mean_test_known_covariance(v.simulation, v.theory_mean, v.theory_cov);
  v.cov_test = covariance_test(v.simulation, v.theory_cov);
  v.nees_mean = nees_mean(v.simulation, v.theory_mean, v.theory_cov);
  v.verdict = verdict(v.mean_test, v.cov_test, alpha);
  v.noise_induced_mean = noise_induced_mean(config.path, config.robot);
  v.noise_induced_mean_test =
      mean_test_known_covariance(v.simulation, v.noise_induced_mean, v.theory_cov);
  v.sampled_cov = sampled_covariance(config.path, config.robot);
  v.sampled_cov_test = covariance_test(v.simulation, v.sampled_cov);
  return v;
}

}  // namespace odomcov
