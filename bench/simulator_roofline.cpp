// Cycles per wheel-sample step of the simulator's kernels, part by part and per instruction set
// (docs/performance.md, "Roofline"). Not a Google Benchmark: a dedicated harness that times the
// kernel's own code (it includes src/engine/lane_kernel-inl.hpp, compiled here for every target)
// with the time-stamp counter, on the [Kleeman95] Table III path (1000 samples per run):
//   philox   the wheel draws (Philox4x32-10 on the block's counters: one per wheel and quad of
//            samples)
//   normals  philox + the two normals of each sample by inversion, stored for the steps
//   (inreg   philox + the normals into a register, not stored: the stores' share)
//   step     the arc step alone, on normals read from a table (so without the two parts above)
//   plain    the whole plain kernel (= philox + normals + step + renormalisation + block setup)
//   general  the general kernel with wheel_diameter_ratio, turn_slip and per_run_radius
//   reduce   MomentAccumulator::add per run, divided by the run's samples
//   scalar   the scalar reference kernel (plain and general), run by run
// Each figure is the best of `repeats` timings of 64 runs x 1000 samples. The time-stamp counter
// ticks at a constant rate (the nominal clock), which may differ from the core clock under boost;
// the harness prints its rate and ns per step beside the counts.
//   simulator_roofline [repeats] [target]   (under valgrind: callgrind's Ir per part)
#undef HWY_TARGET_INCLUDE
#define HWY_DISABLED_TARGETS (HWY_SSSE3 | HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128)
#define HWY_TARGET_INCLUDE "simulator_roofline.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "engine/lane_kernel-inl.hpp"
#include "odomcov/engine/statistics.hpp"

#if HWY_ARCH_X86
#include <x86intrin.h>
#endif

#ifndef ODOMCOV_ROOFLINE_ONCE
#define ODOMCOV_ROOFLINE_ONCE
namespace odomcov::roofline {

inline std::uint64_t ticks() {
#if HWY_ARCH_X86
  return __rdtsc();
#else
  return static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
#endif
}

/// What one target's parts cost, in counter ticks per lane-step.
struct Parts {
  double philox, normals, step, plain, general, inreg;
};

/// The plans the harness runs: Table III plain and with the three effects.
struct Plans {
  const lanes::Plan* plain;
  const lanes::Plan* general;
};

}  // namespace odomcov::roofline
#endif

HWY_BEFORE_NAMESPACE();
namespace odomcov::lanes::HWY_NAMESPACE {

using roofline::ticks;

constexpr std::uint64_t kRuns = 64;  // runs per timing (a multiple of every block size)

/// The best of `repeats` timings of f(key), each with another seed's key (so no branch
/// predictor learns one sequence of tail draws).
template <class F>
double best_of(int repeats, std::uint64_t steps, F&& f) {
  double best = std::numeric_limits<double>::infinity();
  for (int r = 0; r < repeats; ++r) {
    const random::Philox::key_type key = random::key_from_seed(static_cast<std::uint64_t>(r) + 1);
    const std::uint64_t t0 = ticks();
    f(key);
    const std::uint64_t t1 = ticks();
    best = std::min(best, static_cast<double>(t1 - t0) / static_cast<double>(steps));
  }
  return best;
}

std::uint64_t samples_of(const Plan& plan) {
  std::uint64_t n = 0;
  for (const Leg& leg : plan.legs) n += static_cast<std::uint64_t>(leg.count);
  return n;
}

HWY_NOINLINE double part_philox(const Plan& plan, const random::Philox::key_type& key) {
  const std::uint64_t samples = samples_of(plan);
  VU sink = hn::Zero(DU());
  for (std::uint64_t first = 0; first < kRuns; first += kBlock) {
    Block<false> block(plan, key, first);
    for (std::uint32_t q = 0; 4 * q < samples; ++q) {
      for (const std::uint32_t tag : {random::kTagWheelLeft, random::kTagWheelRight}) {
        Words w[kK];
        block.draw(q, tag, w);
        for (std::size_t k = 0; k < kK; ++k) sink = hn::Xor3(sink, hn::Xor3(w[k].w0, w[k].w1, w[k].w2), w[k].w3);
      }
    }
  }
  return static_cast<double>(hn::GetLane(sink) & 1);
}

HWY_NOINLINE double part_normals(const Plan& plan, const random::Philox::key_type& key) {
  for (std::uint64_t first = 0; first < kRuns; first += kBlock) {
    Block<false> block(plan, key, first);
    LegCursor at = block.start();
    for (std::uint32_t n = 0; n < plan.samples; n += kChunk) {
      const std::uint32_t count = plan.samples - n < kChunk ? plan.samples - n : kChunk;
      block.draw_chunk(at, n, count);
      for (std::uint32_t s = 0; s < count;) {
        const std::uint32_t m = at.left(count - s);
        at.skip(m);
        s += m;
      }
    }
  }
  return 0.0;
}

HWY_NOINLINE double part_inreg(const Plan& plan, const random::Philox::key_type& key) {
#if HWY_TARGET == HWY_SCALAR
  (void)plan, (void)key;
  return 0.0;  // the fallback converts word by word (random::normal_from_word)
#else
  const std::uint64_t samples = samples_of(plan);
  VecOps::F sink = VecOps::f(0.0f);
  for (std::uint64_t first = 0; first < kRuns; first += kBlock) {
    Block<false> block(plan, key, first);
    for (std::uint32_t q = 0; 4 * q < samples; ++q) {
      for (const std::uint32_t tag : {random::kTagWheelLeft, random::kTagWheelRight}) {
        Words w[kK];
        block.draw(q, tag, w);
        VecOps::F z[2 * kK];
        quad_normals<kK>(w, z);
        for (std::size_t k = 0; k < 2 * kK; ++k) sink = sink + z[k];
      }
    }
  }
  return static_cast<double>(hn::GetLane(sink));
#endif
}

/// The steps alone: one chunk's normals drawn once, then every chunk steps on them.
HWY_NOINLINE double part_step(const Plan& plan, const random::Philox::key_type& key) {
  EndPose out[kBlock];
  for (std::uint64_t first = 0; first < kRuns; first += kBlock) {
    Block<false> block(plan, key, first);
    LegCursor at = block.start();
    block.draw_chunk(at, 0, kChunk);
    for (std::uint32_t n = 0; n < plan.samples; n += kChunk) {
      block.step_chunk(at, n, plan.samples - n < kChunk ? plan.samples - n : kChunk);
    }
    block.write(out, kBlock);
  }
  return out[0].x;
}

HWY_NOINLINE double part_plain(const Plan& plan, const random::Philox::key_type& key) {
  EndPose out[kRuns];
  run_blocks(plan, key, 0, kRuns, out);
  return out[0].x;
}

HWY_NOINLINE double part_general(const Plan& plan, const random::Philox::key_type& key) {
  EndPose out[kRuns];
  run_blocks(plan, key, 0, kRuns, out);
  return out[0].x;
}

roofline::Parts measure(const roofline::Plans& plans, int repeats) {
  const std::uint64_t steps = kRuns * samples_of(*plans.plain);
  volatile double sink = 0.0;
  roofline::Parts p{};
  p.philox = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_philox(*plans.plain, key); });
  p.normals = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_normals(*plans.plain, key); });
  p.inreg = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_inreg(*plans.plain, key); });
  p.step = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_step(*plans.plain, key); });
  p.plain = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_plain(*plans.plain, key); });
  p.general = best_of(repeats, steps, [&](const auto& key) { sink = sink + part_general(*plans.general, key); });
  return p;
}

}  // namespace odomcov::lanes::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE

#include "odomcov/effects/effects.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/measurement/config.hpp"

namespace odomcov::lanes {

using Measure = roofline::Parts (*)(const roofline::Plans&, int);

/// The compiled targets' measure functions (null where not compiled), best first.
std::vector<std::pair<std::int64_t, Measure>> measures() {
  return {{HWY_AVX3, HWY_CHOOSE_AVX3(measure)}, {HWY_AVX2, HWY_CHOOSE_AVX2(measure)},
          {HWY_SSE4, HWY_CHOOSE_SSE4(measure)}, {HWY_NEON, HWY_CHOOSE_NEON(measure)},
          {HWY_SCALAR, HWY_CHOOSE_FALLBACK(measure)}};
}

}  // namespace odomcov::lanes

namespace odomcov::roofline {

double ticks_per_ns() {
  const auto c0 = std::chrono::steady_clock::now();
  const std::uint64_t t0 = ticks();
  while (std::chrono::steady_clock::now() - c0 < std::chrono::milliseconds(200)) {
  }
  const std::uint64_t t1 = ticks();
  const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - c0).count();
  return static_cast<double>(t1 - t0) / ns;
}

template <class F>
double scalar_part(int repeats, std::uint64_t steps, F&& f) {
  double best = std::numeric_limits<double>::infinity();
  for (int r = 0; r < repeats; ++r) {
    const std::uint64_t t0 = ticks();
    f();
    best = std::min(best, static_cast<double>(ticks() - t0) / static_cast<double>(steps));
  }
  return best;
}

int run(int argc, char** argv) {
  const int repeats = argc > 1 ? std::atoi(argv[1]) : 15;
  const std::string only = argc > 2 ? argv[2] : "";
  const Config c = load_config(ODOMCOV_SOURCE_DIR "/configs/kleeman95/table3.yaml");
  const auto schedule = sample_schedule(c.path);
  const auto none = effects::instantiate({});
  const auto three = effects::instantiate(
      {{"wheel_diameter_ratio", {1.004}}, {"turn_slip", {0.0015}}, {"per_run_radius", {0.002}}});
  const lanes::Plan plain = lanes::make_plan(c.robot, schedule, none);
  const lanes::Plan general = lanes::make_plan(c.robot, schedule, three);
  const Plans plans{&plain, &general};
  const double rate = ticks_per_ns();
  std::printf("counter: %.3f ticks/ns; Table III path, %zu samples per run; best of %d\n", rate,
              static_cast<std::size_t>(1000), repeats);
  std::printf("%-8s %8s %8s %8s %8s %8s   (counter ticks per lane-step)\n", "target", "philox",
              "normals", "step", "plain", "general");
  const std::int64_t supported = hwy::SupportedTargets();
  for (const auto& [bit, m] : lanes::measures()) {
    if (m == nullptr || ((supported & bit) == 0 && bit != HWY_SCALAR)) continue;
    if (!only.empty() && only != hwy::TargetName(bit)) continue;
    const Parts p = m(plans, repeats);
    std::printf("%-8s %8.2f %8.2f %8.2f %8.2f %8.2f   plain %.0f M steps/s, general %.0f M steps/s (normals unstored %.2f)\n",
                hwy::TargetName(bit), p.philox, p.normals, p.step, p.plain, p.general,
                1e3 * rate / p.plain, 1e3 * rate / p.general, p.inreg);
  }
  // The scalar reference kernel and the reduction, for scale.
  const auto key = random::key_from_seed(1);
  const std::uint64_t runs = 16, steps = runs * 1000;
  volatile double sink = 0.0;
  const double ref_plain = scalar_part(std::max(1, repeats / 3), steps, [&] {
    for (std::uint64_t r = 0; r < runs; ++r) sink = sink + lanes::reference_run(plain, key, r).x;
  });
  const double ref_general = scalar_part(std::max(1, repeats / 3), steps, [&] {
    for (std::uint64_t r = 0; r < runs; ++r) sink = sink + lanes::reference_run(general, key, r).x;
  });
  MomentAccumulator acc;
  const double reduce = scalar_part(repeats, 1000 * 1000, [&] {
    for (int r = 0; r < 1000; ++r) acc.add(Vector3(1e-3 * r, 2e-3, -1e-3 * r));
  });
  std::printf("scalar reference: plain %.2f, general %.2f; reduction %.3f ticks per step\n",
              ref_plain, ref_general, reduce);
  return 0;
}

}  // namespace odomcov::roofline

int main(int argc, char** argv) { return odomcov::roofline::run(argc, argv); }

#endif  // HWY_ONCE
