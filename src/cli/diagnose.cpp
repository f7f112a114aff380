// odomcov diagnose SUITE.yaml [--effects a,b,...] [--candidates FILE.yaml] [--alpha A] [--json FILE]
// Which physical effect is the model missing? Fitted size, evidence, and the YAML to add it.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>

#include "commands.hpp"
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

json summary_json(const ModelSummary& s) {
  json out = {{"log_likelihood", s.log_likelihood}, {"nees_mean", s.nees_mean}, {"verdict", s.verdict}};
  out.update(calibration_json(s.calibration));
  return out;
}

json values_json(const Candidate& c, const std::vector<double>& values) {
  json out = json::object();
  for (std::size_t i = 0; i < c.parameters.size(); ++i) {
    out[c.parameters[i]] = std::isfinite(values[i]) ? json(values[i]) : json(nullptr);
  }
  return out;
}

/// --effects: catalogue names, wheel_noise_level or group_variation(<effect>.<parameter>).
void check_effect_names(const std::vector<std::string>& effects) {
  for (const std::string& e : effects) {
    const std::string effect = e.substr(0, e.find('('));  // group_variation(wheelbase_error.Eb)
    if (e != kWheelNoiseLevel && !find_effect(effect)) throw UsageError("--effects: unknown effect '" + e + "'");
  }
}

/// --candidates FILE: the user's own hypotheses, each with a parameter to fit. A candidate the
/// suite's model already has (the same catalogue effect, or a custom one with the same
/// definition, adopted in an earlier round) is left out, as the catalogue's are; a custom one
/// with the name of a different effect in the model is a clash.
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

/// The report's head, the candidates' table and the named effect with the model to adopt.
void write_ranking(std::ostream& out, const Suite& suite, const Diagnosis& d) {
  out << "odomcov diagnose: " << suite.name << " (" << d.runs << " runs), family-wise alpha = "
      << d.alpha << " over " << d.candidates.size() << " candidates\n"
      << "before: log-likelihood " << fixed(d.before.log_likelihood, 2) << ", NEES mean "
      << fixed(d.before.nees_mean, 3) << ", " << d.before.verdict << " ("
      << calibration_text(d.before.calibration) << ")\n"
      << "tails: " << (d.kurtosis.valid ? std::string(d.heavy_tails ? "heavy" : "Gaussian") +
                                              " (Mardia kurtosis z = " + fixed(d.kurtosis.statistic, 2) +
                                              ", p = " + sci(d.kurtosis.p_value, 2) + ")"
                                        : std::string("not testable (no experiment has 10 runs)"))
      << "\n\n";
  int width = 24;  // wider for group_variation(<effect>.<parameter>)
  for (const Candidate& c : d.candidates) width = std::max(width, static_cast<int>(c.effect.size()));
  out << "  " << std::string("candidate").append(static_cast<std::size_t>(width) - 9, ' ')
      << "   d logL   (of)        d BIC   p-value     significant\n";
  for (const Candidate& c : d.candidates) {
    char line[300];
    std::snprintf(line, sizeof line, "  %-*s %10.2f %-8s %10.2f   %-10.3g  %s\n", width, c.effect.c_str(),
                  c.delta_log_likelihood, c.systematic ? "full" : "scatter", c.delta_bic, c.p_value,
                  c.significant ? "yes" : "no");
    out << line;
  }
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

/// Corrected parameters as JSON.
json parameters_json(const CorrectedParameters& p) {
  return {{"wheelbase", p.wheelbase_m}, {"scale_left", p.scale_left}, {"scale_right", p.scale_right}};
}

/// The corrected odometry (UMBmark-style) in words, and as JSON (null without one).
json write_correction(std::ostream& out, const Diagnosis& d) {
  if (!d.odometry_correction) return nullptr;
  const OdometryCorrection& c = *d.odometry_correction;
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
  json kinds = json::array();
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
    json kind = parameters_json(k.parameters);
    kind.update({{"kind", k.kind}, {"runs", k.runs}, {"mean_xy_before", k.mean_xy_before_m},
                 {"mean_xy_after", k.mean_xy_after_m}, {"emax_sys_before", k.emax_before_m},
                 {"emax_sys_after", k.emax_after_m}});
    kinds.push_back(kind);
  }
  json all = parameters_json(c.parameters);
  all.update({{"motion_dependent", c.motion_dependent}, {"by_kind", kinds}});
  return all;
}

/// docs/json.md, "JSON of diagnose".
json diagnosis_json(const Suite& suite, const SuiteModel& model, const Diagnosis& d, const json& correction) {
  json candidates = json::array();
  for (const Candidate& c : d.candidates) {
    json evidence = json::array();
    for (const auto& [name, gain] : c.evidence) evidence.push_back({{"experiment", name}, {"delta_log_likelihood", gain}});
    candidates.push_back({{"effect", c.effect},
                          {"parameters", values_json(c, c.values)},
                          {"stderr", values_json(c, c.stderrs)},
                          {"delta_log_likelihood", c.delta_log_likelihood},
                          {"likelihood", c.systematic ? "full" : "scatter"},
                          {"delta_full_log_likelihood", c.delta_full_log_likelihood},
                          {"delta_bic", c.delta_bic},
                          {"p_value", c.p_value},
                          {"dof", c.dof},
                          {"significant", c.significant},
                          {"evidence", evidence},
                          {"explanation", explain(c)},
                          {"yaml", candidate_yaml(c, model)}});
  }
  json best = nullptr;
  json after = summary_json(d.after);
  if (d.best) {
    const Candidate& b = d.candidates[*d.best];
    best = {{"effect", b.effect}, {"parameters", values_json(b, b.values)}};
    after["yaml"] = model_yaml(b.model);
  }
  json residuals = json::array();
  for (const ResidualAlignment& a : d.residuals) {
    residuals.push_back({{"feature", a.feature},
                         {"part", a.part},
                         {"p_value", a.testable ? json(a.p_value) : json(nullptr)},
                         {"p_value_raw", a.testable ? json(a.p_value_raw) : json(nullptr)},
                         {"statistic", a.testable ? json(a.statistic) : json(nullptr)},
                         {"dof", {a.dof1, a.dof2}},
                         {"testable", a.testable},
                         {"description", a.description}});
  }
  json kurtosis = test_json(d.kurtosis);
  kurtosis["heavy_tails"] = d.heavy_tails;
  json report = {{"suite", suite.name},
                 {"alpha", d.alpha},
                 {"runs", d.runs},
                 {"before", summary_json(d.before)},
                 {"kurtosis", kurtosis},
                 {"candidates", candidates},
                 {"best", best},
                 {"after", after},
                 {"explained", d.explained},
                 {"odometry_correction", correction}};
  if (!d.explained) report["residuals"] = residuals;  // docs/json.md: there whenever not explained
  return report;
}

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
  const json correction = write_correction(out, d);
  std::cout << out.str();
  if (!opt.json.empty()) write_json_atomic(opt.json, diagnosis_json(suite, model, d, correction));
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
