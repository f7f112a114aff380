// Wheel-sample steps per second of the Monte-Carlo simulator on the [Kleeman95] Table III config
// (1000 samples per run), single-threaded and on every core. A step is one sample of one run:
// two Gaussian draws and one exact arc update. Run: cmake --build build --target bench
#include <benchmark/benchmark.h>

#include <thread>

#include "odomcov/config.hpp"
#include "odomcov/simulator.hpp"

namespace {

const odomcov::Config& table3() {
  static const odomcov::Config config =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/kleeman95/table3.yaml");
  return config;
}

void BM_SimulatorTable3(benchmark::State& state) {
  const odomcov::Config& c = table3();
  const odomcov::Simulator sim(c.robot, c.path);
  const int threads = static_cast<int>(state.range(0));
  const std::int64_t runs = 8192;
  sim.simulate(runs, 1, threads);  // warm the thread pool
  std::uint64_t seed = 1;
  for (auto _ : state) {
    benchmark::DoNotOptimize(sim.simulate(runs, seed++, threads).mean());
  }
  const double steps = static_cast<double>(runs * sim.samples_per_run());
  state.counters["steps/s"] =
      benchmark::Counter(steps, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["threads"] = threads;
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
  std::uint64_t seed = 1;
  for (auto _ : state) {
    benchmark::DoNotOptimize(sim.simulate(runs, seed++, 1).mean());
  }
  const double steps = static_cast<double>(runs * sim.samples_per_run());
  state.counters["steps/s"] =
      benchmark::Counter(steps, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["threads"] = 1;
  state.SetLabel("general kernel");
}

BENCHMARK(BM_SimulatorGeneral)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(2.0);

}  // namespace

BENCHMARK_MAIN();
