// Fuzz target: `odomcov calibrate`'s command line and everything it prepares before the loop
// (src/cli/calibrate_command.hpp). The main section holds the arguments after `calibrate`, one
// per line (`suite.yaml`, `--train`, `^a-`, `--rounds`, `3`, ...); the other sections are the
// files they name: the suite, its CSVs, `--candidates`, `--holdout`. The options go through the
// CLI's own parser and checks, the suites and candidates through the loaders, the --train/--test
// regexes split the suite. Then the cheap end of the command, not the loop: the folds the
// cross-validation would use, the training domain, diff_drive.yaml's parameters, and the suite's
// own model judged on the held-out runs as calibrate judges its final one (compare with the
// Gaussian references, NEES per kind, the experiments outside the training domain).
//
// File names are taken relative to the input's directory (only the last path component), the
// output directory is a scratch one and --json is ignored, so nothing outside the fuzzer's
// directories is read or written. The suites, the `domain:` block, `kind:` and `heading0` are
// fuzzed on their own by fuzz_suite and the candidate files by fuzz_custom; this target adds
// their combination with the options.
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "calibrate_command.hpp"
#include "fuzz_util.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/measurement/cross_validation.hpp"
#include "odomcov/measurement/domain.hpp"
#include "output.hpp"

namespace {

/// At most this many arguments and runs: each execution stays well under a millisecond's work
/// per run.
constexpr std::size_t kMaxArguments = 64;
constexpr std::size_t kMaxRuns = 2000;

std::vector<std::string> arguments(const std::filesystem::path& file) {
  std::vector<std::string> args{"calibrate"};
  std::ifstream in(file);
  for (std::string line; std::getline(in, line) && args.size() <= kMaxArguments;) args.push_back(line);
  return args;
}

/// A file the options name, looked up in the input's directory.
void inside(const std::filesystem::path& dir, std::string& path) {
  if (!path.empty()) path = (dir / std::filesystem::path(path).filename()).string();
}

std::size_t runs_of(const odomcov::Suite& suite) {
  std::size_t runs = 0;
  for (const odomcov::SuiteExperiment& ex : suite.experiments) runs += ex.runs.size();
  return runs;
}

void check_folds(const odomcov::Suite& suite) {
  const odomcov::Folds folds = odomcov::make_folds(suite);
  if (!folds.by.empty() && folds.of_experiment.size() != suite.experiments.size()) {
    odomcov::fuzz::invariant_failed("make_folds: " + std::to_string(folds.of_experiment.size()) + " fold indices for " +
                                    std::to_string(suite.experiments.size()) + " experiments");
  }
  for (const int f : folds.of_experiment) {
    if (f < 0 || static_cast<std::size_t>(f) >= folds.size()) odomcov::fuzz::invariant_failed("make_folds: fold index out of range");
  }
}

/// calibrate's last steps on the starting model instead of a calibrated one.
void cheap_end(const odomcov::cli::CalibrateCliOptions& opt, const odomcov::cli::CalibrateInputs& in) {
  using namespace odomcov;
  check_folds(in.train);
  SuiteModel model = in.start;
  model.domain = training_domain(in.train, model.robot.wheelbase_m);
  diff_drive_parameters(in.train, model);
  if (!in.held) return;
  CalibrationOptions gaussian;
  gaussian.method = CalibrationMethod::gaussian;
  const HoldoutSummary h = judge_holdout(*in.held, model, opt.alpha, gaussian);
  if (h.experiments != in.held->experiments.size() || h.consistent > h.experiments) {
    fuzz::invariant_failed("judge_holdout counts " + std::to_string(h.consistent) + " of " +
                           std::to_string(h.experiments) + " experiments");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace odomcov;
  const auto dir = fuzz::unpack(data, size, "args");
  std::vector<std::string> args = arguments(dir / "args");
  cli::CalibrateCliOptions opt;
  CLI::App app;
  cli::add_calibrate_options(app, opt);
  std::reverse(args.begin(), args.end());  // CLI11 takes the arguments last first
  try {
    app.parse(args);
  } catch (const CLI::ParseError&) {
    return 0;  // the CLI's usage error, exit 2
  }
  inside(dir, opt.suite);
  inside(dir, opt.candidates);
  inside(dir, opt.holdout);
  opt.out = (fuzz::scratch_dir("calibrate") / "out").string();
  opt.json.clear();
  try {
    const cli::CalibrateInputs in = cli::prepare_calibrate(opt);
    if (runs_of(in.train) + (in.held ? runs_of(*in.held) : 0) <= kMaxRuns) cheap_end(opt, in);
  } catch (const InputError&) {
  } catch (const cli::UsageError&) {
  }
  return 0;
}
