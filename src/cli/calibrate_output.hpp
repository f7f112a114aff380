// What diagnose and calibrate write: their JSON documents (docs/json.md, "diagnose" and
// "calibrate") and diff_drive.yaml, shared by the command line and the Python module.
#pragma once

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

#include "odomcov/measurement/calibrate.hpp"

namespace odomcov::cli {

/// The corrected odometry (null without one).
nlohmann::json correction_json(const std::optional<OdometryCorrection>& correction);
/// What the misfit lines up with, best first.
nlohmann::json residuals_json(const std::vector<ResidualAlignment>& residuals);
nlohmann::json folds_json(const Folds& folds);
/// A fit (docs/json.md, "fit"): estimates, standard errors (plain and robust), correlations,
/// log-likelihoods, evaluations, the model's YAML, the warnings and the parameters at a bound.
nlohmann::json fit_json(const FitResult& r);
/// What the runs do not separate and what to record next, in words (the report's lines) and as
/// {confounded, next_experiments}.
std::string design_report(const std::vector<ConfoundedPair>& confounded, const std::vector<NextExperiment>& next,
                          const std::vector<UnpredictableExperiment>& unpredictable = {});
nlohmann::json design_json(const std::vector<ConfoundedPair>& confounded, const std::vector<NextExperiment>& next,
                           const std::vector<UnpredictableExperiment>& unpredictable = {});
/// One diagnose round; `model` is the model the round started from (its candidates' YAML
/// snippets add to it).
nlohmann::json diagnosis_json(const Suite& suite, const SuiteModel& model, const Diagnosis& d);
/// calibrate.json: every round, the decisions, the final model, the design and the held-out
/// judgement; `holdout_compare` (compare's JSON of the held-out runs, or null) goes under
/// holdout.compare.
nlohmann::json calibrate_json(const Suite& suite, const SuiteModel& start, const CalibrateResult& c,
                                double alpha, const nlohmann::json& holdout_compare = nullptr);

/// ROS 2 parameters for diff_drive_controller (docs/calibrate.md, "diff_drive.yaml"), with
/// comments saying what each value is for.
std::string diff_drive_yaml(const Suite& suite, const DiffDriveParameters& p);

}  // namespace odomcov::cli
