// The referee's options, shared by every command whose verdict is compare's (compare,
// diagnose): --calibration, --replicates, --seed; their check, the progress bar of the
// simulation, and the calibration's lines in the report and keys in the JSON.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <string>

#include "odomcov/measurement/comparison.hpp"
#include "progress.hpp"

namespace odomcov::cli {

struct RefereeOptions {
  std::string calibration = "automatic";
  std::int64_t replicates = kDefaultReplicates;
  std::uint64_t seed = kDefaultRefereeSeed;
};

/// Adds --calibration, --replicates and --seed to a subcommand.
void add_referee_options(CLI::App* cmd, RefereeOptions& options);

/// The checked options (a usage error, exit 2, for --replicates outside 1 .. kMaxReplicates),
/// reporting progress to `progress`.
CalibrationOptions calibration_options(const RefereeOptions& options, RefereeProgress* progress);

/// A progress bar of the referee's replicates (on a terminal, after half a second).
std::unique_ptr<ProgressBar> referee_bar(RefereeProgress& progress);

/// The calibration in words: one line, e.g. "calibrated by simulating the model's world: B = 199
/// replicates (seed 1), family-wise p = 0.005 +/- 0.005 (resolution 0.005) ...".
std::string calibration_text(const Calibration& c);
/// The calibration's JSON keys (docs/json.md, "compare": calibration).
nlohmann::json calibration_json(const Calibration& c);

}  // namespace odomcov::cli
