// calibrate's command line and what it prepares before the loop (src/cli/calibrate.cpp): the
// options, their checks, the suites (the --train/--test split or --holdout), the user's
// candidates and the starting model, every check that runs before the first fit. Shared with
// the libFuzzer target tests/fuzz/fuzz_calibrate.cpp, which drives exactly this.
#pragma once

#include <CLI/CLI.hpp>

#include <optional>
#include <string>

#include "odomcov/measurement/calibrate.hpp"
#include "referee_options.hpp"

namespace odomcov::cli {

struct CalibrateCliOptions {
  std::string suite, out, candidates, holdout, train, test, json;
  int rounds = kCalibrateRounds;
  double alpha = kDiagnoseAlpha;
  int order = 2;
  int threads = 0;
  bool exact = false;
  RefereeOptions referee;
};

/// Declares the `calibrate` subcommand and its options on `app`, filling `opt` when parsed.
CLI::App* add_calibrate_options(CLI::App& app, CalibrateCliOptions& opt);

/// Everything the loop starts from.
struct CalibrateInputs {
  Suite train;
  std::optional<Suite> held;  // none without --holdout or --train
  SuiteModel start;           // the training suite's model at --order
  CalibrateOptions options;
};

/// Checks the options (UsageError), loads the suites and the candidates (InputError naming the
/// file, line and key), splits by --train/--test and checks the model can start: all of
/// calibrate before its first fit.
CalibrateInputs prepare_calibrate(const CalibrateCliOptions& opt);

}  // namespace odomcov::cli
