#include "odomcov/measurement/calibrate.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <map>

#include "odomcov/base/format.hpp"
#include "odomcov/measurement/domain.hpp"
#include "odomcov/measurement/residual_features.hpp"

namespace odomcov {
namespace {

/// The diagnose rounds: each adopts at most one candidate; the loop stops when one adopts
/// nothing or after `rounds`.
void run_rounds(const Suite& suite, const SuiteModel& start, const CalibrateOptions& options,
                DiagnoseProgress* progress, ResidualCache& cache, CalibrateResult& out) {
  SuiteModel model = start;
  for (int round = 0; round < options.rounds; ++round) {
    if (progress) progress->round = round + 1;
    cache.age();
    out.rounds.push_back(diagnose(suite, model, options.diagnose, progress, cache));
    const Diagnosis& d = out.rounds.back();
    if (!d.best) break;
    out.named.push_back(d.candidates[*d.best].effect);
    model = d.candidates[*d.best].model;
  }
  out.loop_model = model;
}

bool named_noise_level(const std::vector<std::string>& named) {
  return std::find(named.begin(), named.end(), kWheelNoiseLevel) != named.end();
}

/// True when a group_variation of `model` varies a parameter of `effect`.
bool varied_by_group(const SuiteModel& model, const std::string& effect) {
  return std::any_of(model.effects.begin(), model.effects.end(),
                     [&](const EffectSpec& e) { return e.target.rfind(effect + ".", 0) == 0; });
}

/// The loop's model fitted on the full likelihood over every parameter joint_fit refits.
FitResult fit_all(const Suite& suite, const SuiteModel& model, bool noise_level, const CalibrateOptions& options,
                  DiagnoseProgress* progress, ResidualCache& cache) {
  const std::vector<std::string> names = joint_parameters(model, noise_level);
  std::atomic<std::int64_t>* counter = progress ? &progress->evaluations : nullptr;
  const FitResult fast = fit(suite, model, names, Likelihood::full, counter, options.diagnose.path, &cache);
  return refit_exactly(fast, names, Likelihood::full, counter, cache);
}

/// The nested rule once more, on the loop's model. An adopted effect that contains a simpler
/// one (EffectInfo::contains) beat it against the model of its own round; an effect adopted
/// later may explain what its extra parameters took up then (a wheel diameter ratio's share of
/// the arcs' heading, taken up by a turn-dependent wheelbase before the ratio was in). With
/// every effect refitted, it is replaced by the simpler one unless Wilks's likelihood ratio of
/// the two is significant at the level of its round's decision (alpha over the candidates).
/// The fits share `cache` with the joint fit, which starts from the same model.
void simplify_nested(const Suite& suite, const CalibrateOptions& options, DiagnoseProgress* progress,
                     ResidualCache& cache, CalibrateResult& out) {
  if (out.rounds.empty()) return;
  const double level = options.diagnose.alpha / static_cast<double>(std::max<std::size_t>(1, out.rounds.back().candidates.size()));
  const bool noise = named_noise_level(out.named);
  for (std::size_t i = 0; i < out.loop_model.effects.size(); ++i) {
    const EffectSpec rich = out.loop_model.effects[i];
    const EffectInfo* info = info_of(rich);
    if (!info || info->contains.empty() || varied_by_group(out.loop_model, rich.name)) continue;
    const FitResult with_rich = fit_all(suite, out.loop_model, noise, options, progress, cache);
    for (const std::string& simpler : info->contains) {
      const EffectInfo* s = find_effect(simpler);
      if (!s || find_spec(out.loop_model.effects, simpler)) continue;
      SuiteModel start = out.loop_model;
      start.effects[i] = EffectSpec{simpler, {}};
      for (const EffectParameterInfo& p : s->parameters) start.effects[i].values.push_back(p.neutral);
      const FitResult with_simple = fit_all(suite, start, noise, options, progress, cache);
      const int dof = static_cast<int>(with_rich.names.size() - with_simple.names.size());
      const double ratio = 2.0 * (with_rich.log_likelihood_after - with_simple.log_likelihood_after);
      const double p = ratio > 0 ? boost::math::cdf(boost::math::complement(boost::math::chi_squared(std::max(1, dof)), ratio)) : 1.0;
      if (p < level || !with_simple.at_bound.empty()) continue;
      out.simplified.push_back(rich.name + " replaced by " + simpler + ", which it contains: with every effect refitted it fits only " +
                               format_number(0.5 * ratio, "%.3g") + " better in log-likelihood (likelihood ratio p = " +
                               format_number(p, "%.2g") + ", not significant at " + format_number(level, "%.2g") + ")");
      std::replace(out.named.begin(), out.named.end(), rich.name, simpler);
      out.loop_model = with_simple.model;
      break;
    }
  }
}

/// The joint fit of everything in the loop's model, on the full likelihood; kept as the final
/// model unless a parameter ends at a bound or the NEES mean moves further from 3 than the
/// loop's model has it (moves_nees_away).
void joint_fit(const Suite& suite, const CalibrateOptions& options, DiagnoseProgress* progress, ResidualCache& cache,
               CalibrateResult& out) {
  const bool noise = named_noise_level(out.named);
  out.model = out.loop_model;
  if (joint_parameters(out.loop_model, noise).empty()) {
    out.joint_note = "nothing to fit";
    return;
  }
  out.joint = fit_all(suite, out.loop_model, noise, options, progress, cache);
  if (!out.joint.at_bound.empty()) {
    out.joint_note = "not taken: the joint fit leaves parameters at a bound of their range";
    for (const std::string& p : out.joint.at_bound) out.joint_note += (p == out.joint.at_bound.front() ? " (" : ", ") + p;
    out.joint_note += "); the loop's model stands";
    return;
  }
  // Only the NEES means are read: the Gaussian reference (no referee replicates) is enough.
  const double alpha = options.diagnose.alpha;
  CalibrationOptions gaussian;
  gaussian.method = CalibrationMethod::gaussian;
  const ModelSummary loop = summarise(compare(suite, out.loop_model, alpha, cache.at(out.loop_model), gaussian));
  const ModelSummary joint = summarise(compare(suite, out.joint.model, alpha, cache.at(out.joint.model), gaussian));
  std::size_t runs = 0;
  for (const SuiteExperiment& ex : suite.experiments) runs += ex.runs.size();
  if (moves_nees_away(loop, joint, runs)) {
    out.joint_note = "not taken: it moves the NEES mean from " + format_number(loop.nees_mean, "%.3g") + " to " +
                     format_number(joint.nees_mean, "%.3g") + ", further from 3; the loop's model stands";
    return;
  }
  out.joint_adopted = true;
  out.model = out.joint.model;
  out.joint_note = "taken: log-likelihood " + format_number(loop.log_likelihood, "%.6g") + " -> " +
                   format_number(joint.log_likelihood, "%.6g");
}

/// Where the design (confounding, next experiments) is computed: the final model with its
/// jointly fitted parameters, plus every effect the last round stopped because the runs do not
/// separate it from the model's ("confounded"), at its fitted values, its parameters beside the
/// model's. Such an effect is not in the model, but the runs cannot rule it out either: the
/// next experiment should be the one that sizes it. The design then has no observed
/// covariance (estimate_covariance uses the expected information).
FitResult design_point(CalibrateResult& out) {
  FitResult at = out.joint;
  at.model = out.model;
  if (out.rounds.empty()) return at;
  for (const Candidate& c : out.rounds.back().candidates) {
    if (c.rule != "confounded" || c.robot) continue;
    for (const EffectSpec& spec : c.model.effects) {
      if (find_spec(at.model.effects, spec.name) || spec.name == kGroupVariation) continue;
      const std::vector<std::string> fitted = effect_candidate(*info_of(spec)).fitted;
      at.model.effects.push_back(spec);
      at.names.insert(at.names.end(), fitted.begin(), fitted.end());
      out.unresolved.push_back(spec.name);
    }
  }
  if (!out.unresolved.empty()) at.covariance.resize(0, 0);
  return at;
}

/// The final model's account: compare, residuals, corrected odometry, what the runs cannot
/// separate and what to record next.
void account(const Suite& suite, const CalibrateOptions& options, ResidualCache& cache, CalibrateResult& out) {
  const Comparison& c = cache.comparison(out.model, options.diagnose.alpha, options.diagnose.calibration);
  out.after = summarise(c);
  out.explained = c.verdict.consistent();
  if (!out.explained) out.residuals = residual_alignment(cache, out.model);
  out.odometry_correction = odometry_correction(suite, out.model);
  FitResult at = design_point(out);
  if (at.names.empty()) return;
  out.confounded = confounded_pairs(at.names, estimate_covariance(suite, at));
  out.next_experiments = next_experiments(suite, at);
}

/// The model's covariance of the end-pose error after `length_m` of straight line at
/// `speed_mps`, sampled at `rate_hz` (no measurement noise).
Matrix3 line_covariance(const Suite& suite, SuiteModel model, double length_m, double speed_mps, double rate_hz) {
  Suite line = suite;
  line.experiments.clear();
  SuiteExperiment ex;
  ex.name = "line";
  ex.path.sample_rate_hz = rate_hz;
  ex.path.keyframes = keyframes_from_segments({{PathSegment::Kind::line, length_m, 0.0, 0.0}},
                                              model.robot.wheelbase_m, speed_mps);
  ex.runs.push_back({"1", Vector3::Zero(), {}, {}});
  line.experiments.push_back(std::move(ex));
  model.measurement_noise = {};
  const RunResidual r = residuals(line, model)[0][0];
  return r.cov + r.group_column * r.group_column.transpose() + r.group_column2 * r.group_column2.transpose();
}

/// The median of the training runs' mean wheel speeds.
double median_speed(const Suite& suite) {
  std::vector<double> v;
  for (const SuiteExperiment& ex : suite.experiments) {
    for (const SuiteRun& run : ex.runs) v.push_back(path_features(ex, run, suite.robot.wheelbase_m).speed_mps);
  }
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

DiffDriveParameters diff_drive_parameters(const Suite& suite, const SuiteModel& model) {
  DiffDriveParameters p;
  p.nominal_wheelbase_m = model.robot.wheelbase_m;
  if (const auto c = odometry_correction(suite, model)) {
    p.wheel_separation_multiplier = c->parameters.wheelbase_m / model.robot.wheelbase_m;
    p.left_wheel_radius_multiplier = c->parameters.scale_left;
    p.right_wheel_radius_multiplier = c->parameters.scale_right;
    p.motion_dependent = c->motion_dependent;
  }
  p.speed_mps = median_speed(suite);
  if (!(p.speed_mps > 0)) p.speed_mps = 0.1;  // nothing moved: any speed, the covariance is per distance
  const Matrix3 pose = line_covariance(suite, model, p.pose_distance_m, p.speed_mps, p.rate_hz);
  const double period = 1.0 / p.rate_hz;
  const Matrix3 step = line_covariance(suite, model, p.speed_mps * period, p.speed_mps, p.rate_hz) / (period * period);
  p.pose_covariance_diagonal = {pose(0, 0), pose(1, 1), kUnusedVariance, kUnusedVariance, kUnusedVariance, pose(2, 2)};
  p.twist_covariance_diagonal = {step(0, 0), step(1, 1), kUnusedVariance, kUnusedVariance, kUnusedVariance, step(2, 2)};
  return p;
}

std::vector<std::string> joint_parameters(const SuiteModel& model, bool noise_level) {
  std::vector<std::string> names;
  for (const EffectSpec& e : model.effects) {
    const std::vector<std::string> fitted = effect_candidate(*info_of(e)).fitted;
    names.insert(names.end(), fitted.begin(), fitted.end());
  }
  if (noise_level) {
    names.emplace_back("k_left");
    names.emplace_back("k_right");
  }
  return names;
}

HoldoutSummary judge_holdout(const Suite& holdout, const SuiteModel& model, double alpha,
                             const CalibrationOptions& calibration) {
  HoldoutSummary out;
  out.comparison = compare(holdout, model, alpha, calibration);
  out.summary = summarise(out.comparison);
  std::vector<std::string> kinds;
  std::map<std::string, std::pair<double, double>> nees;  // kind -> (sum of NEES, runs)
  for (std::size_t e = 0; e < holdout.experiments.size(); ++e) {
    const ExperimentComparison& c = out.comparison.experiments[e];
    const std::string kind = experiment_kind(holdout.experiments[e]);
    if (!nees.count(kind)) kinds.push_back(kind);
    nees[kind].first += c.nees_mean * static_cast<double>(c.n);
    nees[kind].second += static_cast<double>(c.n);
    ++out.experiments;
    out.consistent += c.verdict.consistent();
    for (const std::string& x : c.extrapolation) out.extrapolation.push_back(c.name + ": " + x);
  }
  for (const std::string& k : kinds) out.nees_by_kind.push_back({k, nees[k].first / nees[k].second});
  return out;
}

CalibrateResult calibrate(const Suite& suite, const SuiteModel& start, const CalibrateOptions& options,
                      const Suite* holdout, DiagnoseProgress* progress) {
  CalibrateResult out;
  // Every exact propagation and verdict, kept for the whole loop: each round's base refit
  // starts where the previous round's winner ended, and the nested checks' fits, the joint fit
  // and the final account start from the loop's model.
  ResidualCache cache(suite);
  run_rounds(suite, start, options, progress, cache, out);
  if (progress && progress->cancel.load()) throw Cancelled();
  simplify_nested(suite, options, progress, cache, out);
  joint_fit(suite, options, progress, cache, out);
  account(suite, options, cache, out);
  out.model.domain = training_domain(suite, out.model.robot.wheelbase_m);
  out.diff_drive = diff_drive_parameters(suite, out.model);
  if (holdout) {
    SuiteModel judged = out.model;
    judged.measurement_noise = holdout->measurement_noise;
    out.holdout = judge_holdout(*holdout, judged, options.diagnose.alpha, options.diagnose.calibration);
  }
  return out;
}

}  // namespace odomcov
