// Cost of fit and diagnose on a real data set: all 171 OptiOdom runs (216 696 logged rows,
// data/optiodom), imported into a temporary directory by the fixture, the model of order 2
// (the default of fit and diagnose).
//  * BM_Likelihood: one exact evaluation (every run propagated), the unit both paths pay;
//  * BM_LikelihoodModel: the same with the in-sample loop's model (four effects and a group);
//  * BM_CompareSimulation: compare with the in-sample loop's model (results/optiodom/
//    model_all.yaml), its verdict calibrated by simulating the model's world (the referee);
//  * BM_DiagnoseRound: one diagnose round from the plain model (13 candidates, two of them
//    group_variation's: the imported sessions are groups);
//  * BM_Fit: the joint fit of Ed and Eb;
//  * BM_Calibrate: odomcov calibrate on every run (cross-validation included): diagnose
//    rounds, adoption, the joint fit, confounded pairs and next experiments (fast path only);
//  * BM_Predictive: the Ivanjko hold-out predicted with what the training runs leave unknown.
// Each on the fast path (FitPath::fast: linearised, re-anchored) and, with
// ODOMCOV_BENCH_EXACT=1 in the environment, the exact one (~40 s CPU per round). The counter
// `propagations` is the number of exact likelihood evaluations per iteration.
// Run: cmake --build build --target bench, or build/bench/diagnose_bench directly.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "odomcov/measurement/calibrate.hpp"
#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/io/optiodom.hpp"
#include "odomcov/io/suite_io.hpp"

namespace {

namespace fs = std::filesystem;

/// The whole OptiOdom set as a suite (as `odomcov import optiodom data/optiodom/data/diff/*/*
/// --wheelbase 0.2 --diameters 0.084,0.084`), with `model` (a robot line and a model block, e.g.
/// results/optiodom/model_all.yaml) in place of the imported robot line when given.
odomcov::Suite import_optiodom(const std::string& model) {
  odomcov::OptiOdomOptions options;
  for (const auto& type : fs::directory_iterator(ODOMCOV_SOURCE_DIR "/data/optiodom/data/diff")) {
    for (const auto& session : fs::directory_iterator(type.path())) {
      options.sessions.push_back(session.path().string());
    }
  }
  std::sort(options.sessions.begin(), options.sessions.end());
  options.wheelbase_m = 0.2;
  options.diameters_m = {{0.084, 0.084}};
  const fs::path dir = fs::temp_directory_path() / ("odomcov_bench_" + std::to_string(::getpid()));
  for (const odomcov::ImportedFile& f : odomcov::import_optiodom(options)) {
    const fs::path p = dir / f.path;
    fs::create_directories(p.parent_path());
    std::string text = f.text;
    if (f.path == "suite.yaml" && !model.empty()) {
      const std::size_t robot = text.find("\nrobot:") + 1;
      text.replace(robot, text.find('\n', robot) + 1 - robot, model);
    }
    std::ofstream(p) << text;
  }
  odomcov::Suite s = odomcov::load_suite((dir / "suite.yaml").string());
  fs::remove_all(dir);
  return s;
}

/// The whole OptiOdom set with its imported (nominal) model, imported once.
const odomcov::Suite& optiodom() {
  static const odomcov::Suite suite = import_optiodom("");
  return suite;
}

/// The same with the model of the in-sample diagnose loop (results/optiodom/model_all.yaml:
/// turn-dependent wheelbase, diameter ratio, scale, reference offset, the spin wheelbase's
/// group_variation over the 32 sessions, turn slip), imported once.
const odomcov::Suite& optiodom_model_all() {
  static const odomcov::Suite suite = [] {
    std::ifstream in(ODOMCOV_SOURCE_DIR "/results/optiodom/model_all.yaml");
    return import_optiodom(std::string(std::istreambuf_iterator<char>(in), {}));
  }();
  return suite;
}

std::size_t runs(const odomcov::Suite& suite) {
  std::size_t n = 0;
  for (const odomcov::SuiteExperiment& e : suite.experiments) n += e.runs.size();
  return n;
}

odomcov::FitPath path_of(const benchmark::State& state) {
  return state.range(0) == 0 ? odomcov::FitPath::fast : odomcov::FitPath::exact;
}

void BM_Likelihood(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom();
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  for (auto _ : state) benchmark::DoNotOptimize(odomcov::residuals(suite, model));
  state.counters["runs"] = static_cast<double>(runs(suite));
}

/// One exact evaluation with the in-sample loop's model (results/optiodom/model_all.yaml: four
/// systematic effects and a group_variation, order 2), the logged runs coarsened once as
/// ResidualCache does: the unit cost of every fit's propagation once the loop has named effects.
void BM_LikelihoodModel(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom_model_all();
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  const odomcov::CoarseRuns coarse = odomcov::coarsen_logged_runs(suite);
  for (auto _ : state) benchmark::DoNotOptimize(odomcov::residuals(suite, model, &coarse));
  state.counters["runs"] = static_cast<double>(runs(suite));
}

void BM_DiagnoseRound(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom();
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  double propagations = 0;
  for (auto _ : state) {
    odomcov::DiagnoseProgress progress;
    const odomcov::Diagnosis d =
        odomcov::diagnose(suite, model, odomcov::kDiagnoseAlpha, {}, &progress, {},
                          path_of(state));
    benchmark::DoNotOptimize(d.after.nees_mean);
    propagations = static_cast<double>(progress.evaluations.load());
    state.counters["nees_after"] = d.after.nees_mean;
  }
  state.counters["propagations"] = propagations;
  state.counters["runs"] = static_cast<double>(runs(suite));
}

/// odomcov calibrate in the library: diagnose rounds with cross-validation over the four path
/// types (each finalist refitted on each fold's complement), adoption, the joint fit, the
/// confounded pairs and the next experiments. Counters: rounds, propagations in all, the NEES
/// mean of the final model, the effects named.
void BM_Calibrate(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom();
  double rounds = 0, propagations = 0, nees = 0, named = 0;
  for (auto _ : state) {
    odomcov::CalibrateOptions options;
    options.diagnose.path = path_of(state);
    odomcov::DiagnoseProgress progress;
    const odomcov::CalibrateResult c =
        odomcov::calibrate(suite, odomcov::suite_model(suite), options, nullptr, &progress);
    rounds = static_cast<double>(c.rounds.size());
    propagations = static_cast<double>(progress.evaluations.load());
    nees = c.after.nees_mean;
    named = static_cast<double>(c.named.size());
  }
  state.counters["rounds"] = rounds;
  state.counters["propagations"] = propagations;
  state.counters["nees"] = nees;
  state.counters["named"] = named;
}

void BM_Fit(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom();
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  double propagations = 0;
  for (auto _ : state) {
    std::atomic<std::int64_t> count{0};
    const odomcov::FitResult f =
        odomcov::fit(suite, model, {"wheel_diameter_ratio.Ed", "wheelbase_error.Eb"},
                     odomcov::Likelihood::full, &count, path_of(state));
    benchmark::DoNotOptimize(f.values);
    propagations = static_cast<double>(count.load());
    state.counters["log_likelihood"] = f.log_likelihood_after;
  }
  state.counters["propagations"] = propagations;
}

/// compare on all 171 runs with the in-sample loop's model, calibrated by the referee (the
/// model has group_variation, so the automatic choice simulates): the whole compare, residuals
/// included, at alpha = 0.001 (compare's default; arg 0) and 0.01 (diagnose's; arg 1), seed 1.
/// Counters: the replicates the looks took, the family-wise p-value, and the wall time per
/// 1000 replicates (the cost of a close call, which looks up to 1599).
void BM_CompareSimulation(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom_model_all();
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  const double alpha = state.range(0) == 0 ? 0.001 : 0.01;
  double replicates = 0, p = 0, seconds = 0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    const odomcov::Comparison c = odomcov::compare(suite, model, alpha);
    seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    replicates = static_cast<double>(c.calibration.replicates);
    p = c.calibration.p_value;
  }
  state.counters["replicates"] = replicates;
  state.counters["p_family"] = p;
  state.counters["s_per_1000_replicates"] = 1000.0 * seconds / replicates;
  state.counters["runs"] = static_cast<double>(runs(suite));
}

/// calibrate's prediction of held-out runs with what the training runs leave unknown
/// (holdout.predictive) for the Ivanjko hold-out, with the in-sample loop's model: the training
/// runs' Fisher information in the joint fit's parameters and every absent systematic catalogue
/// effect's (training_uncertainty), then the held-out runs' sensitivities (predictive_check).
/// Counters: the parameters, and the two NEES means.
void BM_Predictive(benchmark::State& state) {
  const odomcov::Suite& suite = optiodom_model_all();
  odomcov::Suite training = suite, held = suite;
  auto keep = [](odomcov::Suite& s, bool ivanjko) {
    auto& ex = s.experiments;
    ex.erase(std::remove_if(ex.begin(), ex.end(), [&](const odomcov::SuiteExperiment& e) {
               return (e.name.rfind("ivanjko-", 0) == 0) != ivanjko;
             }),
             ex.end());
  };
  keep(training, false);
  keep(held, true);
  const odomcov::SuiteModel model = odomcov::suite_model(suite);
  double parameters = 0, plugin = 0, predictive = 0;
  for (auto _ : state) {
    const odomcov::TrainingUncertainty u =
        odomcov::training_uncertainty(training, model, odomcov::joint_parameters(model, false));
    const odomcov::PredictiveCheck c = odomcov::predictive_check(held, u);
    parameters = static_cast<double>(u.names.size());
    plugin = c.plugin_mean;
    predictive = c.predictive_mean;
  }
  state.counters["parameters"] = parameters;
  state.counters["nees_plugin"] = plugin;
  state.counters["nees_predictive"] = predictive;
  state.counters["runs"] = static_cast<double>(runs(suite));
}

const bool kExact = std::getenv("ODOMCOV_BENCH_EXACT") != nullptr;

BENCHMARK(BM_Likelihood)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->UseRealTime();
BENCHMARK(BM_LikelihoodModel)->Unit(benchmark::kMillisecond)->MeasureProcessCPUTime()->UseRealTime();
BENCHMARK(BM_CompareSimulation)->Arg(0)->Arg(1)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(3);
BENCHMARK(BM_DiagnoseRound)->Arg(0)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(3);
BENCHMARK(BM_Calibrate)->Arg(0)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(1);
BENCHMARK(BM_Fit)->Arg(0)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(3);
BENCHMARK(BM_Predictive)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(3);
const bool kRegistered = kExact && [] {
  benchmark::RegisterBenchmark("BM_DiagnoseRound/exact", [](benchmark::State& s) { BM_DiagnoseRound(s); })
      ->Arg(1)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(1);
  benchmark::RegisterBenchmark("BM_Fit/exact", [](benchmark::State& s) { BM_Fit(s); })
      ->Arg(1)->Unit(benchmark::kSecond)->MeasureProcessCPUTime()->UseRealTime()->Iterations(1);
  return true;
}();

}  // namespace

BENCHMARK_MAIN();
