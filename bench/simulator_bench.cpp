// Wheel-sample steps per second of the Monte-Carlo simulator on the [Kleeman95] Table III config
// (1000 samples per run), single-threaded and on every core. A step is one sample of one run:
// two Gaussian draws and one exact arc update. Run: cmake --build build --target bench
#include <benchmark/benchmark.h>

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

// The general (scalar) kernel: a world with stochastic effects (slip while turning and
// correlated wheel noise) on the configs/effects/turn_slip.yaml path (~11 m at 50 Hz).
void BM_SimulatorGeneral(benchmark::State& state) {
  static const odomcov::Config c =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/effects/turn_slip.yaml");
  const odomcov::EffectList effects{{"turn_slip", {0.0015}}, {"wheel_noise_correlation", {0.3}}};
  const odomcov::Simulator sim(c.world_robot(), c.path, effects);
  const std::int64_t runs = 2048;
  time_simulation(state, sim, runs, 1);
  state.SetLabel("general kernel");
}

BENCHMARK(BM_SimulatorGeneral)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

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

BENCHMARK_MAIN();
