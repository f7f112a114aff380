// One file per subcommand (CLI11 pattern): an options struct, setup_x() that declares the
// options and registers the callback, and run_x() that does the work and returns the exit code.
#pragma once

#include <CLI/CLI.hpp>

namespace odomcov::cli {

/// Exit codes of ../shared/SPEC.md.
inline constexpr int kExitOk = 0;
inline constexpr int kExitInconsistent = 1;
inline constexpr int kExitBadInput = 2;

void setup_theory(CLI::App& app, int& exit_code);

}  // namespace odomcov::cli
