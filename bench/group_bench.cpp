// Cost of the grouped likelihood (group_variation, likelihood.hpp), single thread:
//  * GroupedLogLikelihood/n: log_likelihood of n runs in 4 groups with group columns, the
//    sequential form (condition_on_groups, rank-two Woodbury; these runs have one column), O(n);
//  * DenseLogLikelihood/n: the same value from the dense (3n x 3n) covariance and its Cholesky,
//    O(n^3), what the sequential form avoids (group_test checks they agree to 1e-9);
//  * Residuals{Plain,Grouped}: residuals() of the 180-run world of
//    configs/effects/group_variation.yaml without and with group_variation in the model (the
//    group terms cost two mean-only propagations per logged run, three per planned path).
// Run: cmake --build build --target bench
#include <benchmark/benchmark.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/io/world.hpp"
#include "odomcov/io/suite_io.hpp"

namespace {

using odomcov::RunResidual;
using Runs = std::vector<std::vector<RunResidual>>;

/// n runs in experiments of 10, four groups, random SPD covariances and columns (fixed seed).
Runs random_runs(int n) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Runs res;
  for (int i = 0; i < n; ++i) {
    if (i % 10 == 0) res.emplace_back();
    RunResidual r;
    Eigen::Matrix3d A;
    for (int k = 0; k < 9; ++k) A(k / 3, k % 3) = 0.01 * u(rng);
    r.cov = A * A.transpose() + 1e-5 * Eigen::Matrix3d::Identity();
    r.error = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 0.02;
    r.group_column = Eigen::Vector3d(u(rng), u(rng), u(rng)) * 0.01;
    r.group = static_cast<int>(res.size() % 4);
    res.back().push_back(r);
  }
  return res;
}

double dense(const Runs& res) {
  std::vector<RunResidual> runs;
  for (const auto& ex : res) runs.insert(runs.end(), ex.begin(), ex.end());
  const auto n = static_cast<Eigen::Index>(3 * runs.size());
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd r(n);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto a = static_cast<Eigen::Index>(3 * i);
    r.segment<3>(a) = runs[i].error - runs[i].mean;
    S.block<3, 3>(a, a) += runs[i].cov;
    for (std::size_t j = 0; j < runs.size(); ++j) {
      if (runs[i].group == runs[j].group) {
        S.block<3, 3>(a, static_cast<Eigen::Index>(3 * j)) +=
            runs[i].group_column * runs[j].group_column.transpose();
      }
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd L = llt.matrixL();
  return -0.5 * (r.dot(llt.solve(r)) + 2.0 * L.diagonal().array().log().sum() +
                 static_cast<double>(n) * std::log(2.0 * M_PI));
}

void GroupedLogLikelihood(benchmark::State& state) {
  const Runs res = random_runs(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(odomcov::log_likelihood(res));
  state.counters["runs"] = static_cast<double>(state.range(0));
}
BENCHMARK(GroupedLogLikelihood)->Arg(180)->Arg(1000)->Arg(10000)->Unit(benchmark::kMicrosecond);

void DenseLogLikelihood(benchmark::State& state) {
  const Runs res = random_runs(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(dense(res));
  state.counters["runs"] = static_cast<double>(state.range(0));
}
BENCHMARK(DenseLogLikelihood)->Arg(180)->Arg(1000)->Unit(benchmark::kMicrosecond);

/// The world's suite, synthesised once into a temporary directory.
const odomcov::Suite& world_suite() {
  static const odomcov::Suite suite = [] {
    const odomcov::WorldFile w =
        odomcov::load_world(ODOMCOV_SOURCE_DIR "/configs/effects/group_variation.yaml");
    const auto dir = std::filesystem::temp_directory_path() / "odomcov_group_bench";
    std::filesystem::create_directories(dir);
    for (std::size_t i = 0; i < w.experiments.size(); ++i) {
      std::ofstream(dir / (w.experiments[i].name + ".csv"))
          << odomcov::measurements_csv(odomcov::synthesize(w, i));
    }
    std::ofstream(dir / "suite.yaml") << odomcov::suite_yaml(w);
    return odomcov::load_suite((dir / "suite.yaml").string());
  }();
  return suite;
}

void residuals_case(benchmark::State& state, bool grouped) {
  odomcov::SuiteModel model = odomcov::suite_model(world_suite());
  model.effects = {{"wheelbase_error", {1.01}}};
  if (grouped) model.effects.push_back({"group_variation", {0.004}, "wheelbase_error.Eb"});
  for (auto _ : state) {
    benchmark::DoNotOptimize(odomcov::log_likelihood(odomcov::residuals(world_suite(), model)));
  }
}
void ResidualsPlain(benchmark::State& state) { residuals_case(state, false); }
void ResidualsGrouped(benchmark::State& state) { residuals_case(state, true); }
BENCHMARK(ResidualsPlain)->Unit(benchmark::kMillisecond);
BENCHMARK(ResidualsGrouped)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
