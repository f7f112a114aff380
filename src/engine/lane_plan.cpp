#include "engine/lane_plan.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

namespace odomcov::lanes {
namespace {

/// A leg of the true motion and what the effects see of it.
struct BuiltLeg {
  Leg leg;
  effects::LegView view;
  LegSource source;
};

BuiltLeg make_leg(std::int64_t count, const ArcSegment& increment, const effects::Systematic& sys,
                  const Robot& robot) {
  BuiltLeg b;
  Leg& leg = b.leg;
  leg.count = count;
  const ArcSegment travel = sys.travel(increment.left_m, increment.right_m);
  const double wheelbase_true = sys.wheelbase_factor * robot.wheelbase_m;
  leg.center_m = travel.center_m();
  leg.half_rad = 0.5 * travel.heading_change_rad(wheelbase_true);
  leg.cos_half = std::cos(leg.half_rad);
  leg.sin_half = std::sin(leg.half_rad);
  // the white noise variance k^2 |increment| times the effects' noise factor
  const Eigen::Vector2d variance = wheel_variances(increment, robot.noise) * sys.noise_factor;
  leg.sigma_left = std::sqrt(variance.x());
  leg.sigma_right = std::sqrt(variance.y());
  leg.inv_two_b = 1.0 / (2.0 * wheelbase_true);
  leg.series_sinc = std::abs(leg.half_rad) <= arc::kSincSeriesMax;
  leg.short_series = arc::short_series_for(leg.half_rad, leg.sigma_left, leg.sigma_right, leg.inv_two_b);
  leg.event_travel = 0.5 * (std::abs(increment.left_m) + std::abs(increment.right_m));
  leg.lateral_m = sys.lateral * leg.event_travel;
  b.view = {increment.left_m, increment.right_m, robot.wheelbase_m,
            travel.left_m,    travel.right_m,    wheelbase_true};
  return b;
}

BuiltLeg make_leg(std::int64_t count, const ArcSegment& increment, const effects::Motion& motion,
                  const effects::Systematic& sys, const Robot& robot) {
  BuiltLeg b = make_leg(count, increment, sys, robot);
  b.source = {increment, motion, sys};
  return b;
}

/// The legs of the true motion: each sample's systematic factors from its Motion, once per leg
/// of equal samples when no effect depends on the history, else sample by sample with equal
/// neighbours merged (a leg of a planned path then splits only where the factors change, e.g.
/// while backlash is taken up). Effects whose terms depend on the run's draws are left out
/// (reference_run composes them per run); when one of them depends on the history, no two
/// samples merge (their terms may differ in another run).
std::vector<BuiltLeg> make_legs(const std::vector<SampleRun>& schedule, const Robot& robot,
                                const std::vector<std::unique_ptr<effects::Effect>>& list,
                                double heading0_rad) {
  effects::Dependence dependence = effects::Dependence::none;
  bool merge = true;
  for (const auto& e : list) {
    dependence = std::max(dependence, e->dependence());
    merge = merge && !(e->per_run_systematic() && e->dependence() == effects::Dependence::history);
  }
  const bool per_sample = dependence == effects::Dependence::history;
  auto factors = [&](const effects::Motion& m) {
    effects::Systematic sys;
    for (const auto& e : list) {
      if (!e->per_run_systematic()) e->systematic(m, sys);
    }
    return sys;
  };
  effects::MotionTracker tracker(robot.wheelbase_m, heading0_rad);
  std::vector<BuiltLeg> out;
  effects::Systematic last;
  for (const SampleRun& run : schedule) {
    const ArcSegment& inc = run.increment;
    if (!per_sample) {
      const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s, run.count);
      out.push_back(make_leg(run.count, inc, m, factors(m), robot));
      continue;
    }
    for (std::int64_t i = 0; i < run.count; ++i) {
      const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s);
      const effects::Systematic sys = factors(m);
      if (merge && i > 0 && sys == last) {
        ++out.back().leg.count;
      } else {
        out.push_back(make_leg(1, inc, m, sys, robot));
      }
      last = sys;
    }
  }
  return out;
}

/// The stochastic effects of a plan, and their operations per leg.
class OpsBuilder {
 public:
  explicit OpsBuilder(Plan& plan) : plan_(plan) {}

  /// The stochastic effects' operations on one leg, in effect order; their per-sample normals
  /// become the leg's draws (one Philox tag each).
  void add(Leg& leg, const effects::LegView& view) {
    leg.draws_begin = static_cast<std::uint32_t>(plan_.draw_tags.size());
    leg.ops_begin = static_cast<std::uint32_t>(plan_.ops.size());
    for (std::size_t e = 0; e < plan_.stochastic.size(); ++e) {
      terms_.clear();
      plan_.stochastic[e]->terms(view, terms_);
      for (const effects::TravelTerm& t : terms_) {
        LaneOp op;
        op.wheel = static_cast<std::uint8_t>(t.wheel);
        op.per_run = t.per_run;
        op.effect = static_cast<std::uint8_t>(e);
        op.index = t.per_run ? t.index
                             : draw_slot(leg, random::kTagEffect | plan_.slots[e] << 8 | t.index);
        op.a = t.a;
        op.b = t.b;
        plan_.ops.push_back(op);
      }
      if (plan_.stochastic[e]->events()) {
        LaneOp op;
        op.kind = LaneOp::kEvent;
        op.effect = static_cast<std::uint8_t>(e);
        plan_.ops.push_back(op);
      }
    }
    leg.draws_end = static_cast<std::uint32_t>(plan_.draw_tags.size());
    leg.ops_end = static_cast<std::uint32_t>(plan_.ops.size());
  }

 private:
  /// The position of `tag` among the leg's draws (added when new).
  std::uint32_t draw_slot(const Leg& leg, std::uint32_t tag) {
    for (std::size_t d = leg.draws_begin; d < plan_.draw_tags.size(); ++d) {
      if (plan_.draw_tags[d] == tag) return static_cast<std::uint32_t>(d - leg.draws_begin);
    }
    if (plan_.draw_tags.size() - leg.draws_begin >= kMaxDraws) {
      throw std::logic_error("Simulator: more than " + std::to_string(kMaxDraws) +
                             " per-sample normals on one leg");
    }
    plan_.draw_tags.push_back(tag);
    return static_cast<std::uint32_t>(plan_.draw_tags.size() - 1 - leg.draws_begin);
  }

  Plan& plan_;
  std::vector<effects::TravelTerm> terms_;
};

/// The extra travel of the stochastic effects on one sample, the noise mixes applied to z first
/// (what the SIMD kernel does lane by lane, in the same order).
struct RunEffects {
  std::array<effects::RunState, kMaxEffects> states{};
  std::array<effects::Draws, kMaxEffects> draws;
};

void reference_effects(const Plan& plan, const Leg& leg, std::uint32_t n,
                       const random::Philox::key_type& key, std::uint64_t run, RunEffects& fx,
                       double& zl, double& zr, std::array<double, 2>& extra) {
  for (const NoiseMix& m : plan.mixes) zr = m.from_left * zl + m.from_right * zr;
  std::array<double, kMaxDraws> z{};
  for (std::uint32_t d = leg.draws_begin; d < leg.draws_end; ++d) {
    z[d - leg.draws_begin] = random::normal_at(key, run, n, plan.draw_tags[d]);
  }
  extra = {0.0, 0.0};
  for (std::uint32_t o = leg.ops_begin; o < leg.ops_end; ++o) {
    const LaneOp& op = plan.ops[o];
    effects::RunState& state = fx.states[op.effect];
    if (op.kind == LaneOp::kEvent) {
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

}  // namespace

Plan make_plan(const Robot& robot, const std::vector<SampleRun>& schedule,
               const std::vector<std::unique_ptr<effects::Effect>>& effects, double heading0_rad) {
  Plan plan;
  plan.robot = robot;
  for (std::size_t e = 0; e < effects.size(); ++e) {
    const effects::Effect& effect = *effects[e];
    if (!effect.stochastic()) continue;
    if (effect.per_run_systematic()) plan.per_run_terms.push_back(static_cast<std::uint8_t>(plan.stochastic.size()));
    plan.stochastic.push_back(&effect);
    plan.slots.push_back(static_cast<std::uint32_t>(e));
    NoiseMix mix;
    if (effect.noise_mix(mix.from_left, mix.from_right)) plan.mixes.push_back(mix);
  }
  OpsBuilder ops(plan);
  for (BuiltLeg& b : make_legs(schedule, robot, effects, heading0_rad)) {
    if (plan.general()) ops.add(b.leg, b.view);
    plan.samples += static_cast<std::uint32_t>(b.leg.count);
    plan.legs.push_back(b.leg);
    if (plan.per_run_legs()) plan.sources.push_back(b.source);
  }
  return plan;
}

Leg run_leg(const Plan& plan, std::size_t i, const effects::RunState* states) {
  const LegSource& src = plan.sources[i];
  effects::Systematic sys = src.sys;
  for (const std::uint8_t e : plan.per_run_terms) {
    plan.stochastic[e]->run_systematic(src.motion, states[e], sys);
  }
  const Leg& path_leg = plan.legs[i];
  Leg leg = make_leg(path_leg.count, src.increment, sys, plan.robot).leg;
  leg.draws_begin = path_leg.draws_begin, leg.draws_end = path_leg.draws_end;
  leg.ops_begin = path_leg.ops_begin, leg.ops_end = path_leg.ops_end;
  return leg;
}

EndPose reference_run(const Plan& plan, const random::Philox::key_type& key, std::uint64_t run) {
  arc::Pose<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
  RunEffects fx;
  for (std::size_t i = 0; i < plan.stochastic.size(); ++i) {
    fx.draws[i] = effects::Draws(key, run, plan.slots[i]);
    plan.stochastic[i]->begin_run(fx.states[i], fx.draws[i]);
  }
  std::uint32_t n = 0;
  float quad[8] = {};  // the wheels' normals of the quad of samples n belongs to: left, right
  Leg this_run;  // a leg rebuilt for this run's draws (per_run_legs)
  for (std::size_t l = 0; l < plan.legs.size(); ++l) {
    if (plan.per_run_legs()) this_run = run_leg(plan, l, fx.states.data());
    const Leg& leg = plan.per_run_legs() ? this_run : plan.legs[l];
    for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
      if ((n & 3) == 0) {  // a quad's words: the wheels' next four samples
        const random::Philox::ctr_type left = random::draw4(key, run, n >> 2, random::kTagWheelLeft);
        const random::Philox::ctr_type right = random::draw4(key, run, n >> 2, random::kTagWheelRight);
        const std::uint32_t words[8] = {left[0], left[1], left[2], left[3], right[0], right[1], right[2], right[3]};
        random::normals_from_words(words, quad);
      }
      double zl = quad[n & 3];
      double zr = quad[4 + (n & 3)];
      double noise_l = 0.0, noise_r = 0.0;
      if (plan.general()) {
        std::array<double, 2> extra{};
        reference_effects(plan, leg, n, key, run, fx, zl, zr, extra);
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

EndPose odometry_run(const Plan& plan) {
  arc::Pose<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
  std::uint32_t n = 0;
  for (const Leg& leg : plan.legs) {
    for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
      arc::step(p, leg, 0.0, 0.0);
      if ((n & arc::kRenormMask) == arc::kRenormMask) arc::renormalise(p);
    }
  }
  return {p.x, p.y, p.theta};
}

}  // namespace odomcov::lanes
