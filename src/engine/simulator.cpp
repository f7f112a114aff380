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
  std::vector<std::unique_ptr<effects::Effect>> effects;
  std::vector<const effects::Effect*> measuring;  // effects with a measurement hook
  lanes::Plan plan;
  std::int64_t samples = 0;
  Vector3 odometry_pose = Vector3::Zero();

  Impl(const Robot& robot, const std::vector<SampleRun>& schedule, const EffectList& effect_list,
       double heading0_rad)
      : effects(effects::instantiate(effect_list)),
        plan(lanes::make_plan(robot, schedule, effects, heading0_rad)) {
    double max_travel = 0.0;
    for (const Leg& leg : plan.legs) {
      samples += leg.count;
      max_travel = std::max(max_travel, leg.event_travel);
    }
    for (std::size_t e = 0; e < effects.size(); ++e) {
      if (effects[e]->measures()) measuring.push_back(effects[e].get());
      if (const std::string why = effects[e]->check_samples(max_travel); !why.empty()) {
        throw EffectError("effects[" + std::to_string(e) + "]." + effect_list[e].name, why);
      }
    }
    // The odometry: the nominal motion through the same integrator with zero noise, so with
    // no effects and k = 0 the error is exactly zero.
    const lanes::EndPose end = lanes::odometry_run(lanes::make_plan(robot, schedule, {}));
    odometry_pose = {end.x, end.y, end.theta};
  }

  /// The error the external reference sees: the true end pose through the measurement hooks,
  /// minus the odometry.
  Vector3 error_of(const lanes::EndPose& end) const {
    Vector3 pose(end.x, end.y, end.theta);
    for (const effects::Effect* e : measuring) e->measure(pose);
    return pose_error(pose, odometry_pose);
  }

  /// The errors of runs first .. first+count-1 (count <= kMaxRuns) by the selected SIMD kernel,
  /// or run by run by the scalar reference when the legs change per run (their lanes would not
  /// share a leg).
  void run_errors(const random::Philox::key_type& key, std::uint64_t first, std::size_t count,
                  Vector3* out) const {
    std::array<lanes::EndPose, lanes::kMaxRuns> ends;
    if (plan.per_run_legs()) {
      for (std::size_t j = 0; j < count; ++j) ends[j] = lanes::reference_run(plan, key, first + j);
    } else {
      kernel().run(plan, key, first, count, ends.data());
    }
    for (std::size_t j = 0; j < count; ++j) out[j] = error_of(ends[j]);
  }
};

Simulator::Simulator(const Robot& robot, const Path& path, const EffectList& effects,
                     double heading0_rad)
    : impl_(std::make_unique<Impl>(robot, sample_schedule(path), effects, heading0_rad)) {}

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
                     const std::vector<double>& durations_s, const EffectList& effects,
                     double heading0_rad)
    : impl_(std::make_unique<Impl>(robot, piece_schedule(pieces, durations_s), effects,
                                   heading0_rad)) {}
Simulator::~Simulator() = default;
Simulator::Simulator(Simulator&&) noexcept = default;
Simulator& Simulator::operator=(Simulator&&) noexcept = default;

Vector3 Simulator::odometry_end_pose() const { return impl_->odometry_pose; }
std::int64_t Simulator::samples_per_run() const { return impl_->samples; }

Vector3 Simulator::reference_error(std::uint64_t seed, std::int64_t run) const {
  return impl_->error_of(lanes::reference_run(impl_->plan, random::key_from_seed(seed),
                                              static_cast<std::uint64_t>(run)));
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
