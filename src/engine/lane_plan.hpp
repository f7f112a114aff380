// What the simulator's kernels read: the legs of the true motion, each effect's world side per
// leg as a short list of operations, and the kernel entry points of every compiled instruction
// set. Built once per Simulator (never per run); the scalar reference kernel (simulator.cpp) and
// the SIMD kernels (lane_kernel-inl.hpp, one copy per target) run the same plan with the same
// arithmetic, so they agree bit for bit.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "base/random.hpp"
#include "effects/effect.hpp"
#include "engine/arc_step.hpp"

namespace odomcov::lanes {

/// One operation of the stochastic effects on a sample, in the order the effects are listed.
struct LaneOp {
  enum Kind : std::uint8_t { kTerm, kEvent };
  Kind kind = kTerm;
  std::uint8_t wheel = 0;    // term: 0 left, 1 right
  bool per_run = false;      // term: value is a run value (else a per-sample normal)
  std::uint8_t effect = 0;   // index into Plan::stochastic
  std::uint32_t index = 0;   // term: run value index, or index into the leg's draws
  double a = 1.0, b = 1.0;   // term: extra[wheel] += (value x a) x b
};

/// A noise mix of one effect: z_R <- from_left z_L + from_right z_R.
struct NoiseMix {
  double from_left = 0.0, from_right = 1.0;
};

/// A leg as the kernels see it.
struct Leg : arc::LegStep {
  std::int64_t count = 0;
  double sigma_left = 0.0;   // kL sqrt|L|
  double sigma_right = 0.0;  // kR sqrt|R|
  double event_travel = 0.0;  // (|dL| + |dR|)/2: what event countdowns lose per sample
  std::uint32_t draws_begin = 0, draws_end = 0;  // Plan::draw_tags of the per-sample normals
  std::uint32_t ops_begin = 0, ops_end = 0;      // Plan::ops
};

/// The end of one run in the start frame (the simulator applies the measurement hooks and
/// subtracts the odometry).
struct EndPose {
  double x, y, theta;
};

/// What a leg was built from, for a plan whose legs change per run (Plan::per_run_legs).
struct LegSource {
  ArcSegment increment;
  effects::Motion motion;    // of the leg's first sample
  effects::Systematic sys;   // every effect's terms but the per-run ones
};

struct Plan {
  std::vector<Leg> legs;
  std::uint32_t samples = 0;  // per run
  // The general kernel's data (empty without stochastic effects).
  std::vector<const effects::Effect*> stochastic;  // the effects with world-side randomness
  std::vector<std::uint32_t> slots;                // each one's index in the effect list
  std::vector<NoiseMix> mixes;                     // in effect order
  std::vector<std::uint32_t> draw_tags;            // per leg: Philox tags of its sample normals
  std::vector<LaneOp> ops;                         // per leg, in effect order
  std::vector<std::uint8_t> event_effects;         // indices into `stochastic` with events
  // Effects whose systematic terms depend on the run's draws (a custom effect's `random:`
  // parameters; indices into `stochastic`): each run rebuilds every leg from its source with
  // their terms composed in (run_leg; the SIMD kernel loads them per lane).
  std::vector<std::uint8_t> per_run_terms;
  std::vector<LegSource> sources;  // per leg, when per_run_terms is not empty
  Robot robot;

  bool general() const { return !stochastic.empty(); }
  bool per_run_legs() const { return !per_run_terms.empty(); }
};

/// The plan of a schedule of samples through these effects (which must outlive it): the legs
/// with every systematic factor folded in, and the stochastic effects' operations per leg.
/// `heading0_rad`: the run's start heading in the reference's frame (effects' `heading`).
Plan make_plan(const Robot& robot, const std::vector<SampleRun>& schedule,
               const std::vector<std::unique_ptr<effects::Effect>>& effects,
               double heading0_rad = 0.0);

/// One run by the scalar reference kernel: plain C++, run by run, what every SIMD target must
/// match bit for bit.
EndPose reference_run(const Plan& plan, const random::Philox::key_type& key, std::uint64_t run);

/// Leg i of a plan whose legs change per run (Plan::per_run_legs) as one run sees it: its source's
/// terms composed with those of the effects whose terms depend on the run's draws, `states` the
/// run's RunState of each stochastic effect (indexed as Plan::stochastic; one sin and cos, nothing
/// allocated). Its draws, operations and count are the path leg's. The reference builds each leg
/// of a run so; the SIMD kernel builds one per lane into its block's leg table.
Leg run_leg(const Plan& plan, std::size_t i, const effects::RunState* states);

/// The plan's motion with zero noise (a plan without stochastic effects): the odometry.
EndPose odometry_run(const Plan& plan);

/// Runs first .. first+count-1 of the plan (count <= kMaxRuns), writing their end poses.
using KernelFn = void (*)(const Plan& plan, const random::Philox::key_type& key,
                          std::uint64_t first, std::size_t count, EndPose* out);
inline constexpr std::size_t kMaxRuns = 64;
/// The most per-sample normals one leg draws for its effects.
inline constexpr std::size_t kMaxDraws = 8;

/// The normals of `count` words (random::normal_from_word, every word in turn), as a target
/// computes them: tests and bench/normal_icdf_accuracy hold each target to the scalar bits.
using NormalsFn = void (*)(const std::uint32_t* words, std::size_t count, float* out);

/// One compiled instruction set's kernel.
struct Target {
  const char* name;
  std::int64_t bit;      // Highway's target bit
  std::size_t lanes;     // doubles per vector
  std::size_t block;     // runs advanced in lock step
  KernelFn run;
  NormalsFn normals;
};

/// Every target compiled into this build (best first) that this CPU supports.
std::vector<Target> supported_targets();

}  // namespace odomcov::lanes
