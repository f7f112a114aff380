#include "odomcov/measurement/validation.hpp"

#include <algorithm>
#include <limits>
#include <string>

#include "odomcov/base/error.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/second_order.hpp"

namespace odomcov {
namespace {

/// The order-2 theory and its tests: mean chi^2 (valid for any distribution by the CLT) and
/// Browne's ADF covariance test, which takes the sample's own fourth moments.
/// Order 2 not computed (its cost is quadratic in its pieces): untestable, never "consistent".
OrderResult order2_not_computed(const std::string& why) {
  OrderResult r;
  r.order = 2;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  r.theory_mean = Vector3::Constant(nan);
  r.theory_cov = Matrix3::Constant(nan);
  r.theory_source = "order 2: not computed";
  r.nees_mean = nan;
  r.mean_test.valid = r.cov_test.valid = r.cov_lrt.valid = false;
  r.verdict = Verdict::untestable(why);
  return r;
}

OrderResult order2_result(const Config& config, const SampleMoments& sim, double alpha) {
  OrderResult r;
  r.order = 2;
  std::vector<double> durations;
  const std::vector<ArcSegment> pieces =
      path_model_pieces(config.path, config.robot.wheelbase_m, config.model_effects, &durations);
  const std::size_t count =
      second_order_piece_count(pieces, durations, config.robot.wheelbase_m, config.model_effects);
  if (count > kMaxSecondOrderPieces) {
    return order2_not_computed("order 2 needs " + std::to_string(count) +
                               " quadrature pieces on this path, above the limit " +
                               std::to_string(kMaxSecondOrderPieces) + " (docs/bad-input.md)");
  }
  Prediction p;
  try {
    p = predict_second_order(pieces, durations, config.robot, config.model_effects);
  } catch (const InputError& e) {  // the effects cut the pieces beyond the limit
    if (e.key() != "order 2") throw;
    return order2_not_computed("order 2 needs " + e.message() + " (docs/bad-input.md)");
  }
  r.theory_mean = p.mean + p.noise_mean;
  r.theory_cov = p.cov;
  r.theory_source = "order 2: exact Gaussian-heading moments";
  for (const EffectSpec& e : config.model_effects) r.theory_source += " " + effect_yaml(e).substr(2);
  r.mean_test = mean_test_known_covariance(sim, r.theory_mean, r.theory_cov);
  r.cov_test = covariance_test_adf(sim, r.theory_cov);
  r.cov_lrt = covariance_test(sim, r.theory_cov);
  r.nees_mean = nees_mean(sim, r.theory_mean, r.theory_cov);
  r.verdict = verdict(r.mean_test, r.cov_test, alpha);
  return r;
}

}  // namespace

Validation validate(const Config& config, double alpha, int threads, Progress* progress,
                    std::int64_t keep_samples, int order) {
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
        path_model_pieces(config.path, config.robot.wheelbase_m, config.model_effects, &durations);
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
  // The other order (or, with --order 2, this one's fields from it).
  const OrderResult first = v;  // the first-order part, as computed above
  const OrderResult second = order2_result(config, v.simulation, alpha);
  static_cast<OrderResult&>(v) = order == 2 ? second : first;
  v.other = order == 2 ? first : second;
  if (config.model_effects.empty()) {
    v.sampled_cov = sampled_covariance(config.path, config.robot);
    v.sampled_cov_test = covariance_test(v.simulation, v.sampled_cov);
  } else {
    v.sampled_cov = first.theory_cov;  // the per-sample propagation has no effects
    v.sampled_cov_test.valid = false;
  }
  return v;
}

}  // namespace odomcov
