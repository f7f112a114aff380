// What diagnose and calibrate write: their JSON documents (docs/json.md) and diff_drive.yaml,
// shared by the command line and the Python module (which returns them as dicts, so both give
// the same keys).
#include "calibrate_output.hpp"

#include <cmath>
#include <sstream>

#include "odomcov/base/format.hpp"
#include "output.hpp"
#include "referee_options.hpp"

namespace odomcov::cli {
namespace {

/// The menu's best entries the JSON lists under next_experiments, and the report shows.
constexpr std::size_t kNextInJson = 10;
constexpr std::size_t kNextInReport = 3;

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

/// Corrected parameters as JSON.
json parameters_json(const CorrectedParameters& p) {
  return {{"wheelbase", p.wheelbase_m}, {"scale_left", p.scale_left}, {"scale_right", p.scale_right}};
}

/// One candidate's decision (docs/json.md, "diagnose"): its gains in the mean and held out,
/// per fold, its verdict and the rule that stopped it.
json decision_json(const Candidate& c) {
  json folds = json::array();
  for (const Candidate::FoldGain& g : c.held_out_by_fold) {
    folds.push_back({{"fold", g.fold}, {"gain", finite_or_null(g.gain)}, {"stderr_ratio", finite_or_null(g.stderr_ratio)},
                     {"signal", g.signal}, {"counted", g.counted}, {"contradicts", g.contradicts},
                     {"model_stderr_ratio", finite_or_null(g.model_stderr_ratio)}, {"undetermined", g.undetermined},
                     {"spread", finite_or_null(g.spread)}, {"wall", g.wall}});
  }
  return {{"exact", c.exact},
          {"tails_scale", c.tails_scale},
          {"delta_mean_log_likelihood", finite_or_null(c.delta_mean_log_likelihood)},
          {"mean_p_value", finite_or_null(c.mean_p_value)},
          {"mean_dispersion", finite_or_null(c.mean_dispersion)},
          {"mean_p_value_dispersed", finite_or_null(c.mean_p_value_dispersed)},
          {"gain_held_out", finite_or_null(c.delta_held_out)},
          {"held_out_by_fold", folds},
          {"at_bound", c.at_bound},
          {"confounded", c.confounded},
          {"confounded_with", c.confounded_with},
          {"verdict", c.verdict},
          {"rule", c.rule},
          {"decision", c.decision}};
}

}  // namespace

json correction_json(const std::optional<OdometryCorrection>& correction) {
  if (!correction) return nullptr;
  const OdometryCorrection& c = *correction;
  json kinds = json::array();
  for (const CorrectionByKind& k : c.by_kind) {
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

json residuals_json(const std::vector<ResidualAlignment>& residuals) {
  json out = json::array();
  for (const ResidualAlignment& a : residuals) {
    out.push_back({{"feature", a.feature},
                   {"part", a.part},
                   {"p_value", a.testable ? json(a.p_value) : json(nullptr)},
                   {"p_value_raw", a.testable ? json(a.p_value_raw) : json(nullptr)},
                   {"statistic", a.testable ? json(a.statistic) : json(nullptr)},
                   {"dof", {a.dof1, a.dof2}},
                   {"testable", a.testable},
                   {"description", a.description}});
  }
  return out;
}

json folds_json(const Folds& folds) { return {{"by", folds.by}, {"names", folds.names}}; }

json diagnosis_json(const Suite& suite, const SuiteModel& model, const Diagnosis& d) {
  json candidates = json::array();
  for (const Candidate& c : d.candidates) {
    json evidence = json::array();
    for (const auto& [name, gain] : c.evidence) evidence.push_back({{"experiment", name}, {"delta_log_likelihood", gain}});
    json entry = {{"effect", c.effect},
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
                  {"yaml", candidate_yaml(c, model)}};
    entry.update(decision_json(c));
    candidates.push_back(entry);
  }
  json best = nullptr;
  json after = summary_json(d.after);
  if (d.best) {
    const Candidate& b = d.candidates[*d.best];
    best = {{"effect", b.effect}, {"parameters", values_json(b, b.values)}};
    after["yaml"] = model_yaml(b.model);
  }
  json kurtosis = test_json(d.kurtosis);
  kurtosis["heavy_tails"] = d.heavy_tails;
  json report = {{"suite", suite.name},
                 {"alpha", d.alpha},
                 {"runs", d.runs},
                 {"folds", folds_json(d.folds)},
                 {"before", summary_json(d.before)},
                 {"kurtosis", kurtosis},
                 {"candidates", candidates},
                 {"best", best},
                 {"after", after},
                 {"explained", d.explained},
                 {"odometry_correction", correction_json(d.odometry_correction)}};
  if (!d.explained) report["residuals"] = residuals_json(d.residuals);  // docs/json.md: there whenever not explained
  return report;
}

namespace {

/// The estimates' correlation matrix (rows of the covariance scaled by the standard errors).
json correlation_json(const Eigen::MatrixXd& covariance) {
  json corr = json::array();
  for (Eigen::Index i = 0; i < covariance.rows(); ++i) {
    json row = json::array();
    for (Eigen::Index j = 0; j < covariance.cols(); ++j) {
      row.push_back(finite_or_null(covariance(i, j) / std::sqrt(covariance(i, i) * covariance(j, j))));
    }
    corr.push_back(row);
  }
  return corr;
}

}  // namespace

std::string design_report(const std::vector<ConfoundedPair>& confounded, const std::vector<NextExperiment>& next,
                          const std::vector<UnpredictableExperiment>& unpredictable) {
  std::ostringstream out;
  for (const ConfoundedPair& p : confounded) out << "\nConfounded: " << confounded_text(p) << "\n";
  if (!unpredictable.empty()) {
    out << "\nLeft out of the menu of next experiments, the model cannot predict them:";
    for (const UnpredictableExperiment& u : unpredictable) out << (&u == &unpredictable.front() ? " " : ", ") << u.name;
    out << " (" << unpredictable.front().name << ": " << unpredictable.front().why << ")\n";
  }
  if (next.empty()) return out.str();
  out << "\nWhat to record next (information gain, D-optimality; standard errors to expect after it):\n";
  for (std::size_t i = 0; i < next.size() && i < kNextInReport; ++i) {
    const NextExperiment& n = next[i];
    out << "  " << i + 1 << ". " << n.experiment.name << ": " << n.experiment.runs << " runs of " << n.experiment.path_yaml
        << ", gain " << format_number(n.information_gain, "%.2f") << " nats;";
    for (const auto& [name, se] : n.expected_stderr) out << " " << name << " +/- " << format_number(se, "%.2e");
    out << "\n";
  }
  return out.str();
}

json fit_json(const FitResult& r) {
  json parameters = json::object(), stderrs = json::object(), robust = json::object();
  for (std::size_t i = 0; i < r.names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    parameters[r.names[i]] = r.values(k);
    stderrs[r.names[i]] = finite_or_null(r.stderrs(k));
    robust[r.names[i]] = finite_or_null(r.robust_stderrs(k));
  }
  return {{"parameters", parameters},
          {"stderr", stderrs},
          {"stderr_robust", robust},
          {"correlation", correlation_json(r.covariance)},
          {"log_likelihood_before", r.log_likelihood_before},
          {"log_likelihood_after", r.log_likelihood_after},
          {"evaluations", r.evaluations},
          {"yaml", model_yaml(r.model)},
          {"warnings", r.warnings},
          {"at_bound", r.at_bound}};
}

json design_json(const std::vector<ConfoundedPair>& confounded, const std::vector<NextExperiment>& next,
                 const std::vector<UnpredictableExperiment>& unpredictable) {
  json pairs = json::array();
  for (const ConfoundedPair& p : confounded) {
    pairs.push_back({{"a", p.a}, {"b", p.b}, {"correlation", p.correlation}, {"text", confounded_text(p)}});
  }
  json menu = json::array();
  for (std::size_t i = 0; i < next.size() && i < kNextInJson; ++i) {
    const NextExperiment& n = next[i];
    json se = json::object();
    for (const auto& [name, v] : n.expected_stderr) se[name] = v;
    menu.push_back({{"name", n.experiment.name}, {"path", n.experiment.path_yaml}, {"runs", n.experiment.runs},
                    {"information_gain", n.information_gain}, {"expected_stderr", se}});
  }
  json left_out = json::array();
  for (const UnpredictableExperiment& u : unpredictable) left_out.push_back({{"name", u.name}, {"why", u.why}});
  return {{"confounded", pairs}, {"next_experiments", menu}, {"unpredictable_experiments", left_out}};
}

namespace {

json domain_json(const Domain& d) {
  auto range = [](const Domain::Range& r) { return json::array({r.lo, r.hi}); };
  return {{"speed", range(d.speed_mps)}, {"spin_fraction", range(d.spin_fraction)},
          {"length", range(d.length_m)}, {"duration", range(d.duration_s)}};
}

json candidates_cv_json(const CalibrateResult& c) {
  json out = json::array();
  for (std::size_t r = 0; r < c.rounds.size(); ++r) {
    for (const Candidate& x : c.rounds[r].candidates) {
      out.push_back({{"round", r + 1},
                     {"effect", x.effect},
                     {"gain_in_sample", x.delta_log_likelihood},
                     {"gain_held_out", std::isfinite(x.delta_held_out) ? json(x.delta_held_out) : json(nullptr)},
                     {"verdict", x.verdict},
                     {"rule", x.rule}});
    }
  }
  return out;
}

json stand_ins_json(const std::vector<StandIn>& stand_ins) {
  json out = json::array();
  for (const StandIn& s : stand_ins) {
    out.push_back({{"effect", s.effect}, {"parameter", s.parameter}, {"feature", s.feature},
                   {"halves", s.halves}, {"values", s.value}, {"stderr", s.stderr_}, {"phi", s.phi},
                   {"z", s.z}, {"p_value", s.p_value}, {"level", s.level}, {"text", s.text}});
  }
  return out;
}

json by_kind_json(const NeesByKind& nees) {
  json kinds = json::object();
  for (const auto& [kind, value] : nees) kinds[kind] = value;
  return kinds;
}

json holdout_json(const HoldoutSummary& h) {
  json refitted = nullptr;
  if (h.refitted) {
    refitted = fit_json(h.refitted->fit);
    refitted["nees_mean"] = h.refitted->nees_mean;
    refitted["by_kind"] = by_kind_json(h.refitted->nees_by_kind);
  }
  json predictive = nullptr;
  if (h.predictive) {
    const HoldoutSummary::Predictive& p = *h.predictive;
    json parameters = json::array();
    for (const auto& q : p.parameters) {
      parameters.push_back({{"name", q.name}, {"prior_sd", q.prior_sd > 0 ? json(q.prior_sd) : json(nullptr)},
                            {"posterior_sd", q.posterior_sd}, {"shift", q.shift}, {"sized", q.sized},
                            {"spread", q.spread}});
    }
    predictive = {{"plugin_nees_mean", p.plugin_nees_mean}, {"plugin_by_kind", by_kind_json(p.plugin_by_kind)},
                  {"sized_nees_mean", p.sized_nees_mean}, {"sized_by_kind", by_kind_json(p.sized_by_kind)},
                  {"nees_mean", p.nees_mean}, {"by_kind", by_kind_json(p.nees_by_kind)},
                  {"parameters", parameters}};
  }
  return {{"nees_mean", finite_or_null(h.summary.nees_mean)}, {"verdict", h.summary.verdict},
          {"cannot_predict", h.cannot_predict},
          {"log_likelihood", finite_or_null(h.summary.log_likelihood)}, {"experiments", h.experiments},
          {"consistent_experiments", h.consistent}, {"by_kind", by_kind_json(h.nees_by_kind)},
          {"extrapolation", h.extrapolation}, {"refitted", refitted}, {"predictive", predictive}};
}

json diff_drive_json(const DiffDriveParameters& p) {
  return {{"wheel_separation_multiplier", p.wheel_separation_multiplier},
          {"left_wheel_radius_multiplier", p.left_wheel_radius_multiplier},
          {"right_wheel_radius_multiplier", p.right_wheel_radius_multiplier},
          {"pose_covariance_diagonal", p.pose_covariance_diagonal},
          {"twist_covariance_diagonal", p.twist_covariance_diagonal},
          {"motion_dependent", p.motion_dependent}};
}

}  // namespace

json calibrate_json(const Suite& suite, const SuiteModel& start, const CalibrateResult& c, double alpha,
                      const json& holdout_compare) {
  json rounds = json::array();
  SuiteModel model = start;
  for (const Diagnosis& d : c.rounds) {
    rounds.push_back(diagnosis_json(suite, model, d));
    if (d.best) model = d.candidates[*d.best].model;
  }
  json out = {{"suite", suite.name}, {"alpha", alpha}, {"order", start.order}, {"rounds", rounds},
              {"named", c.named}, {"explained", c.explained}, {"candidates_cv", candidates_cv_json(c)},
              {"after", summary_json(c.after)},
              {"model", {{"yaml", model_yaml(c.model)}, {"domain", domain_json(*c.model.domain)},
                         {"joint_fit_adopted", c.joint_adopted}, {"joint_fit_note", c.joint_note}}},
              {"odometry_correction", correction_json(c.odometry_correction)},
              {"diff_drive", diff_drive_json(c.diff_drive)}};
  out.update(design_json(c.confounded, c.next_experiments, c.unpredictable_experiments));
  out["unresolved"] = c.unresolved;
  out["simplified"] = c.simplified;
  out["stand_ins"] = stand_ins_json(c.stand_ins);
  out["after"]["by_kind"] = by_kind_json(c.nees_by_kind);
  out["joint_fit"] = c.joint.names.empty() ? json(nullptr) : fit_json(c.joint);
  if (!c.explained) out["residuals"] = residuals_json(c.residuals);
  if (c.holdout) {
    out["holdout"] = holdout_json(*c.holdout);
    if (!holdout_compare.is_null()) out["holdout"]["compare"] = holdout_compare;
  }
  return out;
}

namespace {

std::string number(double v, const char* format = "%.6g") { return format_number(v, format); }

std::string list_yaml(const std::vector<double>& v) {
  std::string text = "[";
  for (std::size_t i = 0; i < v.size(); ++i) text += (i ? ", " : "") + format_number(v[i], "%.6g");
  return text + "]";
}

}  // namespace

std::string diff_drive_yaml(const Suite& suite, const DiffDriveParameters& p) {
  std::ostringstream out;
  out << "# diff_drive_controller parameters calibrated by odomcov from " << suite.name << ".\n"
      << "# The multipliers apply to the nominal wheel_separation (" << number(p.nominal_wheelbase_m)
      << " m) and wheel radii of your controller's configuration.\n";
  if (p.motion_dependent) {
    out << "# The calibrated correction depends on the motion (e.g. a turn-dependent wheelbase); one multiplier\n"
           "# cannot follow it: these are its averages over the training runs.\n";
  }
  out << "# Covariances: of the pose after " << number(p.pose_distance_m) << " m straight at " << number(p.speed_mps, "%.3g")
      << " m/s, and of the twist over one\n# update at " << number(p.rate_hz) << " Hz; z, roll and pitch (vz, wx, wy) "
      << number(kUnusedVariance) << " (not observed).\n"
      << "diff_drive_controller:\n  ros__parameters:\n"
      << "    wheel_separation_multiplier: " << number(p.wheel_separation_multiplier, "%.9g") << "\n"
      << "    left_wheel_radius_multiplier: " << number(p.left_wheel_radius_multiplier, "%.9g") << "\n"
      << "    right_wheel_radius_multiplier: " << number(p.right_wheel_radius_multiplier, "%.9g") << "\n"
      << "    pose_covariance_diagonal: " << list_yaml(p.pose_covariance_diagonal) << "\n"
      << "    twist_covariance_diagonal: " << list_yaml(p.twist_covariance_diagonal) << "\n";
  return out.str();
}

}  // namespace odomcov::cli
