#include "odomcov/measurement/referee.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "base/random.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/simulator.hpp"

namespace odomcov {
namespace {

/// Streams of the referee's seed, apart from each other and from synth's (which derives its
/// experiments' seeds from the world's seed directly).
constexpr std::uint64_t kRefereeStream = 0xA000000000000001ull;
constexpr std::uint64_t kMeasurementStream = 0xA000000000000002ull;

/// Chebyshev points of the first kind on which group_variation's systematic mean is
/// interpolated, over value +- kGroupSpan sd: P(|z| > 8) = 1.2e-15, so draws never leave it in
/// practice. The systematic mean is analytic in the parameter and, over so small a range, close
/// to a quadratic: the degree-8 interpolant is exact to rounding.
constexpr int kGroupNodes = 9;
constexpr double kGroupSpan = 8.0;

/// group_variation's world side for one unit of work (a planned path, or a logged run): the
/// exact systematic mean at the group's drawn value, minus the mean at the model's value, as a
/// function of the draw z ~ N(0, 1), by barycentric interpolation through the Chebyshev points
/// [Berrut04, eq. (5.2)]. The noise of the run is simulated at the model's value: the draw moves
/// the noise's covariance by a relative O(sd) (0.2% for the OptiOdom sessions' spin
/// wheelbase), far below what a suite can see.
struct GroupShift {
  bool present = false;
  double lo = 0.0, hi = 0.0;  // the draw is kept within [lo, hi] (the parameter's range)
  double value = 0.0, sd = 0.0;
  double nodes[kGroupNodes] = {};
  double weights[kGroupNodes] = {};
  Vector3 values[kGroupNodes];

  Vector3 at(double z) const {
    if (!present) return Vector3::Zero();
    const double x = std::clamp(value + sd * z, lo, hi);
    Vector3 num = Vector3::Zero();
    double den = 0.0;
    for (int k = 0; k < kGroupNodes; ++k) {
      const double d = x - nodes[k];
      if (d == 0.0) return values[k];
      num += weights[k] / d * values[k];
      den += weights[k] / d;
    }
    return num / den;
  }
};

GroupShift group_shift(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations,
                       const SuiteModel& model, const GroupTarget& t, double heading0_rad) {
  GroupShift g;
  if (!t.present || !(t.sd > 0.0)) return g;
  const EffectList& effects = model.effects;
  const EffectParameterInfo& info = info_of(effects[t.effect])->parameters[t.parameter];
  g.present = true;
  g.value = effects[t.effect].values[t.parameter];
  g.sd = t.sd;
  // Within the parameter's range, as group_terms keeps its points (half the way to a bound).
  const double h = std::min({kGroupSpan * t.sd, 0.5 * (g.value - info.lower), 0.5 * (info.upper - g.value)});
  g.lo = g.value - h;
  g.hi = g.value + h;
  // The mean at the value (list 0) and at each node (list k + 1), in one walk.
  std::vector<EffectList> lists(kGroupNodes + 1, effects);
  for (int k = 0; k < kGroupNodes; ++k) {
    const double angle = M_PI * (k + 0.5) / kGroupNodes;
    g.nodes[k] = g.value + h * std::cos(angle);
    g.weights[k] = (k % 2 == 0 ? 1.0 : -1.0) * std::sin(angle);
    lists[k + 1][t.effect].values[t.parameter] = g.nodes[k];
  }
  const std::vector<Vector3> means = predict_means(pieces, durations, model.robot, lists, nullptr, heading0_rad);
  for (int k = 0; k < kGroupNodes; ++k) g.values[k] = means[k + 1] - means[0];
  return g;
}

/// The model's effects as the world of one group-free run: without group_variation, whose
/// draw is GroupShift's.
EffectList world_effects(const EffectList& effects) {
  EffectList out;
  for (const EffectSpec& e : effects) {
    if (!info_of(e)->grouped) out.push_back(e);
  }
  return out;
}

}  // namespace

/// One unit of work: a planned-path experiment (its simulator serves all its runs) or one
/// logged run. Replicate b of a unit with n runs is its simulator's runs b n .. b n + n - 1.
struct Unit {
  Simulator simulator;
  std::uint64_t seed = 0;
  std::size_t first_run = 0;  // flat index of its first run
  std::size_t runs = 0;
  int group = 0;
  GroupShift shift;
};

struct ModelWorld::Impl {
  std::vector<Unit> units;
  std::size_t runs = 0;
  int groups = 0;
  Vector3 measurement_sd = Vector3::Zero();
  random::Philox::key_type measurement_key{}, group_key{};
};

ModelWorld::ModelWorld(const Suite& suite, const SuiteModel& model, std::uint64_t seed)
    : impl_(std::make_unique<Impl>()) {
  const std::uint64_t base = random::derive_seed(seed, kRefereeStream);
  impl_->measurement_key = random::key_from_seed(random::derive_seed(base, kMeasurementStream));
  impl_->group_key = random::key_from_seed(random::derive_seed(base, random::kGroupSeedStream));
  const MeasurementNoise& m = model.measurement_noise;
  impl_->measurement_sd = Vector3(m.xy_m, m.xy_m, m.theta_rad);
  const EffectList effects = world_effects(model.effects);
  const GroupTarget target = group_target(model.effects);
  const double B = model.robot.wheelbase_m;
  const bool per_run_heading = effect_needs(model.effects).start_heading;
  std::vector<std::string> group_names;
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const SuiteExperiment& ex = suite.experiments[e];
    const std::string key = group_key(ex);
    auto found = std::find(group_names.begin(), group_names.end(), key);
    const int group = static_cast<int>(found - group_names.begin());
    if (found == group_names.end()) group_names.push_back(key);
    const std::uint64_t experiment_seed = random::derive_seed(base, e);
    if (!ex.logged && !per_run_heading) {
      std::vector<double> durations;
      const std::vector<ArcSegment> pieces = path_model_pieces(ex.path, B, model.effects, &durations);
      impl_->units.push_back({Simulator(model.robot, ex.path, effects), experiment_seed,
                              impl_->runs, ex.runs.size(), group,
                              group_shift(pieces, durations, model, target, 0.0)});
      impl_->runs += ex.runs.size();
      continue;
    }
    if (!ex.logged) {  // an effect uses the absolute heading: each run from its own start heading
      std::vector<double> durations;
      const std::vector<ArcSegment> pieces = path_model_pieces(ex.path, B, model.effects, &durations);
      for (std::size_t r = 0; r < ex.runs.size(); ++r) {
        const double heading0 = ex.runs[r].heading0_rad;
        impl_->units.push_back({Simulator(model.robot, ex.path, effects, heading0),
                                random::derive_seed(experiment_seed, r), impl_->runs, 1, group,
                                group_shift(pieces, durations, model, target, heading0)});
        impl_->runs += 1;
      }
      continue;
    }
    for (std::size_t r = 0; r < ex.runs.size(); ++r) {
      const SuiteRun& run = ex.runs[r];
      impl_->units.push_back({Simulator(model.robot, run.pieces, run.durations_s, effects, run.heading0_rad),
                              random::derive_seed(experiment_seed, r), impl_->runs, 1, group,
                              group_shift(run.pieces, run.durations_s, model, target, run.heading0_rad)});
      impl_->runs += 1;
    }
  }
  impl_->groups = static_cast<int>(group_names.size());
}

ModelWorld::~ModelWorld() = default;
ModelWorld::ModelWorld(ModelWorld&&) noexcept = default;
ModelWorld& ModelWorld::operator=(ModelWorld&&) noexcept = default;

std::size_t ModelWorld::runs() const { return impl_->runs; }

void ModelWorld::errors(std::int64_t first, std::int64_t count, std::vector<Vector3>& out) const {
  const Impl& w = *impl_;
  out.assign(static_cast<std::size_t>(count) * w.runs, Vector3::Zero());
  // The simulators, unit by unit (each one's runs in parallel inside it as well).
  tbb::parallel_for(std::size_t{0}, w.units.size(), [&](std::size_t u) {
    const Unit& unit = w.units[u];
    const auto n = static_cast<std::int64_t>(unit.runs);
    if (n == 0) return;
    const std::vector<Vector3> e = unit.simulator.errors(unit.seed, first * n, count * n, 0);
    for (std::int64_t b = 0; b < count; ++b) {
      for (std::int64_t i = 0; i < n; ++i) {
        out[static_cast<std::size_t>(b) * w.runs + unit.first_run + static_cast<std::size_t>(i)] =
            e[static_cast<std::size_t>(b * n + i)];
      }
    }
  });
  // Then the group draws and the reference's noise, replicate by replicate.
  tbb::parallel_for(std::int64_t{0}, count, [&](std::int64_t b) {
    const auto replicate = static_cast<std::uint64_t>(first + b);
    Vector3* row = out.data() + static_cast<std::size_t>(b) * w.runs;
    for (const Unit& unit : w.units) {
      if (!unit.shift.present) continue;
      const double z = random::normal_at(w.group_key, replicate,
                                         static_cast<std::uint32_t>(unit.group), random::kTagGroup);
      const Vector3 shift = unit.shift.at(z);
      for (std::size_t i = 0; i < unit.runs; ++i) row[unit.first_run + i] += shift;
    }
    for (std::size_t i = 0; i < w.runs; ++i) {
      for (std::uint32_t c = 0; c < 3; ++c) {
        if (!(w.measurement_sd(c) > 0)) continue;
        row[i](c) += w.measurement_sd(c) *
                     random::normal_at(w.measurement_key, replicate,
                                       static_cast<std::uint32_t>(3 * i) + c, random::kTagMeasurement);
      }
      row[i].z() = wrap_angle(row[i].z());
    }
  });
}

}  // namespace odomcov
