// Wheel-sample steps per second of the Monte-Carlo simulator (docs/performance.md). A step is one
// sample of one run: two Gaussian draws and one exact arc update.
//   BM_SimulatorTable3/T        the [Kleeman95] Table III config (1000 samples per run), the best
//                               SIMD kernel, T threads (1 and every core)
//   BM_SimulatorTarget/NAME     the same, one thread, with the kernel of one instruction set
//                               forced (AVX3 = AVX-512, AVX2, SSE4, SCALAR; NEON on aarch64)
//   BM_SimulatorGeneral/E       Table III, 200 000 runs, one thread: E = 0 no effect, E = 1 the
//                               general kernel with wheel_diameter_ratio, turn_slip and
//                               per_run_radius (the ratio of the two times is the figure)
//   BM_SimulatorLoggedRun/T     the bootstrap case: a logged run of 1300 irregular samples
//                               (50-100 Hz), 300 replicates per simulation; T = 2: two logged runs
//                               at once, one per core. referee_s is what 171 such runs x 300
//                               replicates would take at that rate.
// Run: cmake --build build --target bench (bench/compare_numpy.sh adds the NumPy baseline).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "odomcov/measurement/config.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/simulator.hpp"
#include "odomcov/io/config_io.hpp"

namespace {

const odomcov::Config& table3() {
  static const odomcov::Config config =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/kleeman95/table3.yaml");
  return config;
}

/// Times `runs` runs per iteration on `threads` threads (one untimed batch first warms the
/// thread pool) and reports the wheel-sample steps per second and the thread count.
void time_simulation(benchmark::State& state, const odomcov::Simulator& sim, std::int64_t runs,
                     int threads) {
  sim.simulate(runs, 1, threads);
  std::uint64_t seed = 1;
  for (auto _ : state) {
    benchmark::DoNotOptimize(sim.simulate(runs, seed++, threads).mean());
  }
  const double steps = static_cast<double>(runs * sim.samples_per_run());
  state.counters["steps/s"] =
      benchmark::Counter(steps, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["threads"] = threads;
}

void BM_SimulatorTable3(benchmark::State& state) {
  const odomcov::Config& c = table3();
  const odomcov::Simulator sim(c.robot, c.path);
  const int threads = static_cast<int>(state.range(0));
  const std::int64_t runs = 8192;
  time_simulation(state, sim, runs, threads);
  state.SetLabel(odomcov::Simulator::kernel_isa());
}

BENCHMARK(BM_SimulatorTable3)
    ->Arg(1)
    ->Arg(static_cast<int>(std::thread::hardware_concurrency()))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(2.0);

void BM_SimulatorTarget(benchmark::State& state, const std::string& target) {
  const odomcov::Config& c = table3();
  const odomcov::Simulator sim(c.robot, c.path);
  odomcov::Simulator::select_kernel(target);
  time_simulation(state, sim, 8192, 1);
  state.SetLabel(odomcov::Simulator::kernel_isa());
  odomcov::Simulator::select_kernel("");
}

// The general kernel against the plain one on the same path and run count.
void BM_SimulatorGeneral(benchmark::State& state) {
  const odomcov::Config& c = table3();
  const odomcov::EffectList effects{
      {"wheel_diameter_ratio", {1.004}}, {"turn_slip", {0.0015}}, {"per_run_radius", {0.002}}};
  const bool general = state.range(0) == 1;
  const odomcov::Simulator sim(c.robot, c.path, general ? effects : odomcov::EffectList{});
  time_simulation(state, sim, 200000, 1);
  state.SetLabel(general ? "general: Ed, turn_slip, per_run_radius" : "plain");
}

BENCHMARK(BM_SimulatorGeneral)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

/// A synthetic logged run: 1300 encoder pieces of 10-20 ms (50-100 Hz), the wheel speeds
/// wandering between straight driving, arcs and turns on the spot.
struct LoggedRun {
  std::vector<odomcov::ArcSegment> pieces;
  std::vector<double> durations;
};

LoggedRun logged_run(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> dt(0.010, 0.020), change(-0.05, 0.05);
  LoggedRun log;
  double v = 0.3, w = 0.0;  // m/s, rad/s
  for (int i = 0; i < 1300; ++i) {
    v = std::clamp(v + change(rng), -0.2, 0.6);
    w = std::clamp(w + 4 * change(rng), -1.5, 1.5);
    const double t = dt(rng), half_b = 0.2;
    log.pieces.push_back({(v - w * half_b) * t, (v + w * half_b) * t});
    log.durations.push_back(t);
  }
  return log;
}

void BM_SimulatorLoggedRun(benchmark::State& state) {
  const odomcov::Robot robot{0.4, {1e-3, 1e-3}};
  const int parallel = static_cast<int>(state.range(0));
  std::vector<odomcov::Simulator> sims;
  for (int i = 0; i < parallel; ++i) {
    const LoggedRun log = logged_run(static_cast<std::uint64_t>(i) + 1);
    sims.emplace_back(robot, log.pieces, log.durations);
  }
  const std::int64_t replicates = 300;
  std::uint64_t seed = 1;
  for (auto _ : state) {
    std::vector<std::thread> threads;
    for (int i = 0; i < parallel; ++i) {
      threads.emplace_back([&, i, s = seed] {
        benchmark::DoNotOptimize(sims[static_cast<std::size_t>(i)].simulate(replicates, s + i, 1).mean());
      });
    }
    for (std::thread& t : threads) t.join();
    seed += static_cast<std::uint64_t>(parallel);
  }
  const double steps = static_cast<double>(parallel * replicates * sims[0].samples_per_run());
  state.counters["steps/s"] = benchmark::Counter(steps, benchmark::Counter::kIsIterationInvariantRate);
  // 171 logged runs x 300 replicates at this rate (the compare referee's load).
  const double referee_steps = 171.0 * 300.0 * static_cast<double>(sims[0].samples_per_run());
  state.counters["referee_s"] = benchmark::Counter(
      steps / referee_steps, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["threads"] = parallel;
}

BENCHMARK(BM_SimulatorLoggedRun)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

// A custom effect (muparser expressions) against none, on the configs/effects/speed_scale.yaml
// path (35 s at 50 Hz: lines at three speeds, a spin, an arc, a reversal), on every core.
// Arg 0: no effect; 1: the speed-dependent scale of that config (factors per leg of equal
// samples); 2: a scale that depends on the distance travelled, s (factors per sample, so the
// legs are single samples); 3: a lateral slip in v and omega (per leg; the scalar kernel, which
// takes the slip); 4: a scale drawn once per run (random: the legs rebuilt for each run's
// draw); 5: the same drawn scale growing with s (every sample a leg, rebuilt per run: the
// costliest kind); 6: a slip nonlinear in the heading theta (per sample; the model cuts its
// pieces finer). Systematic expressions are evaluated when the simulator is built, never per
// run: their per-run cost is that of the legs they give.
odomcov::EffectList custom_variant(int variant) {
  if (variant == 0) return {};
  odomcov::CustomEffect def;
  def.name = "bench";
  def.parameters = {"a"};
  std::vector<double> start{0.02};
  switch (variant) {
    case 1: def.scale.text = "1 + a * (v - 0.4)"; break;
    case 2: def.scale.text = "1 + a * min(s, 5)"; break;
    case 3: def.lateral.text = "0.2 * a - a * v * omega"; break;
    case 4: def.scale.text = "1 + a"; def.random = {"a"}; start.push_back(0.002); break;
    case 5: def.scale.text = "1 + a * min(s, 5)"; def.random = {"a"}; start.push_back(0.002); break;
    default: def.lateral.text = "a * sin(3 * theta)"; break;
  }
  return {odomcov::define_custom_effect(def, start)};
}

const char* custom_label(std::int64_t variant) {
  static const char* const labels[] = {"no effect", "custom, speed", "custom, distance", "custom lateral, v omega",
                                       "custom, scale drawn per run", "custom, drawn scale x distance",
                                       "custom lateral, sin(3 theta)"};
  return labels[variant];
}

void BM_SimulatorCustom(benchmark::State& state) {
  static const odomcov::Config c =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/effects/speed_scale.yaml");
  const odomcov::Simulator sim(c.world_robot(), c.path, custom_variant(static_cast<int>(state.range(0))));
  const int threads = static_cast<int>(std::thread::hardware_concurrency());
  const std::int64_t runs = 2048;
  time_simulation(state, sim, runs, threads);
  state.SetLabel(custom_label(state.range(0)));
}

BENCHMARK(BM_SimulatorCustom)->DenseRange(0, 6)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

// Building the simulator (the expressions evaluated once per leg or sample of the path), and
// the model side (resolve + first-order propagation, what every likelihood evaluation does per
// experiment), for the same three variants.
void BM_SimulatorBuildCustom(benchmark::State& state) {
  static const odomcov::Config c =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/effects/speed_scale.yaml");
  const odomcov::EffectList effects = custom_variant(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    const odomcov::Simulator sim(c.world_robot(), c.path, effects);
    benchmark::DoNotOptimize(sim.samples_per_run());
  }
}

BENCHMARK(BM_SimulatorBuildCustom)->DenseRange(0, 6)->Unit(benchmark::kMicrosecond);

void BM_PredictCustom(benchmark::State& state) {
  static const odomcov::Config c =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/effects/speed_scale.yaml");
  std::vector<double> durations;
  const auto pieces = odomcov::model_pieces(c.path, c.robot.wheelbase_m, &durations);
  const odomcov::EffectList effects = custom_variant(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    benchmark::DoNotOptimize(odomcov::predict(pieces, durations, c.robot, effects).cov);
  }
  state.counters["pieces"] = static_cast<double>(pieces.size());
  state.SetLabel(custom_label(state.range(0)));
}

BENCHMARK(BM_PredictCustom)->DenseRange(0, 6)->Unit(benchmark::kMicrosecond);

}  // namespace

int main(int argc, char** argv) {
  for (const std::string& target : odomcov::Simulator::kernel_targets()) {
    benchmark::RegisterBenchmark(("BM_SimulatorTarget/" + target).c_str(), BM_SimulatorTarget, target)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime()
        ->MinTime(2.0);
  }
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
