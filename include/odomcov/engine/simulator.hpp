// Monte-Carlo simulation of sampled odometry in the closed-loop scenario ([Kleeman95] §7,
// docs/conventions.md): each sample's true wheel travel is the encoder increment plus
// N(0, k^2 |increment|), the true pose follows the exact arc update, and the error of a run is
// true end pose - odometry end pose (theta wrapped to (-pi, pi]).
//
// Determinism: every random number is a Philox draw keyed by the seed at a counter made of the
// run index, sample index and a stream tag (src/base/random.hpp), and runs are reduced in a fixed
// tree, so the same seed gives bit-identical statistics for any thread count.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"
#include "odomcov/engine/statistics.hpp"

namespace odomcov {

/// Shared with the caller while a simulation runs: runs completed so far (for a progress bar)
/// and a cancellation request (remaining work is skipped; the result is then incomplete).
struct Progress {
  std::atomic<std::int64_t> runs_done{0};
  std::atomic<bool> cancel{false};
};

class Simulator {
 public:
  /// `robot`: nominal wheelbase (the odometry's) with the world's wheel noise constants;
  /// `effects`: the world's effects. Systematic effects are folded into the path; stochastic
  /// ones (noise correlation, slip, per-run radius, bumps) run in the SIMD lanes too (the
  /// general kernel), each drawing from its own counter streams; a custom effect's random
  /// parameters rebuild the legs per run (the scalar reference kernel, run by run).
  /// `heading0_rad`: the run's start heading in the reference's frame (effects' `heading`;
  /// every run of this simulator starts there).
  Simulator(const Robot& robot, const Path& path, const EffectList& effects = {},
            double heading0_rad = 0.0);
  /// A logged run (SuiteRun::pieces): one sample per encoder piece, of the piece's duration
  /// (`durations_s` empty: unknown, so speed- and time-dependent effects see NaN), so the
  /// simulated run steps exactly as the model's prediction of that run resolves it.
  Simulator(const Robot& robot, const std::vector<ArcSegment>& pieces,
            const std::vector<double>& durations_s, const EffectList& effects = {},
            double heading0_rad = 0.0);
  ~Simulator();
  Simulator(Simulator&&) noexcept;
  Simulator& operator=(Simulator&&) noexcept;

  /// Streaming statistics of the error over runs 0 .. runs-1. `threads` = 0 uses every core.
  /// Memory does not depend on `runs`.
  MomentAccumulator simulate(std::int64_t runs, std::uint64_t seed, int threads = 0,
                             Progress* progress = nullptr) const;

  /// The errors of runs first .. first+count-1 (for writing measurement suites and for tests).
  std::vector<Vector3> errors(std::uint64_t seed, std::int64_t first, std::int64_t count,
                              int threads = 0) const;

  /// The error of one run by the scalar reference kernel, which the SIMD kernel of every
  /// instruction set must match bit for bit (with effects too).
  Vector3 reference_error(std::uint64_t seed, std::int64_t run) const;

  /// Odometry (noise-free) end pose, integrated sample by sample like the true pose.
  Vector3 odometry_end_pose() const;
  std::int64_t samples_per_run() const;

  /// The instruction set the SIMD kernel runs on (Highway's target name: "AVX3" is AVX-512,
  /// "AVX2", "SSE4", "NEON", "EMU128" the portable one). Every target gives the same bits.
  static const char* kernel_isa();
  /// The instruction sets this build has a kernel for and this CPU runs, best first.
  static std::vector<std::string> kernel_targets();
  /// Makes every simulation run the kernel of `target` (one of kernel_targets(); "" = the best,
  /// the default; the environment variable ODOMCOV_SIMD names one at start-up). For benchmarks
  /// and tests; throws std::invalid_argument for a target not in kernel_targets().
  static void select_kernel(const std::string& target);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace odomcov
