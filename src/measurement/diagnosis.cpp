#include "odomcov/measurement/diagnosis.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <limits>

#include "odomcov/base/format.hpp"

namespace odomcov {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::size_t run_count(const Suite& suite) {
  std::size_t n = 0;
  for (const SuiteExperiment& e : suite.experiments) n += e.runs.size();
  return n;
}

ModelSummary summarise(const Comparison& c) {
  ModelSummary s;
  s.log_likelihood = c.log_likelihood;
  s.verdict = c.verdict.name();
  s.calibration = c.calibration;
  double runs = 0;
  for (const ExperimentComparison& e : c.experiments) {
    s.nees_mean += e.nees_mean * static_cast<double>(e.n);
    runs += static_cast<double>(e.n);
  }
  s.nees_mean /= runs;
  return s;
}

std::vector<double> experiment_log_likelihoods(const std::vector<std::vector<RunResidual>>& res) {
  std::vector<double> out;
  for (const auto& ex : res) out.push_back(log_likelihood({ex}));
  return out;
}

/// The fitted parameters of a model's effects (catalogue or custom, from their EffectInfo),
/// split into systematic ones (moving the mean, fitted on the full likelihood) and random ones
/// (fitted on the scatter part, which a mean misfit cannot inflate): a random effect's, and the
/// sd of a custom effect's parameter drawn per run.
struct FittedNames {
  std::vector<std::string> systematic, random;
};
FittedNames split_fitted_names(const EffectList& effects) {
  FittedNames out;
  for (const EffectSpec& e : effects) {
    const EffectInfo& info = *info_of(e);
    for (const std::string& n : effect_candidate(info).fitted) {
      bool spread = false;
      for (const EffectParameterInfo& p : info.parameters) spread = spread || (p.random_sd && n == info.name + "." + p.name);
      (info.systematic && !spread ? out.systematic : out.random).push_back(n);
    }
  }
  return out;
}

/// Refits every effect of a model by the part of the likelihood it explains, as a block
/// coordinate step: the systematic effects on the full likelihood (random ones held), then the
/// random effects on the scatter part (systematic ones held). A random effect is thus never
/// sized by a mean misfit, and a systematic one always sees the spread the random ones give.
SuiteModel refit(const Suite& suite, const SuiteModel& model, DiagnoseProgress* progress,
                 FitPath path, ResidualCache& cache) {
  const FittedNames names = split_fitted_names(model.effects);
  SuiteModel out = model;
  std::atomic<std::int64_t>* counter = progress ? &progress->evaluations : nullptr;
  if (!names.systematic.empty()) {
    out = fit(suite, out, names.systematic, Likelihood::full, counter, path, &cache).model;
  }
  if (!names.random.empty()) {
    out = fit(suite, out, names.random, Likelihood::scatter, counter, path, &cache).model;
  }
  if (progress) ++progress->fits_done;
  return out;
}

/// The value of a fitted parameter in a model: a robot parameter ("k_left") or an effect's
/// ("wheelbase_error.Eb"); NaN when the model lacks it.
double fitted_value(SuiteModel& model, const std::string& name) {
  const std::size_t dot = name.find('.');
  if (dot == std::string::npos) {
    for (const RobotParameter& p : robot_parameters()) {
      if (p.name == name) return p.ref(model.robot);
    }
    return kNaN;
  }
  const EffectSpec* spec = find_spec(model.effects, name.substr(0, dot));
  if (!spec) return kNaN;
  const auto& ps = info_of(*spec)->parameters;
  for (std::size_t i = 0; i < ps.size() && i < spec->values.size(); ++i) {
    if (ps[i].name == name.substr(dot + 1)) return spec->values[i];
  }
  return kNaN;
}

/// True when a candidate is reported by its fitted names (a robot candidate, or a group
/// candidate whose fit spans the varied effect and group_variation), not by its effect's spec.
bool reported_by_names(const CandidateType& type) { return type.robot || type.effect != type.name; }

/// What an effect's completion sees of the suite: each experiment's planned path (none for
/// logged runs) and its runs' errors at `wheelbase_m`.
std::vector<ObservedExperiment> observed_experiments(const Suite& suite, double wheelbase_m) {
  std::vector<ObservedExperiment> data;
  for (const SuiteExperiment& ex : suite.experiments) {
    ObservedExperiment& o = data.emplace_back();
    o.path = ex.logged ? nullptr : &ex.path;
    for (const SuiteRun& r : ex.runs) o.errors.push_back(run_error(ex, r, wheelbase_m));
  }
  return data;
}

/// The candidate's reported parameters, values and standard errors from its fit: a robot or
/// group candidate's fitted parameters (named within the candidate's effect: "sd" beside
/// "wheelbase_error.Eb"); an effect's every parameter (NaN standard error where not fitted),
/// completed by the effect's own hook (EffectInfo::complete).
void describe_fit(const Suite& suite, const CandidateType& type, Eigen::Index offset,
                  const Eigen::VectorXd& se, Candidate& c) {
  if (reported_by_names(type)) {
    const std::string prefix = type.effect + ".";
    for (std::size_t i = 0; i < type.fitted.size(); ++i) {
      const std::string& n = type.fitted[i];
      const bool within = !type.effect.empty() && n.rfind(prefix, 0) == 0;
      c.parameters.push_back(within ? n.substr(prefix.size()) : n);
      c.values.push_back(fitted_value(c.model, n));
      c.stderrs.push_back(se(offset + static_cast<Eigen::Index>(i)));
    }
    return;
  }
  EffectSpec* spec = find_spec(c.model.effects, type.effect);
  const EffectInfo& info = *info_of(*spec);
  std::vector<double> stderrs(info.parameters.size(), kNaN);
  for (std::size_t p = 0; p < info.parameters.size(); ++p) {
    c.parameters.push_back(info.parameters[p].name);
    for (std::size_t i = 0; i < type.fitted.size(); ++i) {
      if (type.fitted[i] == type.effect + "." + info.parameters[p].name) {
        stderrs[p] = se(offset + static_cast<Eigen::Index>(i));
      }
    }
  }
  if (type.complete) {
    c.note = type.complete(observed_experiments(suite, c.model.robot.wheelbase_m), *spec, stderrs);
  }
  c.values = spec->values;
  c.stderrs = stderrs;
}

/// True when a parameter's "no effect" value is the closed lower edge of its range.
bool neutral_at_edge(const EffectParameterInfo& p) { return p.neutral == p.lower && !p.open_lower; }

/// The group_variation candidate varying `target` ("wheelbase_error.Eb"): it fits the varied
/// parameter too when its effect is not in the model yet (joining at its neutral value), and
/// group_variation's sd; it reads as group_variation's physics and
/// signature. On the boundary when every fitted size is (sd, and the new parameter's).
/// sd starts at its typical size, or with `neutral_start` (the fast path) at 0: the candidate
/// then does nothing at its start, so its anchor and the nuisance parameters' difference points
/// are the base model's, computed once per round (ResidualCache).
CandidateType group_candidate(const std::string& target, const EffectList& model, bool neutral_start) {
  const EffectInfo& group = *find_effect(kGroupVariation);
  const std::string effect = target.substr(0, target.find('.'));
  CandidateType c;
  c.name = std::string(kGroupVariation) + "(" + target + ")";
  c.effect = kGroupVariation;
  c.physics = group.physics + ", varying " + target;
  c.signature = group.signature;
  c.systematic = group.systematic;
  c.heavy_tails = group.heavy_tails;
  c.on_boundary = true;
  if (!find_spec(model, effect)) {
    const EffectInfo& varied = *find_effect(effect);
    EffectSpec spec{effect, {}};
    for (const EffectParameterInfo& p : varied.parameters) {
      spec.values.push_back(p.neutral);
      if (effect + "." + p.name == target) c.on_boundary = neutral_at_edge(p);
    }
    c.start.push_back(spec);
    c.fitted.push_back(target);
  }
  c.start.push_back({kGroupVariation,
                     {neutral_start ? group.parameters[0].neutral : group.parameters[0].typical}, target});
  c.fitted.push_back(std::string(kGroupVariation) + "." + group.parameters[0].name);
  c.on_boundary = c.on_boundary && neutral_at_edge(group.parameters[0]);
  return c;
}

/// The group_variation candidates: one per systematic parameter of the model's effects, and one
/// per catalogue parameter that varies between groups (EffectParameterInfo) when the model
/// lacks it. Only for suites that give groups, and when the model has no group_variation yet.
std::vector<CandidateType> group_candidates(const Suite& suite, const EffectList& model,
                                            bool neutral_start) {
  bool grouped = false;
  for (const SuiteExperiment& ex : suite.experiments) grouped = grouped || !ex.group.empty();
  if (!grouped || find_spec(model, kGroupVariation)) return {};
  std::vector<std::string> targets;
  for (const EffectSpec& e : model) {
    const EffectInfo* info = info_of(e);
    if (!info->systematic || info->grouped) continue;
    for (const EffectParameterInfo& p : info->parameters) {
      if (!p.random_sd) targets.push_back(e.name + "." + p.name);
    }
  }
  for (const EffectInfo& info : effect_catalogue()) {
    for (const EffectParameterInfo& p : info.parameters) {
      const std::string t = info.name + "." + p.name;
      const bool listed = std::find(targets.begin(), targets.end(), t) != targets.end();
      if (p.varies_between_groups && !listed) targets.push_back(t);
    }
  }
  std::vector<CandidateType> out;
  for (const std::string& t : targets) out.push_back(group_candidate(t, model, neutral_start));
  return out;
}

/// The round's candidates: the catalogue's effects not in the model (grouped ones only as group
/// candidates), the group candidates, the robot candidates; only those `only` names (by their
/// name or their effect's) when given; then the user's own candidates, each from its given
/// values (a given catalogue candidate starts there too). `neutral_start`: see group_candidate.
std::vector<CandidateType> round_candidates(const Suite& suite, const EffectList& model,
                                            const std::vector<std::string>& only,
                                            const EffectList& given, bool neutral_start) {
  std::vector<CandidateType> types;
  for (const CandidateType& t : candidate_types()) {
    if (!t.robot && !find_spec(model, t.name) && !find_effect(t.name)->grouped) types.push_back(t);
  }
  for (CandidateType& t : group_candidates(suite, model, neutral_start)) types.push_back(std::move(t));
  for (const CandidateType& t : candidate_types()) {
    if (t.robot) types.push_back(t);
  }
  if (!only.empty()) {
    std::vector<CandidateType> kept;
    for (CandidateType& t : types) {
      const bool named = std::find(only.begin(), only.end(), t.name) != only.end() ||
                         std::find(only.begin(), only.end(), t.effect) != only.end();
      if (named) kept.push_back(std::move(t));
    }
    types = std::move(kept);
  }
  for (const EffectSpec& c : given) {
    if (c.values.empty() || find_spec(model, c.name)) continue;  // nothing to fit / in the model
    auto listed = std::find_if(types.begin(), types.end(),
                               [&](const CandidateType& t) { return t.name == c.name; });
    if (listed == types.end()) listed = types.insert(types.end(), effect_candidate(*info_of(c)));
    listed->start = {c};
  }
  return types;
}

/// The signature rule for the pairs a Gaussian likelihood cannot separate
/// (EffectInfo::confused_with): when both are significant, the one the tails speak against
/// moves to just below the other (the rest of the order stands).
void apply_tail_rule(std::vector<Candidate>& candidates, const std::vector<CandidateType>& types,
                     bool heavy_tails) {
  auto at = [&](const std::string& n) {
    return std::find_if(candidates.begin(), candidates.end(), [&](const Candidate& c) { return c.effect == n; });
  };
  for (const CandidateType& type : types) {
    if (type.confused_with.empty()) continue;
    auto self = at(type.name), other = at(type.confused_with);
    if (self == candidates.end() || other == candidates.end() || !self->significant || !other->significant) continue;
    auto heavy = type.heavy_tails ? self : other, gaussian = type.heavy_tails ? other : self;
    const bool heavy_first = heavy < gaussian;
    if (heavy_tails != heavy_first) {
      auto loser = heavy_tails ? gaussian : heavy;
      auto winner = heavy_tails ? heavy : gaussian;
      std::rotate(loser, loser + 1, winner + 1);  // loser now sits right after the winner
    }
  }
}

/// What every candidate fit of a round shares: the suite and the fit settings, the model
/// before the round (`before`: its comparison, whose kurtosis scales random candidates' tests)
/// and the base every candidate must improve on, the model's own effects refitted, with their
/// names by kind and the base's log-likelihoods (full, scatter part, per experiment).
struct Round {
  const Suite& suite;
  const Comparison& before;
  bool heavy_tails;
  DiagnoseProgress* progress;
  FitPath path;
  ResidualCache& cache;
  FittedNames nuisance;
  SuiteModel base;
  double base_full = 0.0, base_scatter = 0.0;
  std::vector<double> base_by_experiment;
};

/// The round's base: each candidate refits the model's effects of its own kind with it
/// (systematic ones on the full likelihood, random ones on the scatter part); the others stay
/// at these refitted values.
Round start_round(const Suite& suite, const SuiteModel& model, const Comparison& before,
                  bool heavy_tails, DiagnoseProgress* progress, FitPath path, ResidualCache& cache) {
  Round round{suite, before, heavy_tails, progress, path, cache, split_fitted_names(model.effects),
              refit(suite, model, progress, path, cache), 0.0, 0.0, {}};
  const auto& base_residuals = cache.at(round.base);
  round.base_full = log_likelihood(base_residuals);
  round.base_scatter = scatter_log_likelihood(base_residuals);
  round.base_by_experiment = experiment_log_likelihoods(base_residuals);
  return round;
}

/// The p-value of a fitted candidate's likelihood-ratio test on its part of the likelihood:
/// chi^2 with its own parameters as degrees of freedom, halved on the boundary.
double candidate_p_value(const Round& round, const CandidateType& type, const Candidate& c) {
  double lr = 2.0 * c.delta_log_likelihood;
  // Heavy tails widen the null distribution of a Gaussian variance LRT by the kurtosis factor
  // (the scaled test of [Browne84]); the same factor compare uses.
  const Comparison& before = round.before;
  if (!c.systematic && round.heavy_tails && before.mardia_b2 > before.mardia_expected) {
    lr /= before.mardia_b2 / before.mardia_expected;
  }
  lr = std::max(0.0, lr);
  return lr == 0.0 ? 1.0 : (type.on_boundary ? 0.5 : 1.0) * chi2_sf(lr, c.dof);
}

/// The (at most two) experiments where the candidate raised the full log-likelihood most over
/// the base, with their gains.
std::vector<std::pair<std::string, double>> evidence_of(
    const Round& round, const std::vector<std::vector<RunResidual>>& candidate_residuals) {
  const std::vector<double> by_experiment = experiment_log_likelihoods(candidate_residuals);
  std::vector<std::pair<std::string, double>> gains;
  for (std::size_t e = 0; e < round.suite.experiments.size(); ++e) {
    gains.push_back({round.suite.experiments[e].name, by_experiment[e] - round.base_by_experiment[e]});
  }
  std::sort(gains.begin(), gains.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
  std::vector<std::pair<std::string, double>> evidence;
  for (std::size_t i = 0; i < gains.size() && i < 2; ++i) {
    if (gains[i].second > 0) evidence.push_back(gains[i]);
  }
  return evidence;
}

/// Fits one candidate on the base with the nuisance parameters of its kind and judges it:
/// delta log-likelihood on its part of the likelihood, delta BIC, p-value, its reported
/// parameters and where it showed most.
Candidate fit_candidate(const Round& round, const CandidateType& type, double log_runs) {
  Candidate c;
  c.effect = type.name;
  c.physics = type.physics;
  c.signature = type.signature;
  c.robot = type.robot;
  c.systematic = type.systematic;
  std::vector<std::string> fitted = c.systematic ? round.nuisance.systematic : round.nuisance.random;
  const std::vector<std::string>& own = type.fitted;
  fitted.insert(fitted.end(), own.begin(), own.end());
  const Likelihood kind = c.systematic ? Likelihood::full : Likelihood::scatter;
  SuiteModel start = round.base;
  start.effects.insert(start.effects.end(), type.start.begin(), type.start.end());
  const FitResult f = fit(round.suite, start, fitted, kind,
                          round.progress ? &round.progress->evaluations : nullptr, round.path, &round.cache);
  // With heavy tails the observed information understates the uncertainty: sandwich SEs.
  const Eigen::VectorXd& se = round.heavy_tails ? f.robust_stderrs : f.stderrs;
  c.model = f.model;
  c.dof = static_cast<int>(own.size());
  // Each candidate is judged on the part of the likelihood it explains: the full one for a
  // systematic effect, the scatter part for a random one (whose extra variance would
  // otherwise also "explain" any mean misfit). The gains are on one scale; delta BIC ranks.
  c.delta_log_likelihood = f.log_likelihood_after - (c.systematic ? round.base_full : round.base_scatter);
  c.delta_bic = -2.0 * c.delta_log_likelihood + c.dof * log_runs;
  c.p_value = candidate_p_value(round, type, c);
  describe_fit(round.suite, type, static_cast<Eigen::Index>(fitted.size() - own.size()), se, c);
  const auto& candidate_residuals = round.cache.at(c.model);
  c.delta_full_log_likelihood = log_likelihood(candidate_residuals) - round.base_full;
  c.evidence = evidence_of(round, candidate_residuals);
  return c;
}

/// The decision rules: significance at alpha shared among the candidates (Bonferroni), then
/// significant candidates first, each group by delta BIC, and the tail rule.
void rank_candidates(Diagnosis& d, const std::vector<CandidateType>& types) {
  const double per_candidate = d.alpha / static_cast<double>(std::max<std::size_t>(1, d.candidates.size()));
  for (Candidate& c : d.candidates) c.significant = c.p_value < per_candidate;
  std::stable_sort(d.candidates.begin(), d.candidates.end(), [&](const Candidate& a, const Candidate& b) {
    return a.significant != b.significant ? a.significant : a.delta_bic < b.delta_bic;
  });
  apply_tail_rule(d.candidates, types, d.heavy_tails);
}

/// Simulated replicates per step of match_tails, and its steps at most.
constexpr std::int64_t kTailReplicates = 49;
constexpr int kTailSteps = 4;

/// An adopted effect whose tails the Gaussian likelihood cannot see (EffectInfo::rescale_tails,
/// bumps): its impulse size is set so that the model's own simulated world has the data's
/// pooled Mardia kurtosis, a simulated method of moments. At a fixed variance the excess
/// kurtosis grows as the square of the impulse size, so a few fixed-point steps settle it; the
/// variance, and so every Gaussian likelihood, is unchanged. Returns a note for the report ("" when
/// nothing was done: no such effect, no experiment of 10 runs, or no excess kurtosis in the
/// data).
std::string match_tails(const Suite& suite, SuiteModel& model, const std::string& effect,
                        ResidualCache& cache, std::uint64_t seed) {
  EffectSpec* spec = find_spec(model.effects, effect);
  const TailRescale rescale = spec ? info_of(*spec)->rescale_tails : nullptr;
  if (!rescale) return "";
  const std::vector<std::vector<RunResidual>> res = cache.at(model);
  CalibrationOptions gaussian;
  gaussian.method = CalibrationMethod::gaussian;
  const Comparison data = compare(suite, model, kDiagnoseAlpha, res, gaussian);
  const double excess = data.mardia_b2 - data.mardia_expected;
  if (!data.kurtosis.valid || !(excess > 0)) return "";
  for (int step = 0; step < kTailSteps; ++step) {
    const double model_excess = simulated_kurtosis(suite, model, res, kTailReplicates, seed) - data.mardia_expected;
    if (!(model_excess > 0)) break;
    const double factor = std::clamp(std::sqrt(excess / model_excess), 0.1, 10.0);
    rescale(*spec, factor);
    if (std::abs(factor - 1.0) < 0.02) break;
  }
  return "the impulse size then set so that the model's simulated world has the data's Mardia "
         "kurtosis, " + format_number(data.mardia_b2, "%.3g") + " (simulated method of moments)";
}

/// Adopts the best (significant) candidate: its model with everything refitted by its part of
/// the likelihood, now that the new effect is in (the earlier effects were sized without it),
/// its tails matched to the data's (match_tails), and its reported values from that model.
void adopt_best(Diagnosis& d, const std::vector<CandidateType>& types, const Round& round,
                std::uint64_t seed) {
  d.best = 0;
  Candidate& best = d.candidates.front();
  // (When every effect is of the candidate's kind and nothing was completed after its fit,
  // the candidate's own fit was already that refit: all of them jointly on its likelihood.)
  const CandidateType& type = *std::find_if(
      types.begin(), types.end(), [&](const CandidateType& t) { return t.name == best.effect; });
  bool other_kind = type.complete != nullptr;
  for (const EffectSpec& e : best.model.effects) {
    other_kind = other_kind || info_of(e)->systematic != best.systematic;
  }
  if (other_kind) best.model = refit(round.suite, best.model, round.progress, round.path, round.cache);
  if (const std::string note = match_tails(round.suite, best.model, type.effect, round.cache, seed); !note.empty()) {
    best.note += (best.note.empty() ? "" : "; ") + note;
  }
  if (reported_by_names(type)) {
    for (std::size_t i = 0; i < type.fitted.size(); ++i) {
      best.values[i] = fitted_value(best.model, type.fitted[i]);
    }
  } else {
    // completed ones stay, fitted ones refitted
    best.values = find_spec(best.model.effects, type.effect)->values;
  }
}

/// The outcome: the final model (the best candidate's, else the suite's) compared again, its
/// corrected odometry and, when it still misfits, what the misfit lines up with.
void explain_outcome(Diagnosis& d, const Suite& suite, const SuiteModel& model, ResidualCache& cache,
                     const CalibrationOptions& calibration) {
  d.after = d.best ? summarise(compare(suite, d.candidates[*d.best].model, d.alpha,
                                       cache.at(d.candidates[*d.best].model), calibration))
                   : d.before;
  d.explained = d.after.verdict == "consistent";
  d.odometry_correction = odometry_correction(suite, d.best ? d.candidates[*d.best].model : model);
  if (!d.explained) {
    const SuiteModel& final_model = d.best ? d.candidates[*d.best].model : model;
    d.residuals = residual_alignment(suite, final_model, cache.at(final_model));
  }
}

}  // namespace

Diagnosis diagnose(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::string>& only, DiagnoseProgress* progress,
                   const EffectList& candidates, FitPath path, const CalibrationOptions& calibration) {
  // Every exact propagation of the round, kept: the fast path's anchors and difference points
  // around the base model are shared by all candidates.
  ResidualCache cache(suite);
  Diagnosis d;
  d.alpha = alpha;
  d.runs = run_count(suite);
  const Comparison before = compare(suite, model, alpha, cache.at(model), calibration);
  d.before = summarise(before);
  d.kurtosis = before.kurtosis;
  d.heavy_tails = d.kurtosis.valid && d.kurtosis.statistic > 0 && d.kurtosis.p_value < alpha;

  // The model's own effects, refitted: the reference every candidate must improve on.
  const Round round = start_round(suite, model, before, d.heavy_tails, progress, path, cache);
  const std::vector<CandidateType> types =
      round_candidates(suite, model.effects, only, candidates, path == FitPath::fast);

  // The fits: the base refit, one per candidate and the winner's refit.
  if (progress) progress->fits_total = static_cast<std::int64_t>(types.size()) + 2;
  const double log_runs = std::log(static_cast<double>(d.runs));
  for (const CandidateType& type : types) {
    d.candidates.push_back(fit_candidate(round, type, log_runs));
    if (progress) ++progress->fits_done;
  }

  rank_candidates(d, types);
  if (!d.candidates.empty() && d.candidates.front().significant) adopt_best(d, types, round, calibration.seed);
  if (progress) progress->fits_done = progress->fits_total.load();
  explain_outcome(d, suite, model, cache, calibration);
  return d;
}

std::string explain(const Candidate& c) {
  std::string text = c.physics + ": ";
  const std::string& signature = c.signature;
  for (std::size_t i = 0; i < c.parameters.size(); ++i) {
    text += (i ? ", " : "") + c.parameters[i] + " = " + format_number(c.values[i], "%.6g");
    if (std::isfinite(c.stderrs[i])) text += " +/- " + format_number(c.stderrs[i], "%.1g");
  }
  text += "; " + signature;
  if (!c.evidence.empty()) {
    text += "; it showed most in " + c.evidence[0].first + " (log-likelihood +" +
            format_number(c.evidence[0].second, "%.3g") + ")";
    if (c.evidence.size() > 1) {
      text += " and " + c.evidence[1].first + " (+" + format_number(c.evidence[1].second, "%.3g") + ")";
    }
  }
  if (!c.note.empty()) text += " [" + c.note + "]";
  return text;
}

std::string verdict_text(const Diagnosis& d) {
  if (d.explained) {
    return std::string(d.best ? "With it the model is consistent with the data"
                              : "No candidate is significant, and the model is consistent with the "
                                "data") +
           " (compare at alpha = " + format_number(d.alpha, "%.3g") + "): it explains them.\n";
  }
  std::string text = d.best ? "Even with it, the model is still inconsistent with the data"
                            : "No candidate is significant, but the model is still inconsistent "
                              "with the data";
  text += " (compare at alpha = " + format_number(d.alpha, "%.3g") + ", NEES mean " +
          format_number(d.after.nees_mean, "%.3g") + " against 3): " +
          (d.best ? "adopt it and run diagnose again for the next effect.\n"
                  : "something the candidates do not cover is missing.\n");
  std::size_t shown = 0;
  for (const ResidualAlignment& a : d.residuals) {
    if (!a.testable || shown == 3) break;
    if (shown == 0) {
      text += a.p_value < d.alpha
                  ? "The remaining misfit lines up with (mean: the experiments' mean errors; scatter: their "
                    "spread; p family-wise over the features and parts):\n"
                  : "The remaining misfit lines up with no path feature at alpha; the closest "
                    "(p family-wise over the features and parts):\n";
    }
    if (shown > 0 && !(a.p_value < d.alpha)) break;
    text += "  " + a.feature + ", " + a.part + " (p = " + format_number(a.p_value, "%.2g") + "): " +
            a.description + "\n";
    ++shown;
  }
  if (shown == 0) text += "No path feature varies across the experiments enough to test.\n";
  return text;
}

std::string candidate_yaml(const Candidate& c, const SuiteModel& model) {
  if (c.robot) {
    Robot robot = model.robot;
    for (std::size_t i = 0; i < c.parameters.size(); ++i) {
      for (const RobotParameter& p : robot_parameters()) {
        if (p.name == c.parameters[i]) p.ref(robot) = c.values[i];
      }
    }
    return robot_yaml(robot);
  }
  // The effects the candidate adds, in its model's order: a group candidate's varied effect
  // (when new) before group_variation, so the lines pasted under model.effects never repeat an
  // effect the suite has.
  std::string text;
  for (const EffectSpec& e : c.model.effects) {
    if (!find_spec(model.effects, e.name)) text += (text.empty() ? "" : "\n") + effect_yaml(e);
  }
  return text;
}

}  // namespace odomcov
