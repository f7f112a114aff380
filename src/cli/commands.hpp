// One file per subcommand (CLI11 pattern): an options struct, setup_x() that declares the
// options and registers the callback, and run_x() that does the work and returns the exit code.
#pragma once

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/measurement/validation.hpp"

namespace odomcov::cli {

/// Exit codes (docs/json.md, "Exit codes").
inline constexpr int kExitOk = 0;
inline constexpr int kExitInconsistent = 1;
inline constexpr int kExitBadInput = 2;

void setup_theory(CLI::App& app, int& exit_code);
void setup_run(CLI::App& app, int& exit_code);
void setup_sweep(CLI::App& app, int& exit_code);
void setup_synth(CLI::App& app, int& exit_code);
void setup_compare(CLI::App& app, int& exit_code);
void setup_fit(CLI::App& app, int& exit_code);
void setup_umbmark(CLI::App& app, int& exit_code);
void setup_import(CLI::App& app, int& exit_code);
void setup_diagnose(CLI::App& app, int& exit_code);
void setup_predict(CLI::App& app, int& exit_code);
void setup_calibrate(CLI::App& app, int& exit_code);

/// The report and JSON of `compare` (docs/json.md, "compare"), shared with `diagnose`.
std::string comparison_text(const Suite& suite, const Comparison& c);
nlohmann::json comparison_json(const Suite& suite, const Comparison& c);

/// diagnose's pieces that calibrate shares (src/cli/diagnose.cpp): --candidates FILE (the
/// user's hypotheses, each with a parameter to fit; one the suite's model already has, the same
/// catalogue effect or the same custom definition, is left out; a custom one with the name of a
/// different effect in the model is a clash), the report of one round (the candidates' table,
/// the decisions and the model to adopt), the folds in words and the corrected odometry.
EffectList load_candidates(const std::string& file, const Suite& suite);
void write_ranking(std::ostream& out, const Suite& suite, const Diagnosis& d);
std::string folds_text(const Folds& folds);
void write_correction(std::ostream& out, const std::optional<OdometryCorrection>& correction);

/// The JSON of `run` (docs/json.md, "run"), shared with `sweep`.
nlohmann::json validation_json(const std::string& name, const Validation& v);

}  // namespace odomcov::cli
