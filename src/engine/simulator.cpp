#include "odomcov/engine/simulator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "base/random.hpp"
#include "effects/effect.hpp"
#include "engine/arc_step.hpp"
#include "engine/lane_plan.hpp"

namespace odomcov {
namespace {

using lanes::Leg;

// ---------------------------------------------------------------------------------------------
// Kernel selection: the best SIMD target this CPU supports (lane_kernels.cpp), or the one named
// by Simulator::select_kernel or, at the first simulation, by the environment variable
// ODOMCOV_SIMD (a name of Simulator::kernel_targets()).
// ---------------------------------------------------------------------------------------------

const std::vector<lanes::Target>& targets() {
  static const std::vector<lanes::Target> list = lanes::supported_targets();
  return list;
}

const lanes::Target* find_target(const std::string& name) {
  for (const lanes::Target& t : targets()) {
    if (name == t.name) return &t;
  }
  return nullptr;
}

const lanes::Target* initial_target() {
  const char* env = std::getenv("ODOMCOV_SIMD");
  const lanes::Target* named = env != nullptr && *env != '\0' ? find_target(env) : nullptr;
  return named != nullptr ? named : &targets().front();
}

std::atomic<const lanes::Target*>& chosen_target() {
  static std::atomic<const lanes::Target*> chosen{initial_target()};
  return chosen;
}

const lanes::Target& kernel() { return *chosen_target().load(std::memory_order_relaxed); }

/// Runs per unit of the reduction tree (and of the parallel loops).
constexpr std::int64_t kGroup = 8;

}  // namespace

struct Simulator::Impl {
  Robot robot;
  std::vector<std::unique_ptr<effects::Effect>> effects;
  std::vector<const effects::Effect*> measuring;  // effects with a measurement hook
  lanes::Plan plan;
  std::int64_t samples = 0;
  Vector3 odometry_pose = Vector3::Zero();

  /// A leg of the true motion and what the effects see of it.
  struct BuiltLeg {
    Leg leg;
    effects::LegView view;
  };

  static BuiltLeg make_leg(std::int64_t count, const ArcSegment& increment,
                           const effects::Systematic& sys, const Robot& robot) {
    BuiltLeg b;
    Leg& leg = b.leg;
    leg.count = count;
    const ArcSegment travel = sys.travel(increment.left_m, increment.right_m);
    const double wheelbase_true = sys.wheelbase_factor * robot.wheelbase_m;
    leg.center_m = travel.center_m();
    leg.half_rad = 0.5 * travel.heading_change_rad(wheelbase_true);
    leg.cos_half = std::cos(leg.half_rad);
    leg.sin_half = std::sin(leg.half_rad);
    const Eigen::Vector2d variance = wheel_variances(increment, robot.noise);
    leg.sigma_left = std::sqrt(variance.x());
    leg.sigma_right = std::sqrt(variance.y());
    leg.inv_two_b = 1.0 / (2.0 * wheelbase_true);
    leg.series_sinc = std::abs(leg.half_rad) <= arc::kSincSeriesMax;
    leg.event_travel = 0.5 * (std::abs(increment.left_m) + std::abs(increment.right_m));
    b.view = {increment.left_m, increment.right_m, robot.wheelbase_m,
              travel.left_m,    travel.right_m,    wheelbase_true};
    return b;
  }

  /// The legs of the true motion: each sample's systematic factors from its Motion, once per
  /// leg of equal samples when no effect depends on the history, else sample by sample with
  /// equal neighbours merged (a leg of a planned path then splits only where the factors
  /// change, e.g. while backlash is taken up). Built once per path, never per run.
  static std::vector<BuiltLeg> make_legs(const std::vector<SampleRun>& schedule,
                                         const Robot& robot,
                                         const std::vector<std::unique_ptr<effects::Effect>>& list) {
    effects::Dependence dependence = effects::Dependence::none;
    for (const auto& e : list) dependence = std::max(dependence, e->dependence());
    const bool per_sample = dependence == effects::Dependence::history;
    auto factors = [&](const effects::Motion& m) {
      effects::Systematic sys;
      for (const auto& e : list) e->systematic(m, sys);
      return sys;
    };
    effects::MotionTracker tracker(robot.wheelbase_m);
    std::vector<BuiltLeg> out;
    effects::Systematic last;
    for (const SampleRun& run : schedule) {
      const ArcSegment& inc = run.increment;
      if (!per_sample) {
        const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s, run.count);
        out.push_back(make_leg(run.count, inc, factors(m), robot));
        continue;
      }
      for (std::int64_t i = 0; i < run.count; ++i) {
        const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s);
        const effects::Systematic sys = factors(m);
        if (i > 0 && sys == last) {
          ++out.back().leg.count;
        } else {
          out.push_back(make_leg(1, inc, sys, robot));
        }
        last = sys;
      }
    }
    return out;
  }

  /// The stochastic effects' operations on one leg, in effect order; their per-sample normals
  /// become the leg's draws (one Philox tag each).
  void add_ops(Leg& leg, const effects::LegView& view) {
    leg.draws_begin = static_cast<std::uint32_t>(plan.draw_tags.size());
    leg.ops_begin = static_cast<std::uint32_t>(plan.ops.size());
    std::vector<effects::TravelTerm> terms;
    for (std::size_t e = 0; e < plan.stochastic.size(); ++e) {
      terms.clear();
      plan.stochastic[e]->terms(view, terms);
      for (const effects::TravelTerm& t : terms) {
        lanes::LaneOp op;
        op.wheel = static_cast<std::uint8_t>(t.wheel);
        op.per_run = t.per_run;
        op.effect = static_cast<std::uint8_t>(e);
        op.index = t.per_run ? t.index : draw_slot(leg, random::kTagEffect | plan.slots[e] << 8 | t.index);
        op.a = t.a;
        op.b = t.b;
        plan.ops.push_back(op);
      }
      if (plan.stochastic[e]->events()) {
        lanes::LaneOp op;
        op.kind = lanes::LaneOp::kEvent;
        op.effect = static_cast<std::uint8_t>(e);
        plan.ops.push_back(op);
      }
    }
    leg.draws_end = static_cast<std::uint32_t>(plan.draw_tags.size());
    leg.ops_end = static_cast<std::uint32_t>(plan.ops.size());
  }

  /// The position of `tag` among the leg's draws (added when new).
  std::uint32_t draw_slot(const Leg& leg, std::uint32_t tag) {
    for (std::uint32_t d = leg.draws_begin; d < plan.draw_tags.size(); ++d) {
      if (plan.draw_tags[d] == tag) return d - leg.draws_begin;
    }
    if (plan.draw_tags.size() - leg.draws_begin >= lanes::kMaxDraws) {
      throw std::logic_error("Simulator: more than " + std::to_string(lanes::kMaxDraws) +
                             " per-sample normals on one leg");
    }
    plan.draw_tags.push_back(tag);
    return static_cast<std::uint32_t>(plan.draw_tags.size() - 1 - leg.draws_begin);
  }

  void add_effects() {
    for (std::size_t e = 0; e < effects.size(); ++e) {
      const effects::Effect& effect = *effects[e];
      if (effect.measures()) measuring.push_back(&effect);
      if (!effect.stochastic()) continue;
      plan.stochastic.push_back(&effect);
      plan.slots.push_back(static_cast<std::uint32_t>(e));
      lanes::NoiseMix mix;
      if (effect.noise_mix(mix.from_left, mix.from_right)) plan.mixes.push_back(mix);
    }
  }

  Impl(const Robot& r, const std::vector<SampleRun>& schedule, const EffectList& effect_list)
      : robot(r), effects(effects::instantiate(effect_list)) {
    add_effects();
    double max_travel = 0.0;
    for (BuiltLeg& b : make_legs(schedule, robot, effects)) {
      if (plan.general()) add_ops(b.leg, b.view);
      samples += b.leg.count;
      max_travel = std::max(max_travel, b.leg.event_travel);
      plan.legs.push_back(b.leg);
    }
    for (std::size_t e = 0; e < effects.size(); ++e) {
      if (const std::string why = effects[e]->check_samples(max_travel); !why.empty()) {
        throw EffectError("effects[" + std::to_string(e) + "]." + effect_list[e].name, why);
      }
    }
    // The odometry: the nominal motion through the same integrator with zero noise, so with
    // no effects and k = 0 the error is exactly zero.
    arc::Pose<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
    std::uint32_t n = 0;
    for (const BuiltLeg& b : make_legs(schedule, robot, {})) {
      for (std::int64_t i = 0; i < b.leg.count; ++i, ++n) {
        arc::step(p, b.leg, 0.0, 0.0);
        if ((n & arc::kRenormMask) == arc::kRenormMask) arc::renormalise(p);
      }
    }
    odometry_pose = {p.x, p.y, p.theta};
  }

  /// The error the external reference sees: the true end pose through the measurement hooks,
  /// minus the odometry.
  Vector3 error_of(const lanes::EndPose& end) const {
    Vector3 pose(end.x, end.y, end.theta);
    for (const effects::Effect* e : measuring) e->measure(pose);
    return pose_error(pose, odometry_pose);
  }

  // ---- The scalar reference kernel -----------------------------------------------------------
  // Run by run, in plain C++ over the same plan: what every SIMD target must match bit for bit.

  /// Per-run state of the stochastic effects (fixed size: nothing is allocated per run).
  struct RunEffects {
    std::array<effects::RunState, kMaxEffects> states{};
    std::array<effects::Draws, kMaxEffects> draws;
  };

  /// The extra travel of the stochastic effects on one sample (noise mixes applied to z first).
  void scalar_effects(const Leg& leg, std::uint32_t n, const random::Philox::key_type& key,
                      std::uint64_t run, RunEffects& fx, double& zl, double& zr,
                      std::array<double, 2>& extra) const {
    for (const lanes::NoiseMix& m : plan.mixes) zr = m.from_left * zl + m.from_right * zr;
    std::array<double, lanes::kMaxDraws> z{};
    for (std::uint32_t d = leg.draws_begin; d < leg.draws_end; ++d) {
      z[d - leg.draws_begin] = random::normal_at(key, run, n, plan.draw_tags[d]);
    }
    extra = {0.0, 0.0};
    for (std::uint32_t o = leg.ops_begin; o < leg.ops_end; ++o) {
      const lanes::LaneOp& op = plan.ops[o];
      effects::RunState& state = fx.states[op.effect];
      if (op.kind == lanes::LaneOp::kEvent) {
        state.value[0] = state.value[0] - leg.event_travel;
        if (state.value[0] <= 0.0) {
          plan.stochastic[op.effect]->event(n, state, fx.draws[op.effect], extra[0], extra[1]);
        }
        continue;
      }
      const double value = op.per_run ? state.value[op.index] : z[op.index];
      extra[op.wheel] = extra[op.wheel] + (value * op.a) * op.b;
    }
  }

  lanes::EndPose scalar_run(const random::Philox::key_type& key, std::uint64_t run) const {
    arc::Pose<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
    RunEffects fx;
    for (std::size_t i = 0; i < plan.stochastic.size(); ++i) {
      fx.draws[i] = effects::Draws(key, run, plan.slots[i]);
      plan.stochastic[i]->begin_run(fx.states[i], fx.draws[i]);
    }
    std::uint32_t n = 0;
    for (const Leg& leg : plan.legs) {
      for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
        const random::Bits128 b = random::draw(key, run, n, random::kTagWheelNoise);
        double zl = random::normal(b.lo, key, run, n, random::kTagWheelRetry + 0);
        double zr = random::normal(b.hi, key, run, n, random::kTagWheelRetry + 1);
        double noise_l = 0.0, noise_r = 0.0;
        if (plan.general()) {
          std::array<double, 2> extra{};
          scalar_effects(leg, n, key, run, fx, zl, zr, extra);
          noise_l = leg.sigma_left * zl + extra[0];
          noise_r = leg.sigma_right * zr + extra[1];
        } else {
          noise_l = leg.sigma_left * zl;
          noise_r = leg.sigma_right * zr;
        }
        arc::step(p, leg, noise_l, noise_r);
        if ((n & arc::kRenormMask) == arc::kRenormMask) arc::renormalise(p);
      }
    }
    return {p.x, p.y, p.theta};
  }

  /// The errors of runs first .. first+count-1 (count <= kMaxRuns) by the selected SIMD kernel.
  void run_errors(const random::Philox::key_type& key, std::uint64_t first, std::size_t count,
                  Vector3* out) const {
    std::array<lanes::EndPose, lanes::kMaxRuns> ends;
    kernel().run(plan, key, first, count, ends.data());
    for (std::size_t j = 0; j < count; ++j) out[j] = error_of(ends[j]);
  }
};

Simulator::Simulator(const Robot& robot, const Path& path, const EffectList& effects)
    : impl_(std::make_unique<Impl>(robot, sample_schedule(path), effects)) {}

namespace {

/// A logged run's schedule: one sample per encoder piece, of the piece's duration.
std::vector<SampleRun> piece_schedule(const std::vector<ArcSegment>& pieces,
                                      const std::vector<double>& durations_s) {
  if (!durations_s.empty() && durations_s.size() != pieces.size()) {
    throw std::invalid_argument("Simulator: " + std::to_string(durations_s.size()) +
                                " durations for " + std::to_string(pieces.size()) + " pieces");
  }
  std::vector<SampleRun> schedule;
  schedule.reserve(pieces.size());
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const double dt = durations_s.empty() ? std::numeric_limits<double>::quiet_NaN() : durations_s[i];
    schedule.push_back({1, pieces[i], dt});
  }
  return schedule;
}

}  // namespace

Simulator::Simulator(const Robot& robot, const std::vector<ArcSegment>& pieces,
                     const std::vector<double>& durations_s, const EffectList& effects)
    : impl_(std::make_unique<Impl>(robot, piece_schedule(pieces, durations_s), effects)) {}
Simulator::~Simulator() = default;
Simulator::Simulator(Simulator&&) noexcept = default;
Simulator& Simulator::operator=(Simulator&&) noexcept = default;

Vector3 Simulator::odometry_end_pose() const { return impl_->odometry_pose; }
std::int64_t Simulator::samples_per_run() const { return impl_->samples; }

Vector3 Simulator::reference_error(std::uint64_t seed, std::int64_t run) const {
  return impl_->error_of(
      impl_->scalar_run(random::key_from_seed(seed), static_cast<std::uint64_t>(run)));
}

namespace {

/// Groups of kGroup runs per leaf of the reduction tree: about 2^20 sample steps, a function of
/// the path only, so the tree (and therefore every rounding) is the same for any thread count
/// and any instruction set.
std::int64_t groups_per_leaf(std::int64_t samples_per_run) {
  const std::int64_t steps_per_group = std::max<std::int64_t>(1, samples_per_run * kGroup);
  return std::clamp<std::int64_t>((std::int64_t{1} << 20) / steps_per_group, 1, 64);
}

template <class F>
auto in_arena(int threads, F&& f) {
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  return arena.execute(std::forward<F>(f));
}

constexpr std::int64_t kChunk = static_cast<std::int64_t>(lanes::kMaxRuns);

}  // namespace

MomentAccumulator Simulator::simulate(std::int64_t runs, std::uint64_t seed, int threads,
                                      Progress* progress) const {
  const auto key = random::key_from_seed(seed);
  const std::int64_t groups = (runs + kGroup - 1) / kGroup;
  const tbb::blocked_range<std::int64_t> range(0, groups, groups_per_leaf(impl_->samples));
  // A leaf adds its runs in run order, in chunks of up to kChunk runs through the kernel.
  auto leaf = [&](const tbb::blocked_range<std::int64_t>& r, MomentAccumulator acc) {
    std::array<Vector3, lanes::kMaxRuns> errors;
    const std::int64_t end = std::min(r.end() * kGroup, runs);
    for (std::int64_t first = r.begin() * kGroup; first < end; first += kChunk) {
      if (progress && progress->cancel.load(std::memory_order_relaxed)) break;
      const std::int64_t count = std::min(kChunk, end - first);
      impl_->run_errors(key, static_cast<std::uint64_t>(first), static_cast<std::size_t>(count),
                        errors.data());
      for (std::int64_t j = 0; j < count; ++j) acc.add(errors[static_cast<std::size_t>(j)]);
      if (progress) progress->runs_done.fetch_add(count, std::memory_order_relaxed);
    }
    return acc;
  };
  return in_arena(threads, [&] {
    return tbb::parallel_deterministic_reduce(range, MomentAccumulator{}, leaf,
                                              [](MomentAccumulator left, const MomentAccumulator& right) {
                                                left.merge(right);
                                                return left;
                                              });
  });
}

std::vector<Vector3> Simulator::errors(std::uint64_t seed, std::int64_t first, std::int64_t count,
                                       int threads) const {
  const auto key = random::key_from_seed(seed);
  std::vector<Vector3> out(static_cast<std::size_t>(count));
  const std::int64_t chunks = (count + kChunk - 1) / kChunk;
  in_arena(threads, [&] {
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, chunks), [&](const tbb::blocked_range<std::int64_t>& r) {
      for (std::int64_t c = r.begin(); c != r.end(); ++c) {
        const std::int64_t offset = c * kChunk;
        impl_->run_errors(key, static_cast<std::uint64_t>(first + offset),
                          static_cast<std::size_t>(std::min(kChunk, count - offset)),
                          out.data() + offset);
      }
    });
  });
  return out;
}

const char* Simulator::kernel_isa() { return kernel().name; }

std::vector<std::string> Simulator::kernel_targets() {
  std::vector<std::string> names;
  for (const lanes::Target& t : targets()) names.emplace_back(t.name);
  return names;
}

void Simulator::select_kernel(const std::string& target) {
  const lanes::Target* t = target.empty() ? &targets().front() : find_target(target);
  if (t == nullptr) {
    std::string known;
    for (const lanes::Target& o : targets()) known += std::string(known.empty() ? "" : ", ") + o.name;
    throw std::invalid_argument("Simulator: no kernel for '" + target + "' on this CPU (" + known + ")");
  }
  chosen_target().store(t, std::memory_order_relaxed);
}

}  // namespace odomcov
