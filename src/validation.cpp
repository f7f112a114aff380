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

  // First-order theory: with no model effects the closed form (zero mean); with effects the
  // general engine, whose mean is the exact systematic one. The noise-induced mean is beyond
  // first order and reported apart.
  Vector3 noise_mean;
  if (config.model_effects.empty()) {
    v.theory_mean = Vector3::Zero();
    v.theory_cov = path_covariance(config.path, config.robot).end().P_world;
    v.theory_source = "closed form [Kleeman95], first order";
    noise_mean = noise_induced_mean(config.path, config.robot);
  } else {
    std::vector<double> durations;
    const std::vector<ArcSegment> pieces =
        model_pieces(config.path, config.robot.wheelbase_m, &durations);
    const Prediction p = predict(pieces, durations, config.robot, config.model_effects);
    v.theory_mean = p.mean;
    v.theory_cov = p.cov;
    v.theory_source = "linearised model with effects:";
    for (const EffectSpec& e : config.model_effects) v.theory_source += " " + effect_yaml(e).substr(2);
    noise_mean = p.noise_mean;
  }

  const Simulator simulator(config.world_robot(), config.path, config.world.effects);
  v.simulation = moments(simulator.simulate(v.runs, v.seed, threads, progress));
  v.odometry_end_pose = simulator.odometry_end_pose();
  if (keep_samples > 0) {
    v.samples = simulator.errors(v.seed, 0, std::min(keep_samples, v.runs), threads);
  }
  v.mean_test = mean_test_known_covariance(v.simulation, v.theory_mean, v.theory_cov);
  v.cov_test = covariance_test(v.simulation, v.theory_cov);
  v.nees_mean = nees_mean(v.simulation, v.theory_mean, v.theory_cov);
  v.verdict = verdict(v.mean_test, v.cov_test, alpha);
  v.noise_induced_mean = noise_mean;
  v.noise_induced_mean_test =
      mean_test_known_covariance(v.simulation, v.theory_mean + noise_mean, v.theory_cov);
  if (config.model_effects.empty()) {
    v.sampled_cov = sampled_covariance(config.path, config.robot);
    v.sampled_cov_test = covariance_test(v.simulation, v.sampled_cov);
  } else {
    v.sampled_cov = v.theory_cov;  // the per-sample propagation has no effects
    v.sampled_cov_test.valid = false;
  }
  return v;
}

}  // namespace odomcov
