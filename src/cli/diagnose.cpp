// odomcov diagnose SUITE.yaml [--effects a,b,...] [--candidates FILE.yaml] [--alpha A] [--json FILE]
// Which physical effect is the model missing? Fitted size, evidence, and the YAML to add it.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "calibrate_output.hpp"
#include "failures.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/io/suite_io.hpp"
#include "output.hpp"
#include "progress.hpp"
#include "referee_options.hpp"

namespace odomcov::cli {
namespace {

struct DiagnoseOptions {
  std::string suite;
  std::vector<std::string> effects;
  std::string candidates;
  double alpha = kDiagnoseAlpha;
  std::string json;
  int order = 2;
  bool exact = false;
  RefereeOptions referee;
};

/// --effects: catalogue names, wheel_noise_level or group_variation(<effect>.<parameter>).
void check_effect_names(const std::vector<std::string>& effects) {
  for (const std::string& e : effects) {
    const std::string effect = e.substr(0, e.find('('));  // group_variation(wheelbase_error.Eb)
    if (e != kWheelNoiseLevel && !find_effect(effect)) throw UsageError("--effects: unknown effect '" + e + "'");
  }
}

}  // namespace

EffectList load_candidates(const std::string& file, const Suite& suite) {
  if (file.empty()) return {};
  EffectList candidates;
  const EffectList own = load_effects(file);
  for (std::size_t i = 0; i < own.size(); ++i) {
    const int line = own[i].custom ? own[i].custom->line : 0;
    if (own[i].values.empty()) {
      throw InputError(file, line, "[" + std::to_string(i) + "]",
                       "a candidate needs a parameter to fit (custom: parameters: {name: start})");
    }
    const EffectSpec* in_model = find_spec(suite.model_effects, own[i].name);
    if (!in_model) {
      candidates.push_back(own[i]);
    } else if (own[i].custom && !(in_model->custom && *in_model->custom == *own[i].custom)) {
      throw InputError(file, line, "[" + std::to_string(i) + "]",
                       "name clash: " + quote(own[i].name) +
                           " is already in the suite's model with another definition");
    }
  }
  return candidates;
}

namespace {

/// A gain that may be missing (not cross-validated): "%10.2f" or "-" right-aligned.
std::string gain_cell(double v) {
  char cell[32];
  if (std::isfinite(v)) {
    std::snprintf(cell, sizeof cell, "%10.2f", v);
  } else {
    std::snprintf(cell, sizeof cell, "%10s", "-");
  }
  return cell;
}

/// The candidates that were significant but not adopted, each with why.
void write_decisions(std::ostream& out, const Diagnosis& d) {
  bool header = false;
  for (const Candidate& c : d.candidates) {
    if (c.decision.empty() || c.verdict == "adopted") continue;
    if (!header) out << "\nNot adopted:\n";
    header = true;
    out << "  - " << c.effect << ": " << c.decision << "\n";
  }
}

}  // namespace

std::string folds_text(const Folds& folds) {
  if (folds.size() < 2) return "no cross-validation (a suite of one experiment): candidates judged in-sample";
  const std::string what = folds.by == "kind" ? "kind of path" : folds.by == "group" ? "group" : "fold of experiments";
  std::string names;
  for (const std::string& n : folds.names) names += (names.empty() ? "" : ", ") + n;
  return "the significant candidates' gain in log-likelihood on each " + what + " (" + names +
         ") when fitted without it, summed (- : not cross-validated)";
}

void write_ranking(std::ostream& out, const Suite& suite, const Diagnosis& d) {
  out << "odomcov diagnose: " << suite.name << " (" << d.runs << " runs), family-wise alpha = "
      << d.alpha << " over " << d.candidates.size() << " candidates\n"
      << "before: log-likelihood " << fixed(d.before.log_likelihood, 2) << ", NEES mean "
      << fixed(d.before.nees_mean, 3) << ", " << d.before.verdict << " ("
      << calibration_text(d.before.calibration) << ")\n"
      << "tails: " << (d.kurtosis.valid ? std::string(d.heavy_tails ? "heavy" : "Gaussian") +
                                              " (Mardia kurtosis z = " + fixed(d.kurtosis.statistic, 2) +
                                              ", p = " + sci(d.kurtosis.p_value, 2) + ")"
                                        : "not testable (" + no_kurtosis_reason(suite) + ")")
      << "\n\n";
  int width = 24;  // wider for group_variation(<effect>.<parameter>)
  for (const Candidate& c : d.candidates) width = std::max(width, static_cast<int>(c.effect.size()));
  out << "  " << std::string("candidate").append(static_cast<std::size_t>(width) - 9, ' ')
      << "   d logL   (of)        d BIC   p-value       held out  verdict\n";
  for (const Candidate& c : d.candidates) {
    char line[300];
    std::snprintf(line, sizeof line, "  %-*s %10.2f %-8s %10.2f   %-10.3g  %s  %s%s\n", width, c.effect.c_str(),
                  c.delta_log_likelihood, c.systematic ? "full" : "scatter", c.delta_bic, c.p_value,
                  gain_cell(c.delta_held_out).c_str(), c.verdict.c_str(),
                  c.rule.empty() || c.verdict == "mimic" ? "" : (" (" + c.rule + ")").c_str());
    out << line;
  }
  out << "held out: " << folds_text(d.folds) << "\n";
  write_decisions(out, d);
  if (d.best) {
    const Candidate& b = d.candidates[*d.best];
    out << "\nMissing: " << explain(b) << "\n"
        << "Adopt it: replace the suite's robot line and its model block (if any) with these, "
           "every effect refitted with the new one:\n"
        << model_yaml(b.model)
        << "after: log-likelihood " << fixed(d.after.log_likelihood, 2) << ", NEES mean "
        << fixed(d.after.nees_mean, 3) << ", " << d.after.verdict << " ("
        << calibration_text(d.after.calibration) << ")\n";
  }
}

void write_correction(std::ostream& out, const std::optional<OdometryCorrection>& correction) {
  if (!correction) return;
  const OdometryCorrection& c = *correction;
  auto number = [](double x) { return format_number(x, "%.6g"); };
  out << "\nThe odometry corrected by the model's systematic effects (UMBmark-style): ";
  if (c.motion_dependent) {
    out << "the correction depends on the motion, so each kind of experiment has its own effective "
           "wheelbase and wheel scales (below); over all runs wheelbase "
        << number(c.parameters.wheelbase_m) << " m";
  } else {
    out << "wheelbase " << number(c.parameters.wheelbase_m) << " m";
  }
  out << ", wheel scales left " << number(c.parameters.scale_left) << ", right "
      << number(c.parameters.scale_right) << " (multiply each wheel's diameter by its scale).\n"
      << "End-pose x-y error with the runs re-integrated, before and after [mm]:\n"
      << "  kind          runs  mean before  mean after  Emax before  Emax after";
  out << (c.motion_dependent ? "  wheelbase [m]  scale left  scale right\n" : "\n");
  for (const CorrectionByKind& k : c.by_kind) {
    char line[256];
    std::snprintf(line, sizeof line, "  %-12s %5zu %12.1f %11.1f %12.1f %11.1f", k.kind.c_str(), k.runs,
                  1e3 * k.mean_xy_before_m, 1e3 * k.mean_xy_after_m, 1e3 * k.emax_before_m, 1e3 * k.emax_after_m);
    out << line;
    if (c.motion_dependent) {
      std::snprintf(line, sizeof line, "  %13.6g %11.6g %12.6g", k.parameters.wheelbase_m,
                    k.parameters.scale_left, k.parameters.scale_right);
      out << line;
    }
    out << "\n";
  }
}

namespace {

int run_diagnose(const DiagnoseOptions& opt) {
  check_alpha(opt.alpha);
  check_effect_names(opt.effects);
  if (!opt.json.empty()) check_output_path(opt.json);
  const CalibrationOptions calibration = calibration_options(opt.referee, nullptr);
  const Suite suite = load_suite(opt.suite);
  const EffectList own = load_candidates(opt.candidates, suite);
  check_order(opt.order);
  check_second_order_size(suite, opt.order);
  SuiteModel model = suite_model(suite);
  model.order = opt.order;
  check_finite_start(suite, model, "diagnosis");
  DiagnoseProgress progress;
  ProgressBar bar([&progress] { return progress.fits_done.load(); },
                  std::function<std::int64_t()>([&progress] { return progress.fits_total.load(); }),
                  "fits");
  const Diagnosis d = diagnose(suite, model, opt.alpha, opt.effects, &progress, own,
                               opt.exact ? FitPath::exact : FitPath::fast, calibration);
  bar.finish();

  std::ostringstream out;
  write_ranking(out, suite, d);
  out << "\n" << verdict_text(d);
  write_correction(out, d.odometry_correction);
  std::cout << out.str();
  if (!opt.json.empty()) write_json_atomic(opt.json, diagnosis_json(suite, model, d));
  return kExitOk;
}

}  // namespace

void setup_diagnose(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<DiagnoseOptions>();
  CLI::App* cmd = app.add_subcommand("diagnose", "Which physical effect is the model missing?");
  cmd->add_option("suite", opt->suite, "Measurement suite (YAML)")->required();
  cmd->add_option("--effects", opt->effects,
                  "Candidates to try (default: every catalogue effect not in the model, and "
                  "wheel_noise_level)")
      ->delimiter(',');
  cmd->add_option("--candidates", opt->candidates,
                  "YAML list of your own candidate effects (custom, or catalogue ones with starting "
                  "values), ranked beside the catalogue");
  cmd->add_option("--alpha", opt->alpha, "Family-wise significance level over the candidates")
      ->capture_default_str();
  cmd->add_option("--order", opt->order,
                  "Model order: 2 (default) = exact Gaussian-heading moments, 1 = first order")
      ->capture_default_str();
  add_referee_options(cmd, opt->referee);
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->add_flag("--exact", opt->exact,
                "Propagate every run at every likelihood evaluation (slow; the reference for the "
                "default linearised, re-anchored fit)");
  cmd->callback([opt, &exit_code] { exit_code = run_diagnose(*opt); });
}

}  // namespace odomcov::cli
