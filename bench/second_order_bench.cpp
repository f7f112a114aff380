// Cost of one model prediction, first order against order 2 (second_order.hpp), single thread:
//  * the [Kleeman95] Fig. 7 path (model pieces of <= 0.25 rad / 0.25 m);
//  * the 38 m lawn-mower path of configs/order2/lawnmower.yaml;
//  * a logged run of 3000 per-sample pieces (order 2 coarsens them for its correction), as
//    the likelihood of fit and diagnose evaluates for every run.
// Run: cmake --build build --target bench
#include <benchmark/benchmark.h>

#include "odomcov/measurement/config.hpp"
#include "odomcov/engine/second_order.hpp"
#include "odomcov/io/config_io.hpp"

namespace {

using odomcov::ArcSegment;

struct Case {
  odomcov::Robot robot;
  std::vector<ArcSegment> pieces;
  odomcov::EffectList effects;
};

Case keyframe_case(const char* file) {
  const odomcov::Config c = odomcov::load_config(std::string(ODOMCOV_SOURCE_DIR) + file);
  return {c.robot, odomcov::model_pieces(c.path, c.robot.wheelbase_m), c.model_effects};
}

/// The lawn-mower path sampled at 50 Hz over its first 60 s: one piece per sample, as a log.
Case logged_case() {
  const odomcov::Config c =
      odomcov::load_config(ODOMCOV_SOURCE_DIR "/configs/order2/lawnmower.yaml");
  Case out{c.robot, {}, {{"per_run_radius", {0.002}}, {"turn_slip", {0.01}}}};
  for (const odomcov::SampleRun& run : odomcov::sample_schedule(c.path)) {
    for (std::int64_t n = 0; n < run.count && out.pieces.size() < 3000; ++n) {
      out.pieces.push_back(run.increment);
    }
  }
  return out;
}

void run_case(benchmark::State& state, const Case& c) {
  const int order = static_cast<int>(state.range(0));
  for (auto _ : state) {
    benchmark::DoNotOptimize(odomcov::predict_with_order(c.pieces, c.robot, c.effects, order).cov);
  }
  state.counters["pieces"] = static_cast<double>(c.pieces.size());
  state.counters["order"] = order;
}

void BM_PredictFig7(benchmark::State& state) {
  static const Case c = keyframe_case("/configs/kleeman95/fig7.yaml");
  run_case(state, c);
}
void BM_PredictLawnmower(benchmark::State& state) {
  static const Case c = keyframe_case("/configs/order2/lawnmower.yaml");
  run_case(state, c);
}
void BM_PredictLoggedRun(benchmark::State& state) {
  static const Case c = logged_case();
  run_case(state, c);
}

BENCHMARK(BM_PredictFig7)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PredictLawnmower)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PredictLoggedRun)->Arg(1)->Arg(2)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
