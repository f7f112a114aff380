#include "odomcov/measurement/diagnosis.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <utility>

#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/measurement/design.hpp"
#include "odomcov/measurement/residual_features.hpp"

namespace odomcov {

double lrt_p_value(double delta, int dof, bool on_boundary) {
  const double lr = std::max(0.0, 2.0 * delta);
  return lr == 0.0 ? 1.0 : (on_boundary ? 0.5 : 1.0) * chi2_sf(lr, dof);
}

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInfinity = std::numeric_limits<double>::infinity();

std::size_t run_count(const Suite& suite) {
  std::size_t n = 0;
  for (const SuiteExperiment& e : suite.experiments) n += e.runs.size();
  return n;
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
/// Returns the model and the parameters the fits left at a bound.
struct Refit {
  SuiteModel model;
  std::vector<std::string> at_bound;
};
Refit refit(const Suite& suite, const SuiteModel& model, DiagnoseProgress* progress,
            FitPath path, ResidualCache& cache) {
  const FittedNames names = split_fitted_names(model.effects);
  Refit out{model, {}};
  std::atomic<std::int64_t>* counter = progress ? &progress->evaluations : nullptr;
  for (const auto& [fitted, kind] : {std::pair{&names.systematic, Likelihood::full},
                                     std::pair{&names.random, Likelihood::scatter}}) {
    if (fitted->empty()) continue;
    const FitResult f = fit(suite, out.model, *fitted, kind, counter, path, &cache);
    out.model = f.model;
    out.at_bound.insert(out.at_bound.end(), f.at_bound.begin(), f.at_bound.end());
  }
  if (progress) ++progress->fits_done;
  return out;
}

/// The value of a fitted parameter in a model (fitted_parameter); NaN when the model lacks it.
double fitted_value(SuiteModel& model, const std::string& name) {
  try {
    return fitted_parameter(model, name);
  } catch (const std::invalid_argument&) {
    return kNaN;
  }
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
  c.on_boundary = true;
  if (!find_spec(model, effect)) {
    const EffectInfo& varied = *find_effect(effect);
    EffectSpec spec{effect, {}};
    for (const EffectParameterInfo& p : varied.parameters) {
      spec.values.push_back(p.neutral);
      if (effect + "." + p.name == target) c.on_boundary = p.neutral_at_edge();
    }
    c.start.push_back(spec);
    c.fitted.push_back(target);
  }
  c.start.push_back({kGroupVariation,
                     {neutral_start ? group.parameters[0].neutral : group.parameters[0].typical}, target});
  c.fitted.push_back(std::string(kGroupVariation) + "." + group.parameters[0].name);
  c.on_boundary = c.on_boundary && group.parameters[0].neutral_at_edge();
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

/// How far each experiment's runs scatter about their own mean beyond what the model predicts
/// for them: phi_e, the Pearson statistic of its runs about their own mean over its expectation
/// (scatter_ratio; 3 (n - 1) for runs that share one covariance), each run conditioned on the
/// earlier runs of its group, at least 1 (1 for an experiment of one run). Under a Gaussian
/// model it is independent of the experiment's mean error, whose variance it scales when the
/// model's covariance is too small there (noise that grows with speed, slip on some paths): the
/// within-experiment estimate of the quasi-likelihood's dispersion, one per experiment
/// [McCullagh89, §9.2].
std::vector<double> scatter_ratios(const std::vector<std::vector<RunResidual>>& residuals) {
  std::vector<double> ratio;
  std::vector<Vector3> r;
  std::vector<Matrix3> cov;
  for (const std::vector<RunResidual>& runs : condition_on_groups(residuals)) {
    r.clear(), cov.clear();
    for (const RunResidual& x : runs) r.push_back(x.error - x.mean), cov.push_back(x.cov);
    ratio.push_back(std::max(1.0, scatter_ratio(r, cov).value_or(1.0)));
  }
  return ratio;
}

/// The residuals with each experiment's covariance, its group columns' part included, scaled
/// by its scatter ratio.
std::vector<std::vector<RunResidual>> inflated(std::vector<std::vector<RunResidual>> residuals,
                                               const std::vector<double>& ratio) {
  for (std::size_t e = 0; e < residuals.size(); ++e) {
    for (RunResidual& x : residuals[e]) {
      x.cov *= ratio[e];
      x.group_column *= std::sqrt(ratio[e]);
      x.group_column2 *= std::sqrt(ratio[e]);
    }
  }
  return residuals;
}

/// Folds with the base's fits on them (its own effects of each kind refitted on each fold's
/// training runs), computed once per round when first needed.
struct FoldSet {
  Folds folds;
  std::optional<FoldFits> base_full, base_scatter;
  std::size_t size() const { return folds.size(); }
};

/// The base's most significant feature of one part of the residual alignment, when significant
/// at the family-wise alpha; computed once per round, when first needed.
struct BaseFeature {
  std::optional<ResidualAlignment> feature;
  bool done = false;
};

/// What every candidate fit of a round shares: the suite and the fit settings, the model
/// before the round (`before`, its comparison) and the base every candidate must improve on,
/// the model's own effects refitted, with their names by kind and the base's log-likelihoods
/// (full, scatter part, per experiment); the folds and, once computed, the base's held-out
/// log-likelihood of each part.
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
  std::vector<double> base_by_experiment = {};
  /// The base's residuals with each experiment's covariance scaled by the scatter of its own
  /// runs (scatter_ratios; the largest ratio and its experiment), and their log-likelihood: the
  /// base against which a systematic candidate's gain in the mean is judged as a quasi-likelihood
  /// (overdispersed).
  std::vector<std::vector<RunResidual>> base_inflated = {};
  double base_inflated_log_likelihood = 0.0;
  double max_scatter_ratio = 1.0;
  std::string max_scatter_experiment = {};
  FoldSet folds = {};   // the suite's (make_folds)
  FoldSet within = {};  // K folds over the experiments (experiment_folds), every kind in training
  FoldSet across = {};  // the halves of the base's mean feature (feature_folds), once it is known
  std::optional<ResidualAlignment> base_mean_feature = {};  // the base's, when significant (across_feature)
  bool base_mean_done = false;
  /// The round's full model (the base with every significant candidate judged on the mean) and
  /// the names it fits, fitted the first time a candidate needs it (full_model_dispersion).
  SuiteModel full = {};
  std::vector<std::string> full_names = {};
  std::optional<MeanDispersion> full_dispersion = {};
  BaseFeature scatter_feature = {};  // the base's most significant scatter feature (scatter_shape)
  std::uint64_t seed = kDefaultRefereeSeed;  // the referee's, for match_tails' simulated worlds
  BaseFeature run_feature = {};  // the base's most significant run feature (run_by_run)
  /// The base's own world has heavy tails (heavy_tailed_effect: bumps): tails_scale applies
  /// whatever the kurtosis test says.
  bool heavy_tailed_world = false;

  std::atomic<std::int64_t>* counter() const { return progress ? &progress->evaluations : nullptr; }
  /// Throws Cancelled when the caller asked to stop.
  void check_cancel() const {
    if (progress && progress->cancel.load()) throw Cancelled();
  }
};

/// The round's base: each candidate refits the model's effects of its own kind with it
/// (systematic ones on the full likelihood, random ones on the scatter part); the others stay
/// at these refitted values.
Round start_round(const Suite& suite, const SuiteModel& model, const Comparison& before,
                  bool heavy_tails, DiagnoseProgress* progress, FitPath path, ResidualCache& cache) {
  Round round{suite, before, heavy_tails, progress, path, cache, split_fitted_names(model.effects),
              refit(suite, model, progress, path, cache).model};  // the rest as declared
  round.heavy_tailed_world = heavy_tailed_effect(round.base.effects);
  const auto& base_residuals = cache.at(round.base);
  round.base_full = log_likelihood(base_residuals);
  round.base_scatter = scatter_log_likelihood(base_residuals);
  round.base_by_experiment = experiment_log_likelihoods(base_residuals);
  const std::vector<double> ratio = scatter_ratios(base_residuals);
  round.base_inflated = inflated(base_residuals, ratio);
  round.base_inflated_log_likelihood = log_likelihood(round.base_inflated);
  for (std::size_t e = 0; e < ratio.size(); ++e) {
    if (ratio[e] > round.max_scatter_ratio) {
      round.max_scatter_ratio = ratio[e];
      round.max_scatter_experiment = suite.experiments[e].name;
    }
  }
  return round;
}

/// The p-value of a gain `delta` in the mean with `dof` parameters under the dispersion `d`:
/// the likelihood ratio when phi is 1, else the quasi-likelihood F = (2 delta/dof)/phi ~
/// F(dof, d.dof) [McCullagh89, §9.3]; halved on the boundary [Self87].
double mean_p_value(double delta, int dof, bool on_boundary, const MeanDispersion& d) {
  if (!(d.phi > 1.0) || dof <= 0) return lrt_p_value(delta, dof, on_boundary);
  const double f = std::max(0.0, 2.0 * delta) / (dof * d.phi);
  if (f == 0.0) return 1.0;
  const boost::math::fisher_f_distribution<double> dist(dof, d.dof);
  return (on_boundary ? 0.5 : 1.0) * boost::math::cdf(boost::math::complement(dist, f));
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

/// One candidate of the round: its kind, its fit (for the exact refit and the held-out
/// folds) and what diagnose reports of it.
struct Trial {
  const CandidateType* type = nullptr;
  std::vector<std::string> fitted;  // the nuisance of its kind, then its own
  Likelihood kind = Likelihood::full;
  SuiteModel start;
  FitResult fit;
  Candidate c;
  /// A systematic candidate's gain in the mean against the base's residuals with each
  /// experiment's covariance scaled by the scatter of its own runs (Round::base_inflated).
  double mean_gain_inflated = kNaN;
};

/// Fits one candidate on the base with the nuisance parameters of its kind (the fit path of
/// the round: the fast path, unless diagnose --exact).
Trial fit_trial(const Round& round, const CandidateType& type) {
  Trial t;
  t.type = &type;
  t.fitted = type.systematic ? round.nuisance.systematic : round.nuisance.random;
  t.fitted.insert(t.fitted.end(), type.fitted.begin(), type.fitted.end());
  t.kind = type.systematic ? Likelihood::full : Likelihood::scatter;
  t.start = round.base;
  t.start.effects.insert(t.start.effects.end(), type.start.begin(), type.start.end());
  t.fit = fit(round.suite, t.start, t.fitted, t.kind, round.counter(), round.path, &round.cache);
  return t;
}

/// The base's residuals with the candidate's predicted means: what the candidate does to the
/// mean alone, under the base's covariances and group columns.
std::vector<std::vector<RunResidual>> with_means(const std::vector<std::vector<RunResidual>>& candidate,
                                                 std::vector<std::vector<RunResidual>> base) {
  for (std::size_t e = 0; e < base.size(); ++e) {
    for (std::size_t r = 0; r < base[e].size(); ++r) base[e][r].mean = candidate[e][r].mean;
  }
  return base;
}

/// True for a grouped candidate (group_variation), which acts through the correlation of a
/// group's runs, neither on each run's mean nor on the spread within an experiment.
bool grouped(const Trial& t, const SuiteModel& model) {
  const EffectInfo* info = t.type->effect.empty() ? nullptr : find_effect(t.type->effect, model.effects);
  return info && info->grouped;
}

/// True for a candidate judged on what it does to the mean: systematic and not grouped.
bool judged_on_mean(const Trial& t, const SuiteModel& model) { return t.type->systematic && !grouped(t, model); }

/// The largest |correlation| of the estimates of a fit's own parameters (from index `first`
/// on) with the parameters before them, the model's effects refitted beside them; 1 when an own
/// parameter has no standard error while the others have (singular or at a bound).
void confounding(const FitResult& fit, std::size_t first, Candidate& c) {
  const Eigen::MatrixXd& cov = fit.covariance;
  if (first > 0 && !cov.allFinite()) {  // a singular information: nothing separates them
    c.confounded = 1.0;
    c.confounded_with = "the model's effects (singular information)";
    return;
  }
  for (std::size_t i = first; i < fit.names.size(); ++i) {
    const auto a = static_cast<Eigen::Index>(i);
    for (std::size_t j = 0; j < first; ++j) {
      const auto b = static_cast<Eigen::Index>(j);
      double r = std::abs(cov(a, b) / std::sqrt(cov(a, a) * cov(b, b)));
      if (!std::isfinite(r)) r = std::isfinite(cov(b, b)) && !std::isfinite(cov(a, a)) ? 1.0 : 0.0;
      if (r > c.confounded) {
        c.confounded = r;
        c.confounded_with = fit.names[j];
      }
    }
  }
}

/// The factor by which heavy tails inflate a random candidate's likelihood ratio. The Gaussian
/// likelihood's ratio for a variance parameter is chi^2 only when the errors are Gaussian: its
/// score's variance grows with their kurtosis, and the ratio is then about c chi^2 with c the
/// sandwich variance of the estimate over the observed information's [Kent82] (for several
/// parameters, c their mean: the ratio scaled to its mean). A mean parameter's
/// score does not depend on the kurtosis, so a systematic candidate keeps 1; so does every
/// candidate of a round whose errors are not heavy-tailed (neither against the model by the
/// kurtosis test nor in the model's own world: heavy_tailed_effect); c is never taken below 1.
double tails_scale(const Round& round, const Trial& t) {
  const bool gaussian = !round.heavy_tails && !round.heavy_tailed_world;
  if (gaussian || t.type->systematic || t.fit.robust_stderrs.size() != t.fit.stderrs.size()) return 1.0;
  const Eigen::Index own = static_cast<Eigen::Index>(t.type->fitted.size());
  const Eigen::Index first = static_cast<Eigen::Index>(t.fit.names.size()) - own;
  double sum = 0.0;
  Eigen::Index counted = 0;
  for (Eigen::Index k = first; k < first + own; ++k) {
    const double naive = t.fit.stderrs(k), robust = t.fit.robust_stderrs(k);
    if (!(std::isfinite(naive) && std::isfinite(robust) && naive > 0.0)) continue;
    sum += (robust * robust) / (naive * naive);
    ++counted;
  }
  return counted == 0 ? 1.0 : std::max(1.0, sum / static_cast<double>(counted));
}

/// A candidate of `type` before any judgement: its name, physics and kind.
Candidate unjudged(const CandidateType& type) {
  Candidate c;
  c.effect = type.name;
  c.physics = type.physics;
  c.signature = type.signature;
  c.robot = type.robot;
  c.systematic = type.systematic;
  return c;
}

/// Judges a fitted candidate in-sample: delta log-likelihood on its part of the likelihood,
/// delta BIC, p-value, the gain in the mean (systematic, not grouped), its reported parameters
/// and where it showed most.
void judge_in_sample(const Round& round, Trial& t, double log_runs) {
  const CandidateType& type = *t.type;
  const bool exact = t.c.exact;
  t.c = unjudged(type);
  Candidate& c = t.c;
  c.exact = exact;
  // With heavy tails the observed information understates the uncertainty: sandwich SEs.
  const Eigen::VectorXd& se = round.heavy_tails ? t.fit.robust_stderrs : t.fit.stderrs;
  c.model = t.fit.model;
  c.at_bound = t.fit.at_bound;
  c.dof = static_cast<int>(type.fitted.size());
  // Each candidate is judged on the part of the likelihood it explains: the full one for a
  // systematic effect, the scatter part for a random one (whose extra variance would
  // otherwise also "explain" any mean misfit). The gains are on one scale; delta BIC ranks.
  c.delta_log_likelihood = t.fit.log_likelihood_after - (c.systematic ? round.base_full : round.base_scatter);
  c.delta_bic = -2.0 * c.delta_log_likelihood + c.dof * log_runs;
  c.tails_scale = tails_scale(round, t);
  c.p_value = lrt_p_value(c.delta_log_likelihood / c.tails_scale, c.dof, type.on_boundary);
  describe_fit(round.suite, type, static_cast<Eigen::Index>(t.fitted.size() - type.fitted.size()), se, c);
  const auto& candidate_residuals = round.cache.at(c.model);
  c.delta_full_log_likelihood = log_likelihood(candidate_residuals) - round.base_full;
  c.evidence = evidence_of(round, candidate_residuals);
  if (judged_on_mean(t, c.model)) {
    const auto& base = round.cache.at(round.base);
    c.delta_mean_log_likelihood = log_likelihood(with_means(candidate_residuals, base)) - log_likelihood(base);
    c.mean_p_value = lrt_p_value(c.delta_mean_log_likelihood, c.dof, type.on_boundary);
    const auto candidate_inflated = with_means(candidate_residuals, round.base_inflated);
    t.mean_gain_inflated = log_likelihood(candidate_inflated) - round.base_inflated_log_likelihood;
    const MeanDispersion d =
        mean_dispersion(candidate_inflated, round.nuisance.systematic.size() + type.fitted.size());
    c.mean_dispersion = d.phi;
    c.mean_p_value_dispersed = mean_p_value(t.mean_gain_inflated, c.dof, type.on_boundary, d);
  }
  confounding(t.fit, t.fitted.size() - type.fitted.size(), c);
}

/// Significance at alpha shared among the `family` candidates considered (Bonferroni), then
/// significant candidates first, each group by delta BIC.
void rank_trials(std::vector<Trial>& trials, double alpha, std::size_t family) {
  const double per_candidate = alpha / static_cast<double>(std::max<std::size_t>(1, family));
  for (Trial& t : trials) {
    t.c.significant = t.c.p_value < per_candidate;
    t.c.verdict = t.c.significant ? "not judged" : "not significant";
  }
  std::stable_sort(trials.begin(), trials.end(), [&](const Trial& a, const Trial& b) {
    return a.c.significant != b.c.significant ? a.c.significant : a.c.delta_bic < b.c.delta_bic;
  });
}

/// Simulated replicates per step of match_tails, and its steps at most.
constexpr int kMatchReplicates = 49;
constexpr int kMatchSteps = 4;

/// A heavy-tailed effect (EffectInfo::rescale_tails, bumps) whose tails the Gaussian likelihood
/// cannot see: its impulse size is set so that the model's own simulated world has the data's
/// pooled Mardia kurtosis over every experiment of five runs or more (tails_test's pool), a
/// simulated method of moments. At a fixed variance the excess kurtosis grows as the square of
/// the impulse size, so a few fixed-point steps settle it; the variance, and so every Gaussian
/// likelihood, is unchanged. The matched world must show the data's tails typically, not only
/// on average (its median excess at least half the data's): when the effect carries too small a
/// share of the variance, only jolts so large and rare that most replicates have none reach the
/// data's mean kurtosis, and the size is then left as it was, with a note that says why.
/// Returns a note for the report ("" when nothing was done: no such effect, no experiment of
/// five runs, or no excess kurtosis in the data).
std::string match_tails(const Suite& suite, SuiteModel& model, const std::string& effect,
                        ResidualCache& cache, std::uint64_t seed) {
  EffectSpec* spec = find_spec(model.effects, effect);
  const TailRescale rescale = spec ? info_of(*spec)->rescale_tails : nullptr;
  if (!rescale) return "";
  const std::vector<std::vector<RunResidual>> res = cache.at(model);
  const std::vector<double> start = spec->values;
  bool rescaled = false;
  for (int step = 0; step < kMatchSteps; ++step) {
    const TailsTest t = tails_test(suite, model, res, kMatchReplicates, seed);
    const double excess = t.b2 - t.gaussian, model_excess = t.mean - t.gaussian;
    if (!t.valid || !(excess > 0) || !(model_excess > 0)) break;
    const double factor = std::clamp(std::sqrt(excess / model_excess), 0.1, 10.0);
    rescale(*spec, factor);
    rescaled = true;
    if (std::abs(factor - 1.0) < 0.02) break;
  }
  if (!rescaled) return "";
  const TailsTest t = tails_test(suite, model, res, kMatchReplicates, seed);  // at the size reached
  const std::string b2 = format_number(t.b2, "%.3g");
  if (!t.valid || t.model - t.gaussian < 0.5 * (t.b2 - t.gaussian)) {
    spec->values = start;
    return "the impulse size kept: the data's Mardia kurtosis, " + b2 + ", is more than " + effect +
           " carrying this share of the variance gives in a typical world of these runs (" +
           format_number(t.model, "%.3g") + " at the size that matches it on average)";
  }
  return "the impulse size then set so that the model's simulated world has the data's Mardia kurtosis, " + b2 +
         " (simulated method of moments)";
}

/// match_tails on a candidate's model; its reported values and standard errors follow (the
/// rescale is multiplicative, so each relative standard error stays).
void match_candidate_tails(const Round& round, Candidate& c, const std::string& effect) {
  const std::string note = match_tails(round.suite, c.model, effect, round.cache, round.seed);
  if (note.empty()) return;
  c.tails_note = note;  // a match before (an adoption's refit moved the rate) is replaced
  const std::vector<double>& v = find_spec(c.model.effects, effect)->values;
  for (std::size_t i = 0; i < v.size() && i < c.values.size(); ++i) {
    if (i < c.stderrs.size() && c.values[i] != 0) c.stderrs[i] *= std::abs(v[i] / c.values[i]);
    c.values[i] = v[i];
  }
}

/// The base's fits on each fold (its own effects of that kind refitted on each fold's
/// training runs), computed once per round.
const FoldFits& base_folds(const Round& round, FoldSet& set, Likelihood kind) {
  std::optional<FoldFits>& slot = kind == Likelihood::full ? set.base_full : set.base_scatter;
  if (!slot) {
    const std::vector<std::string>& names = kind == Likelihood::full ? round.nuisance.systematic : round.nuisance.random;
    slot = fit_folds(round.cache, set.folds, round.base, names, {}, kind, round.counter(), round.path);
  }
  return *slot;
}

/// The largest ratio of a fold fit's standard error to the in-sample one over the parameters
/// [first, last) of a fit's names, and the name of that parameter ("" when every ratio is 1 or
/// less). Where the fold's fit has no standard error and the in-sample fit has one, the ratio
/// is infinite, or, with `missing_is_determined`, that parameter is skipped: a model's spread
/// fitted to 0 on a fold, at the edge of its range, has none, and is pinned there, not
/// wandering.
struct StderrRatio {
  double ratio = 1.0;
  std::string name;
};

StderrRatio stderr_ratio(const std::vector<double>& fold, const Eigen::VectorXd& in_sample,
                         const std::vector<std::string>& names, std::size_t first, std::size_t last,
                         bool missing_is_determined) {
  StderrRatio most;
  for (std::size_t k = first; k < last && k < fold.size() && k < static_cast<std::size_t>(in_sample.size()); ++k) {
    const double s = in_sample(static_cast<Eigen::Index>(k));
    if (!std::isfinite(s) || s <= 0 || (missing_is_determined && !std::isfinite(fold[k]))) continue;
    const double r = std::isfinite(fold[k]) ? fold[k] / s : std::numeric_limits<double>::infinity();
    if (r > most.ratio) most = {r, names[k]};
  }
  return most;
}

/// What a candidate is judged on, against the base: its part of the likelihood, and for a
/// candidate judged on the mean, its means under the base's covariances.
std::vector<std::vector<RunResidual>> judged(const std::vector<std::vector<RunResidual>>& candidate,
                                             const std::vector<std::vector<RunResidual>>& base, bool on_mean) {
  return on_mean ? with_means(candidate, base) : candidate;
}

/// The in-sample gain of the candidate over the base on each fold's runs (what it judges
/// on): whether a fold has anything for it to predict.
std::vector<double> fold_signal(const Round& round, const Folds& folds, const Trial& t, bool on_mean) {
  const auto& base = round.cache.at(round.base);
  const auto mine = judged(round.cache.at(t.c.model), base, on_mean);
  const bool scatter = t.kind == Likelihood::scatter;
  const std::vector<double> a = run_log_likelihoods(mine, scatter), b = run_log_likelihoods(base, scatter);
  std::vector<double> out(folds.size(), 0.0);
  std::size_t i = 0;
  for (std::size_t e = 0; e < base.size(); ++e) {
    for (std::size_t r = 0; r < base[e].size(); ++r, ++i) out[static_cast<std::size_t>(folds.of_experiment[e])] += a[i] - b[i];
  }
  return out;
}

/// The candidate cross-validated: per fold, its gain in held-out log-likelihood over the base
/// (both fitted without the fold; a candidate judged on the mean by its means under the base's
/// covariances), whether the fold can test it (its training runs determine the candidate,
/// kMaxFoldStderrRatio, and the candidate changes the fold's prediction, kMinFoldSignal), and
/// in all over the folds that can; NaN when none can.
void cross_validate(const Round& round, FoldSet& set, Trial& t) {
  const Folds& folds = set.folds;
  if (round.progress) round.progress->fits_total += static_cast<std::int64_t>(folds.size());
  const FoldFits& base = base_folds(round, set, t.kind);
  const FoldFits mine = fit_folds(round.cache, folds, t.start, t.fitted, t.type->fitted, t.kind,
                                  round.counter(), round.path);
  if (round.progress) round.progress->fits_done += static_cast<std::int64_t>(folds.size());
  const bool on_mean = judged_on_mean(t, t.c.model);
  const std::size_t first_own = t.fitted.size() - t.type->fitted.size();
  const std::vector<double> signal = fold_signal(round, folds, t, on_mean);
  t.c.held_out_by_fold.clear();
  bool any = false;
  double total = 0.0;
  for (std::size_t f = 0; f < folds.size(); ++f) {
    const std::vector<bool> training = folds.training(f);
    const auto& b = round.cache.full(base.models[f], round.counter());
    const StderrRatio own = stderr_ratio(mine.stderrs[f], t.fit.stderrs, t.fitted, first_own, t.fitted.size(), false);
    const StderrRatio model = stderr_ratio(mine.stderrs[f], t.fit.stderrs, t.fitted, 0, first_own, true);
    Candidate::FoldGain g;
    g.fold = folds.names[f];
    g.stderr_ratio = own.ratio;
    g.signal = signal[f];
    g.model_stderr_ratio = model.ratio;
    const std::vector<std::vector<RunResidual>>* c = nullptr;
    try {
      c = &round.cache.full(mine.models[f], round.counter());
    } catch (const InputError& e) {
      // Fitted without the fold, a custom expression leaves its range on the fold's runs (a
      // noise factor fitted below 1 at the training runs' speeds, negative at the fold's): it
      // cannot predict them at all.
      g.wall = e.what();
      g.gain = kNaN;
      g.counted = false;
      g.contradicts = true;
      t.c.held_out_by_fold.push_back(g);
      continue;
    }
    std::vector<double> parts = held_out_parts(judged(*c, b, on_mean), training, t.kind);
    const std::vector<double> base_parts = held_out_parts(b, training, t.kind);
    for (std::size_t i = 0; i < parts.size(); ++i) parts[i] -= base_parts[i];
    g.gain = std::accumulate(parts.begin(), parts.end(), 0.0);
    g.spread = spread_of_sum(parts);
    g.parts = parts.size();
    if (model.ratio > kMaxFoldStderrRatio) g.undetermined = model.name;
    // A fold whose training runs leave a parameter of the model itself undetermined tests
    // nothing: the candidate's fit and the base's both extrapolate it there, and their
    // difference follows where each one's fit wandered (with the circles held out of June's
    // runs, the arc wheelbase, 48 times its standard error, moved by 0.014 when a diameter
    // ratio joined it, and the circles' 12.6 rad of turning made that a loss of 1475).
    const bool model_determined = model.ratio <= kMaxFoldStderrRatio;
    g.counted = model_determined && g.stderr_ratio <= kMaxFoldStderrRatio && std::abs(g.signal) >= kMinFoldSignal;
    g.contradicts = !g.counted && model_determined && std::abs(g.signal) >= kMinFoldSignal &&
                    g.stderr_ratio <= kMaxContradictionStderrRatio &&
                    g.gain < -contradiction_bound(g.stderr_ratio, t.c.dof);
    if (g.counted) total += g.gain;
    any = any || g.counted;
    t.c.held_out_by_fold.push_back(g);
  }
  t.c.delta_held_out = any ? total : kNaN;
}

/// "a (-12.3 ± 2.1), b (+4.1 ± 1.5)": the counted folds' gains with their spreads, worst first,
/// at most `most`.
std::string worst_folds(std::vector<Candidate::FoldGain> gains, std::size_t most) {
  std::sort(gains.begin(), gains.end(), [](const auto& a, const auto& b) { return a.gain < b.gain; });
  std::string text;
  for (const Candidate::FoldGain& g : gains) {
    if (!g.counted || most == 0) continue;
    text += (text.empty() ? "" : ", ") + g.fold + " (" + format_number(g.gain, "%+.3g") +
            (std::isfinite(g.spread) ? " ± " + format_number(g.spread, "%.2g") : std::string()) + ")";
    --most;
  }
  return text;
}

/// Why a fold could not test the candidate, in words.
std::string why_uncounted(const Candidate& c, const Candidate::FoldGain& g) {
  if (!g.wall.empty()) return "fitted without it, " + c.effect + " cannot predict these runs at all: " + g.wall;
  if (g.contradicts) {
    return "fitted without it, " + c.effect + " is not determined (" + format_number(g.stderr_ratio, "%.2g") +
           " times the standard error), and it loses " + format_number(-g.gain, "%.3g") +
           " there, more than that uncertainty explains: what the other runs fit is not what it wants";
  }
  const auto times = [](double ratio) {
    return std::isfinite(ratio) ? format_number(ratio, "%.2g") + " times the standard error" : std::string("no standard error");
  };
  if (g.stderr_ratio > kMaxFoldStderrRatio) return "without it " + c.effect + " is not determined: " + times(g.stderr_ratio);
  if (!g.undetermined.empty()) {
    return "without it the model's " + g.undetermined + " is not determined (" + times(g.model_stderr_ratio) +
           "): with and without " + c.effect + " the prediction there extrapolates it";
  }
  return "nothing to predict there: in-sample gain " + format_number(g.signal, "%+.2g");
}

/// The folds that could not test the candidate and those that contradict it, in words ("" for
/// none).
std::string uncounted_folds(const Candidate& c) {
  std::string against, skipped;
  for (const Candidate::FoldGain& g : c.held_out_by_fold) {
    std::string& text = g.contradicts ? against : skipped;
    if (!g.counted) text += (text.empty() ? "" : ", ") + g.fold + " (" + why_uncounted(c, g) + ")";
  }
  return (against.empty() ? "" : "; against it: " + against) + (skipped.empty() ? "" : "; not counted: " + skipped);
}

/// The mimic's verdict in words: what it imitates in-sample, and how it predicts held out.
std::string mimic_text(const Trial& t, const Folds& folds) {
  const Candidate& c = t.c;
  std::string text = c.effect + " is a mimic: fitted on all the runs it gains " +
                     format_number(c.delta_log_likelihood, "%.4g") + " in log-likelihood";
  if (!c.evidence.empty()) text += ", most in " + c.evidence[0].first;
  text += ", but fitted without each " + std::string(folds.by == "kind" ? "kind of path" : folds.by == "group" ? "group" : "fold") +
          " in turn it predicts " + (c.delta_held_out <= 0 ? "the held-out runs" : "some of them") +
          " worse than the model without it (" +
          (std::isfinite(c.delta_held_out)
               ? "in all " + format_number(c.delta_held_out, "%+.4g") + "; worst: " + worst_folds(c.held_out_by_fold, 2)
               : std::string("no fold's gain counted")) +
          uncounted_folds(c) + "). It imitates part of the misfit (" + c.signature +
          ") in the runs it is fitted on, but it is not what predicts the others: something else is missing.";
  return text;
}

/// The candidate's model with everything refitted by its part of the likelihood, now that the
/// new effect is in (the earlier effects were sized without it), and its reported values from
/// that model. Returns the parameters that refit left at a bound.
std::vector<std::string> adoption_refit(const Round& round, Trial& t) {
  Candidate& c = t.c;
  const CandidateType& type = *t.type;
  // (When every effect is of the candidate's kind and nothing was completed after its fit,
  // the candidate's own fit was already that refit: all of them jointly on its likelihood.)
  bool other_kind = type.complete != nullptr;
  for (const EffectSpec& e : c.model.effects) other_kind = other_kind || info_of(e)->systematic != c.systematic;
  std::vector<std::string> at_bound;
  if (other_kind) {
    Refit r = refit(round.suite, c.model, round.progress, round.path, round.cache);
    c.model = std::move(r.model);
    at_bound = std::move(r.at_bound);
    if (reported_by_names(type)) {
      for (std::size_t i = 0; i < type.fitted.size(); ++i) c.values[i] = fitted_value(c.model, type.fitted[i]);
    } else {
      c.values = find_spec(c.model.effects, type.effect)->values;  // completed ones stay
    }
  }
  match_candidate_tails(round, c, type.effect);
  return at_bound;
}

/// True for a candidate judged on what it does to the runs' scatter: random and not grouped.
bool judged_on_scatter(const Trial& t, const SuiteModel& model) { return !t.type->systematic && !grouped(t, model); }

/// A model's scatter features of the path, each with its family-wise p-value (residual_alignment
/// with the dispersion from the model's simulated world: Bonferroni over every feature and
/// part), best first. Not the group: a spread that differs between sessions is no shape of
/// noise along the path, and no candidate of the catalogue varies with the session, so it
/// tells none of them apart (real labs show it nearly always).
std::vector<ResidualAlignment> scatter_features(const Round& round, const SuiteModel& model) {
  const SimulatedDispersion simulated{round.seed};
  std::vector<ResidualAlignment> out;
  for (ResidualAlignment& a : residual_alignment(round.cache, model, &simulated)) {
    if (a.part == "scatter" && a.feature != "group" && a.testable) out.push_back(std::move(a));
  }
  return out;
}

/// The family-wise p-value of the base's most significant feature among `features` (of one part;
/// `base` keeps it for the round) with the candidate's model, when the base's is significant at
/// the family-wise alpha and the candidate's still is: the candidate did not explain what the
/// misfit lines up with. Empty otherwise.
std::optional<double> still_aligned(Round& round, const Trial& t, BaseFeature& base,
                                    std::vector<ResidualAlignment> (*features)(const Round&, const SuiteModel&)) {
  const double alpha = round.before.alpha;
  if (!base.done) {
    const std::vector<ResidualAlignment> found = features(round, round.base);
    if (!found.empty() && found.front().p_value < alpha) base.feature = found.front();
    base.done = true;
  }
  if (!base.feature) return {};
  for (const ResidualAlignment& a : features(round, t.c.model)) {
    if (a.feature != base.feature->feature) continue;
    if (a.p_value < alpha) return a.p_value;
    return {};
  }
  return {};
}

/// The scatter shape rule. The scatter test of residual_alignment is blind to the spread's
/// overall level (its gamma GLM fits it), so a spread that grows with a feature of the path
/// (speed, say) stays a significant feature whatever constant factor the noise takes, and a
/// noise of another shape (a slip per radian turned) leaves it too. A random candidate that
/// leaves the base's most significant scatter feature significant did not explain what the
/// scatter lines up with: it imitates a noise of another shape. The test takes each
/// experiment's dispersion from the model's simulated world (SimulatedDispersion): with it
/// estimated from the data, a misfit of other experiments dilutes the feature, and a slip per
/// radian turned took up a noise that grows with speed in blind worlds whose fast runs spin.
/// Returns the decision's words when it stops the candidate.
std::string scatter_shape(Round& round, const Trial& t) {
  const std::optional<double> p = still_aligned(round, t, round.scatter_feature, scatter_features);
  if (!p) return {};
  const ResidualAlignment& before = *round.scatter_feature.feature;
  return "not adopted: the runs' scatter lines up with " + before.feature + " (p = " +
         format_number(before.p_value, "%.2g") + "), and with " + t.c.effect + " it still does (p = " +
         format_number(*p, "%.2g") + "): it does not give the spread that shape, so it imitates a " +
         "noise of another kind: " + before.description;
}

/// A model's run part (residual_alignment): the features its runs' errors about their
/// experiment's mean follow, run by run, each with its family-wise p-value, best first; none
/// unless some experiment's runs started at different headings.
std::vector<ResidualAlignment> run_features(const Round& round, const SuiteModel& model) {
  std::vector<ResidualAlignment> out;
  if (!runs_start_at_different_headings(round.suite)) return out;
  for (ResidualAlignment& a : residual_alignment(round.cache, model)) {
    if (a.part == "run" && a.testable) out.push_back(std::move(a));
  }
  return out;
}

/// The run-by-run rule. A random candidate says that the runs scatter more than the model
/// predicts, by chance. When the runs of an experiment started at different headings and their
/// errors about the experiment's mean follow the heading (the run part of residual_alignment,
/// significant at the family-wise alpha), that spread is systematic: the heading predicts it
/// run by run, and a random effect that widens the prediction only imitates it (bumps took up a
/// sideways drift down a sloping floor in blind worlds whose runs start at random headings).
/// The test estimates its scale from the data, so a wider prediction does not weaken it: the
/// candidate is stopped when the run part stays significant with it. Returns the decision's
/// words when it stops the candidate.
std::string run_by_run(Round& round, const Trial& t) {
  const std::optional<double> p = still_aligned(round, t, round.run_feature, run_features);
  if (!p) return {};
  const ResidualAlignment& before = *round.run_feature.feature;
  return "not adopted: the runs of an experiment differ from each other along their " + before.feature +
         " (p = " + format_number(before.p_value, "%.2g") + "), and with " + t.c.effect + " they still do (p = " +
         format_number(*p, "%.2g") + "): the spread it widens the prediction for is systematic, not random: " +
         before.description;
}

/// The feature of the path the base's mean misfit lines up with most (residual_alignment; not
/// the group), when it is significant at the family-wise alpha, and the halves of the
/// experiments along it (feature_folds); computed once per round.
const ResidualAlignment* base_mean_feature(Round& round) {
  if (!round.base_mean_done) {
    for (ResidualAlignment& a : residual_alignment(round.cache, round.base)) {
      if (a.part != "mean" || a.feature == "group" || !a.testable) continue;
      if (a.p_value < round.before.alpha) {
        round.across.folds = feature_folds(
            experiment_feature_values(round.suite, round.base.robot.wheelbase_m, a.feature), a.feature);
        round.base_mean_feature = std::move(a);
      }
      break;
    }
    round.base_mean_done = true;
  }
  return round.base_mean_feature && round.across.size() >= 2 ? &*round.base_mean_feature : nullptr;
}

/// The rule across the feature. Leaving out one kind of path at a time tests a candidate
/// across kinds, but a misfit that lines up with a feature every kind shares (speed, the
/// direction of the turns or of travel) is imitated alike in every kind: a wheelbase error
/// fitted to a scale that grows with speed predicts each kind's turns at the suite's mix of
/// speeds. Its cause predicts along the feature; a mimic fitted on one side of it predicts the
/// other side worse. So a candidate judged on the mean is cross-validated once more, on the two
/// halves of the experiments along the base's most significant mean feature, and is a mimic
/// when it predicts them worse in all or a half contradicts it (a half that cannot test it does
/// not count). Unlike a kind of path, one half losing a little while the other gains more is
/// not a compromise between causes: a real effect whose size drifts along the feature does
/// that (a marker offset on the real robot's fast and slow runs: -3.8 and +16.5). Returns the
/// decision's words when it stops the candidate.
std::string across_feature(Round& round, Trial& t) {
  const ResidualAlignment* feature = base_mean_feature(round);
  if (!feature) return {};
  Candidate& c = t.c;
  // The candidate keeps its kinds' folds for the report; the halves decide here.
  std::vector<Candidate::FoldGain> by_kind = std::move(c.held_out_by_fold);
  const double kinds_total = c.delta_held_out;
  cross_validate(round, round.across, t);
  const std::vector<Candidate::FoldGain> across = std::exchange(c.held_out_by_fold, std::move(by_kind));
  const double halves = std::exchange(c.delta_held_out, kinds_total);
  const bool contradicted = std::any_of(across.begin(), across.end(), [](const Candidate::FoldGain& g) { return g.contradicts; });
  if (!(halves <= 0) && !contradicted) return {};
  std::string gains;
  for (std::size_t f = 0; f < across.size(); ++f) {
    const Candidate::FoldGain& g = across[f];
    gains += (f ? "; " : "") + std::string("fitted on the experiments with ") + across[1 - f].fold +
             ", it predicts those with " + g.fold;
    if (!g.counted && !g.contradicts) {
      gains += " (not counted: " + why_uncounted(c, g) + ")";
    } else {
      gains += std::string(g.gain < 0 ? " worse" : " better") + " than the model without it (" +
               format_number(g.gain, "%+.3g") + " in log-likelihood)";
    }
  }
  return c.effect + " is a mimic: the misfit lines up with " + feature->feature + " (p = " +
         format_number(feature->p_value, "%.2g") + "), and " + c.effect + " does not carry across it: " + gains +
         ". It imitates the misfit on each side, but it is not its cause: " + feature->description;
}

/// Stops a candidate by `rule` with the words of `decision`.
bool stop(Candidate& c, const std::string& verdict, const std::string& rule, const std::string& decision) {
  c.verdict = verdict;
  c.rule = rule;
  c.decision = decision;
  return false;
}

std::string joined(const std::vector<std::string>& list) {
  std::string text;
  for (const std::string& s : list) text += (text.empty() ? "" : ", ") + s;
  return text;
}

/// The round's full model: the base with every significant candidate judged on the mean whose
/// predicted means gain significantly (one per effect; a candidate stopped by rule 2b, "covariance,
/// not mean", fits no direction of the means), and the names to fit. A candidate's own model
/// leaves in the scatter whatever other effect the world has, so with two large effects each
/// would be judged against the other's misfit and neither adopted (the nested F test's trap in
/// forward selection); the full model's residual scatter is the one a term is tested against in
/// a multiple regression.
void plan_full_model(Round& round, const std::vector<Trial>& trials, double per_candidate) {
  round.full = round.base;
  round.full_names = round.nuisance.systematic;
  for (const Trial& t : trials) {
    if (!t.c.significant || !judged_on_mean(t, t.c.model) || reported_by_names(*t.type)) continue;
    if (std::isfinite(t.c.mean_p_value) && !(t.c.mean_p_value < per_candidate)) continue;
    const EffectSpec* spec = find_spec(t.c.model.effects, t.type->effect);
    if (!spec || find_spec(round.full.effects, t.type->effect)) continue;
    round.full.effects.push_back(*spec);
    round.full_names.insert(round.full_names.end(), t.type->fitted.begin(), t.type->fitted.end());
  }
}

/// The dispersion of the experiments' means under the round's full model, fitted jointly the
/// first time it is asked for (no degrees of freedom, dof 0, when the model has as many
/// parameters as the means have components, or its fit fails).
const MeanDispersion& full_model_dispersion(Round& round) {
  if (round.full_dispersion) return *round.full_dispersion;
  MeanDispersion d;
  d.dof = 0;
  if (round.progress) ++round.progress->fits_total;
  try {
    round.check_cancel();
    const FitResult r = fit(round.suite, round.full, round.full_names, Likelihood::full, round.counter(),
                            round.path, &round.cache);
    // Less the parameters' rank, not their count: the full model holds every significant
    // candidate, nested ones beside their containers (wheelbase_error inside
    // turn_dependent_wheelbase) and effects the runs cannot size, which fit no direction of the
    // means; counting them would leave the scatter next to no degrees of freedom and the rule
    // no power to pass anything.
    d = mean_dispersion(with_means(round.cache.at(r.model), round.base_inflated), static_cast<std::size_t>(r.rank));
  } catch (const Cancelled&) {
    throw;
  } catch (const std::exception&) {
    d.dof = 0;  // a joint fit of mimicking effects may not converge: no full model to judge by
  }
  if (round.progress) ++round.progress->fits_done;
  return *(round.full_dispersion = d);
}

/// The overdispersed-mean rule: the candidate's gain in the mean, each experiment's covariance
/// scaled by the scatter of its own runs (Round::base_inflated), stays significant at the
/// family-wise alpha against the scatter of the experiments' means that its own model leaves,
/// or failing that, the round's full model (plan_full_model; its dispersion replaces the
/// candidate's in the report when it is the smaller). When the full model has no degrees of
/// freedom left, the scatter beside every candidate cannot be estimated: the rule stands aside.
bool overdispersed(Round& round, Trial& t) {
  Candidate& c = t.c;
  if (!std::isfinite(c.mean_p_value_dispersed) || c.mean_p_value_dispersed < round.before.alpha) return false;
  const MeanDispersion& full = full_model_dispersion(round);
  if (full.dof <= 0) {
    c.mean_p_value_dispersed = kNaN;
    return false;
  }
  if (full.phi < c.mean_dispersion) {
    c.mean_dispersion = full.phi;
    c.mean_p_value_dispersed = mean_p_value(t.mean_gain_inflated, c.dof, t.type->on_boundary, full);
  }
  return !(c.mean_p_value_dispersed < round.before.alpha);
}

/// Rules 1-2 of judge, on the candidate's in-sample fit; false when one stops it.
bool passes_in_sample(Round& round, Trial& t, double per_candidate) {
  Candidate& c = t.c;
  if (!c.at_bound.empty()) {
    return stop(c, "stopped", "parameter at bound",
                "not adopted: its fit ends at the edge of the allowed range (" + joined(c.at_bound) +
                    "), so the data push it beyond any plausible size");
  }
  if (c.confounded > kConfoundedCorrelation) {
    return stop(c, "stopped", "confounded",
                "not adopted: the experiments do not separate it from " + c.confounded_with + " (correlation " +
                    format_number(c.confounded, "%.3f") +
                    "): the runs fix only a combination of the two; record an experiment that moves one of them "
                    "alone (next_experiments)");
  }
  if (std::isfinite(c.mean_p_value) && !(c.mean_p_value < per_candidate)) {
    return stop(c, "stopped", "covariance, not mean",
                "not adopted: a systematic effect, but its predicted means gain only " +
                    format_number(c.delta_mean_log_likelihood, "%.3g") + " (p = " +
                    format_number(c.mean_p_value, "%.2g") +
                    "); its gain comes from the covariance it inflates, not from the mean it should explain");
  }
  if (overdispersed(round, t)) {
    const std::string runs =
        round.max_scatter_ratio > 1.0
            ? "each experiment's runs scatter up to " + format_number(round.max_scatter_ratio, "%.3g") +
                  " times as much as the model predicts (" + round.max_scatter_experiment +
                  (c.mean_dispersion > 1.0 ? "), and with it the experiments' mean errors scatter " +
                                                 format_number(c.mean_dispersion, "%.3g") + " times as much as that"
                                           : "), and with it the experiments' mean errors scatter no more than that")
            : "with it the experiments' mean errors still scatter " + format_number(c.mean_dispersion, "%.3g") +
                  " times as much as the model predicts";
    return stop(c, "stopped", "overdispersed mean",
                "not adopted: its predicted means gain " + format_number(c.delta_mean_log_likelihood, "%.3g") +
                    " in log-likelihood (p = " + format_number(c.mean_p_value, "%.2g") +
                    " were the model's covariances right), but " + runs +
                    ", and against that scatter the gain is not significant (p = " +
                    format_number(c.mean_p_value_dispersed, "%.2g") +
                    "): it fits a little of a misfit that it does not explain");
  }
  return true;
}

/// Rule 3 of judge, on the held-out folds; false when it stops the candidate.
bool passes_held_out(Round& round, Trial& t) {
  Candidate& c = t.c;
  if (round.folds.size() < 2) return true;
  round.check_cancel();
  const Folds* used = &round.folds.folds;
  cross_validate(round, round.folds, t);
  if (!std::isfinite(c.delta_held_out) && round.within.size() >= 2) {
    // No kind of path can test it (an effect that one kind alone shows): held-out experiments
    // of each kind instead, with every kind in the training runs.
    used = &round.within.folds;
    cross_validate(round, round.within, t);
  }
  // A fold's loss is on the quasi-likelihood's scale: where the experiments' means scatter phi
  // times as much as the model predicts (mean_dispersion, a systematic candidate's), a loss of
  // phi kMaxFoldLoss weighs what kMaxFoldLoss would under a right covariance [McCullagh89, §9.3].
  const double phi = std::isfinite(c.mean_dispersion) ? c.mean_dispersion : 1.0;
  const auto tested = static_cast<std::size_t>(std::count_if(c.held_out_by_fold.begin(), c.held_out_by_fold.end(),
                                                              [](const Candidate::FoldGain& g) { return g.counted; }));
  const bool loses_a_fold = std::any_of(c.held_out_by_fold.begin(), c.held_out_by_fold.end(), [&](const Candidate::FoldGain& g) {
    return (g.counted && g.gain < -fold_loss_bound(g, phi, tested)) || g.contradicts;
  });
  if (c.delta_held_out <= 0 || loses_a_fold) return stop(c, "mimic", "held-out likelihood", mimic_text(t, *used));
  if (judged_on_mean(t, c.model)) {
    const std::string across = across_feature(round, t);
    if (!across.empty()) return stop(c, "mimic", "across the feature", across);
  }
  return true;
}

/// The rules every adoption must pass, in order; true when the candidate is adopted.
///  1. no fitted parameter at a bound of its range (not its neutral value);
///  2. a systematic candidate gains in the mean, not only by inflating the covariance: the
///     gain of its means under the base's covariances is significant at the per-candidate
///     level, and stays significant at the family-wise level against the scatter of the
///     experiments' means that its model, or the round's full model, still leaves
///     (mean_dispersion, overdispersed);
///  3. it predicts the held-out folds better than the base, and no fold worse by more than
///     kMaxFoldLoss times its mean dispersion (else it is a mimic), and a candidate judged on
///     the mean also predicts across the base's mean feature (across_feature);
///  4. its adopted model (everything refitted) has no parameter at a bound;
///  5. a random candidate explains the spread it is judged on: the runs' errors about their
///     experiment's mean do not follow their start heading (run_by_run), and the scatter's
///     shape along the path is the candidate's (scatter_shape);
///  6. its adopted model does not move the NEES mean away from 3 (moves_nees_away).
bool judge(Round& round, Trial& t, double per_candidate, const ModelSummary& before, std::size_t runs) {
  Candidate& c = t.c;
  if (!passes_in_sample(round, t, per_candidate) || !passes_held_out(round, t)) return false;
  const std::vector<std::string> bounds = adoption_refit(round, t);
  if (!bounds.empty()) {
    return stop(c, "stopped", "parameter at bound",
                "not adopted: with every effect refitted, " + joined(bounds) + " ends at the edge of its range");
  }
  if (judged_on_scatter(t, c.model)) {
    const std::string by_run = run_by_run(round, t);
    if (!by_run.empty()) return stop(c, "stopped", "run by run", by_run);
    const std::string shape = scatter_shape(round, t);
    if (!shape.empty()) return stop(c, "stopped", "scatter shape", shape);
  }
  // Only the NEES mean is read: the Gaussian reference (no referee replicates) is enough.
  CalibrationOptions gaussian;
  gaussian.method = CalibrationMethod::gaussian;
  const ModelSummary after =
      summarise(compare(round.suite, c.model, round.before.alpha, round.cache.at(c.model), gaussian));
  if (moves_nees_away(before, after, runs)) {
    return stop(c, "stopped", "NEES",
                "not adopted: it moves the NEES mean from " + format_number(before.nees_mean, "%.3g") + " to " +
                    format_number(after.nees_mean, "%.3g") + ", further from 3");
  }
  c.verdict = "adopted";
  c.decision = std::isfinite(c.delta_held_out)
                   ? "adopted: it predicts the held-out folds better (" + format_number(c.delta_held_out, "%+.4g") +
                         uncounted_folds(c) + ")"
                   : "adopted on the in-sample evidence: " +
                         std::string(round.folds.size() >= 2 ? "no fold can test it" + uncounted_folds(c)
                                                             : "no cross-validation (one experiment)");
  return true;
}

/// Vuong's statistic for two non-nested fitted candidates on their part of the likelihood
/// [Vuong89]: z = sum d_i / (sqrt(n) sd(d)), d_i the runs' log-likelihood differences
/// (spread_of_sum). Near 0 when the likelihood cannot tell the two apart.
double vuong_z(const Round& round, const Trial& a, const Trial& b) {
  const bool scatter = a.kind == Likelihood::scatter;
  std::vector<double> d = run_log_likelihoods(round.cache.at(a.c.model), scatter);
  const std::vector<double> lb = run_log_likelihoods(round.cache.at(b.c.model), scatter);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] -= lb[i];
  const double sum = std::accumulate(d.begin(), d.end(), 0.0), spread = spread_of_sum(d);
  return spread > 0 ? sum / spread : (sum == 0.0 ? 0.0 : std::copysign(kInfinity, sum));
}

/// True when the likelihood cannot tell two fitted candidates apart: |Vuong z| below the
/// two-sided point of the family-wise alpha.
bool likelihood_ties(double z, double alpha) {
  return std::abs(z) < boost::math::quantile(boost::math::complement(boost::math::normal(), 0.5 * alpha));
}

/// " the likelihood cannot tell a from b (Vuong z = z)".
std::string tie_words(const Candidate& a, const Candidate& b, double z) {
  return " the likelihood cannot tell " + a.effect + " from " + b.effect + " (Vuong z = " + format_number(z, "%.2f") + ")";
}

/// The rule for nested candidates. A candidate that contains a simpler significant one
/// (CandidateType::contains: it reduces to it exactly at some of its parameter values) is
/// adopted over it only when it fits significantly better: the likelihood ratio of the two
/// (both fitted on the same part of the likelihood, with the same nuisance), chi^2 with the
/// difference of their free parameters [Wilks38], below the per-candidate level. Otherwise the
/// simpler one, if it passes every rule, is adopted instead. Returns the adopted trial's index.
std::size_t prefer_nested_simpler(Round& round, std::vector<Trial>& trials, std::size_t best, double per_candidate,
                                  const ModelSummary& before, std::size_t runs) {
  const std::vector<std::string>& contains = trials[best].type->contains;
  for (std::size_t j = best + 1; j < trials.size() && trials[j].c.significant; ++j) {
    const Candidate& simple = trials[j].c;
    const int dof = trials[best].c.dof - simple.dof;
    if (dof <= 0 || std::find(contains.begin(), contains.end(), trials[j].type->name) == contains.end()) continue;
    const double ratio = 2.0 * (trials[best].c.delta_log_likelihood - simple.delta_log_likelihood);
    const double p = ratio > 0 ? boost::math::cdf(boost::math::complement(boost::math::chi_squared(dof), ratio)) : 1.0;
    if (p < per_candidate) continue;
    round.check_cancel();
    if (!judge(round, trials[j], per_candidate, before, runs)) continue;
    const std::string tie = trials[best].c.effect + " contains " + simple.effect + " and fits only " +
                            format_number(0.5 * ratio, "%.3g") + " better in log-likelihood (likelihood ratio p = " +
                            format_number(p, "%.2g") + ", not significant at " + format_number(per_candidate, "%.2g") + ")";
    stop(trials[best].c, "stopped", "nested", "not adopted: " + tie);
    trials[j].c.decision += "; preferred because " + tie;
    return j;
  }
  return best;
}

bool consistent_model(const Round& round, const SuiteModel& model, const CalibrationOptions& calibration) {
  return round.cache.comparison(model, round.before.alpha, calibration).verdict.consistent();
}

/// The consistency rule. The likelihood that ranks the candidates is Gaussian and blind to the
/// shape of the errors (a wheel noise level and bumps add the same variance per metre). When
/// the adopted candidate leaves the model inconsistent by compare (with its referee, which sees
/// the shape), each later significant candidate of the same part that the likelihood cannot
/// tell from it (|Vuong z| below the two-sided alpha point) and that passes every rule is
/// tried, and the first whose model compare finds consistent is adopted instead. Returns the
/// adopted trial's index.
std::size_t prefer_consistent_rival(Round& round, std::vector<Trial>& trials, std::size_t best, double per_candidate,
                                    const ModelSummary& before, std::size_t runs, const CalibrationOptions& calibration) {
  if (consistent_model(round, trials[best].c.model, calibration)) return best;
  for (std::size_t j = best + 1; j < trials.size() && trials[j].c.significant; ++j) {
    if (trials[j].c.systematic != trials[best].c.systematic) continue;
    const double z = vuong_z(round, trials[best], trials[j]);
    if (!likelihood_ties(z, round.before.alpha)) continue;
    round.check_cancel();
    if (!judge(round, trials[j], per_candidate, before, runs)) continue;
    const std::string tie = tie_words(trials[best].c, trials[j].c, z);
    if (!consistent_model(round, trials[j].c.model, calibration)) {
      stop(trials[j].c, "not judged", "", "passes every rule, but" + tie + " and neither leaves the model consistent");
      continue;
    }
    stop(trials[best].c, "stopped", "consistency",
         "not adopted:" + tie + ", and with it compare finds the model inconsistent, with " + trials[j].c.effect +
             " consistent (the shape of the errors decides)");
    trials[j].c.decision += ";" + tie + ", and only with it compare finds the model consistent";
    return j;
  }
  return best;
}

/// True for a candidate whose effect has tails that the Gaussian likelihood cannot see
/// (EffectInfo::rescale_tails: bumps).
bool heavy_tailed(const Trial& t) {
  const EffectSpec* spec = find_spec(t.c.model.effects, t.type->effect);
  return spec != nullptr && info_of(*spec)->rescale_tails != nullptr;
}

/// Replicates of a tied candidate's world behind the tails rule (tails_test): with 499 a
/// two-sided p-value can fall below alpha = 0.01 (its smallest is 2/500).
constexpr int kTailsReplicates = 499;

/// "11.3 in its world, p = 0.03": a tails_test's median in the model's world and p-value.
std::string tails_words(const TailsTest& t) {
  return format_number(t.model, "%.4g") + " in its world, p = " + format_number(t.p_value, "%.2g");
}

/// tails_test of a candidate's model against the data.
TailsTest tails_of(Round& round, const Candidate& c) {
  return tails_test(round.suite, c.model, round.cache.at(c.model), kTailsReplicates, round.seed);
}

/// What the runs' tails say on a tie between the adopted candidate `best` and a `rival` of the
/// other shape (tails_test of each model's world): the words, and whether the rival is to take
/// its place; undecided when a world could not be simulated or neither has the data's tails.
struct TailsVerdict {
  std::string words;
  bool decided = false;
  bool rival = false;
};

TailsVerdict tails_verdict(const Candidate& best, const Candidate& rival, bool best_heavy, double z,
                           const TailsTest& best_tails, const TailsTest& rival_tails, double alpha) {
  const Candidate& heavy = best_heavy ? best : rival;
  const Candidate& plain = best_heavy ? rival : best;
  const TailsTest& h = best_heavy ? best_tails : rival_tails;
  const TailsTest& g = best_heavy ? rival_tails : best_tails;
  TailsVerdict v;
  v.words = tie_words(best, rival, z);
  if (!h.valid || !g.valid) {
    v.words += ", and the tails cannot either (a model's world could not be simulated)";
    return v;
  }
  const bool heavy_shown = g.p_value < alpha;
  v.words += ", and the runs' tails (pooled Mardia kurtosis " + format_number(g.b2, "%.4g") + " over " +
             std::to_string(g.experiments) + " experiments) are ";
  if (heavy_shown && h.p_value < alpha) {
    v.words += "neither " + plain.effect + "'s world's (" + tails_words(g) + ") nor " + heavy.effect + "'s (" +
               tails_words(h) + ")";
    return v;
  }
  v.words += heavy_shown ? "heavier than " + plain.effect + "'s world gives (" + tails_words(g) + ") and as " +
                               heavy.effect + "'s gives (" + tails_words(h) + ")"
                         : "no heavier than " + plain.effect + "'s world gives (" + tails_words(g) + "; " +
                               heavy.effect + "'s: " + tails_words(h) + "): the heavy tails that would set " +
                               heavy.effect + " apart are not in the data";
  v.decided = true;
  v.rival = heavy_shown != best_heavy;
  return v;
}

/// The tails rule. A wheel noise level and bumps add the same variance per metre, so the
/// Gaussian likelihood that ranks them ties them, and the ranking then turns on their numbers of
/// parameters; compare's kurtosis test, which would see the difference, needs experiments of ten
/// runs, and a lab of a few runs per session has none. When the adopted random candidate and a
/// significant random rival of the other shape (one heavy-tailed, the other not) are a tie
/// (|Vuong z| below the two-sided alpha point), the tails decide, the heavy-tailed shape needing
/// the evidence, as a richer candidate needs it in the nested rule: each model's own world is
/// simulated and the runs' pooled Mardia kurtosis (tails_test, every experiment of five runs or
/// more) set against it. The heavy-tailed candidate is adopted when the data's tails reject the
/// other's world at the family-wise alpha and not its own; otherwise the other one. A rival
/// adopted instead must pass every rule, and leave the model consistent when the adopted one
/// does; one the tails do not decide is reported so. Returns the adopted trial's index.
std::size_t prefer_by_tails(Round& round, std::vector<Trial>& trials, std::size_t best, double per_candidate,
                            const ModelSummary& before, std::size_t runs, const CalibrationOptions& calibration) {
  if (trials[best].c.systematic) return best;
  const bool best_heavy = heavy_tailed(trials[best]);
  const double alpha = round.before.alpha;
  std::optional<TailsTest> best_tails;
  for (std::size_t j = best + 1; j < trials.size() && trials[j].c.significant; ++j) {
    Trial& rival = trials[j];
    const bool other_shape = !rival.c.systematic && heavy_tailed(rival) != best_heavy && rival.c.decision.empty();
    const double z = other_shape ? vuong_z(round, trials[best], rival) : kInfinity;
    if (!likelihood_ties(z, alpha)) continue;
    round.check_cancel();
    if (!best_tails) best_tails = tails_of(round, trials[best].c);
    if (!best_tails->valid) return best;
    if (!judge(round, rival, per_candidate, before, runs)) continue;
    const TailsVerdict v =
        tails_verdict(trials[best].c, rival.c, best_heavy, z, *best_tails, tails_of(round, rival.c), alpha);
    const bool inconsistent = v.rival && consistent_model(round, trials[best].c.model, calibration) &&
                              !consistent_model(round, rival.c.model, calibration);
    if (!v.rival || inconsistent) {
      stop(rival.c, "not judged", "",
           "passes every rule, but" + v.words + (inconsistent ? ", and with it compare finds the model inconsistent" : ""));
      if (v.decided) return best;
      continue;
    }
    stop(trials[best].c, "stopped", "tails", "not adopted:" + v.words);
    rival.c.decision += ";" + v.words;
    return j;
  }
  return best;
}

/// The outcome: the final model (the best candidate's, else the suite's) compared again, its
/// corrected odometry and, when it still misfits, what the misfit lines up with.
void explain_outcome(Diagnosis& d, const Suite& suite, const SuiteModel& model, ResidualCache& cache,
                     const CalibrationOptions& calibration) {
  d.after = d.best ? summarise(cache.comparison(d.candidates[*d.best].model, d.alpha, calibration)) : d.before;
  d.explained = d.after.verdict == "consistent";
  d.odometry_correction = odometry_correction(suite, d.best ? d.candidates[*d.best].model : model);
  if (!d.explained) {
    const SuiteModel& final_model = d.best ? d.candidates[*d.best].model : model;
    d.residuals = residual_alignment(cache, final_model);
  }
}

/// Every candidate fitted and judged in-sample, ranked: the fast path screens; then every fit
/// it could not verify (FitResult::verified) of a significant candidate, and of a user's
/// candidate (whose expressions may be arbitrarily nonlinear), is refitted exactly
/// (refit_exactly) and judged again, and the candidates are ranked again. (The catalogue's
/// candidates agree with the exact path where the fast one is verified: fast_path_test.)
/// `uncomputable` receives the candidates whose model cannot be computed on these runs at all
/// (order 2's piece limit, met as the candidate cuts the pieces: an InputError keyed "order 2"),
/// each not judged, with the reason; the others are fitted and judged.
std::vector<Trial> fit_trials(Round& round, const std::vector<CandidateType>& types, std::size_t runs, double alpha,
                              std::vector<Candidate>& uncomputable) {
  const double log_runs = std::log(static_cast<double>(runs));
  std::vector<Trial> trials;
  for (const CandidateType& type : types) {
    round.check_cancel();
    try {
      trials.push_back(fit_trial(round, type));
    } catch (const InputError& e) {
      if (e.key() != "order 2") throw;
      Candidate& c = uncomputable.emplace_back(unjudged(type));
      c.model = round.base;
      stop(c, "not judged", "uncomputable",
           "not judged: its model cannot be computed on these runs at order 2 (" + e.message() + ")");
      if (round.progress) ++round.progress->fits_done;
      continue;
    }
    judge_in_sample(round, trials.back(), log_runs);
    if (round.progress) ++round.progress->fits_done;
  }
  rank_trials(trials, alpha, types.size());
  bool refitted = false;
  for (Trial& t : trials) {
    if (t.fit.verified || !(t.c.significant || !t.type->start.empty())) continue;
    round.check_cancel();
    // A user's candidate (arbitrarily nonlinear) is refitted exactly from its given values too.
    t.fit = t.type->start.empty()
                ? refit_exactly(t.fit, t.type->fitted, t.kind, round.counter(), round.cache)
                : refit_exactly_from_both(t.fit, t.start, t.type->fitted, t.kind, round.counter(), round.cache);
    t.c.exact = true;
    judge_in_sample(round, t, log_runs);
    refitted = true;
  }
  if (refitted) rank_trials(trials, alpha, types.size());
  // A heavy-tailed candidate's impulse size, which its completion sized from the straight lines
  // alone, is matched to the tails of every experiment before any rule looks at the shape of
  // its model's errors (the consistency and tails rules); its likelihood does not change.
  for (Trial& t : trials) {
    if (!t.c.significant || !heavy_tailed(t)) continue;
    round.check_cancel();
    match_candidate_tails(round, t.c, t.type->effect);
  }
  return trials;
}

}  // namespace

double fold_loss_bound(const Candidate::FoldGain& gain, double phi, std::size_t tested) {
  const double scaled = kMaxFoldLoss * std::max(1.0, phi);
  if (!std::isfinite(gain.spread)) return scaled;
  const boost::math::students_t t(static_cast<double>(gain.parts - 1));
  const double level = kFoldLossAlpha / static_cast<double>(std::max<std::size_t>(tested, 1));
  return std::max(scaled, boost::math::quantile(boost::math::complement(t, level)) * gain.spread);
}

double contradiction_bound(double stderr_ratio, int dof) {
  const boost::math::chi_squared chi2(std::max(1, dof));
  return kMaxFoldLoss + 0.5 * stderr_ratio * stderr_ratio *
                            boost::math::quantile(boost::math::complement(chi2, kContradictionAlpha));
}

bool moves_nees_away(const ModelSummary& before, const ModelSummary& after, std::size_t runs) {
  const double tolerance = 2.0 * std::sqrt(6.0 / static_cast<double>(std::max<std::size_t>(runs, 1)));
  return std::abs(after.nees_mean - 3.0) > std::abs(before.nees_mean - 3.0) + tolerance;
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

Diagnosis diagnose(const Suite& suite, const SuiteModel& model, const DiagnoseOptions& options,
                   DiagnoseProgress* progress) {
  ResidualCache cache(suite);
  return diagnose(suite, model, options, progress, cache);
}

Diagnosis diagnose(const Suite& suite, const SuiteModel& model, const DiagnoseOptions& options,
                   DiagnoseProgress* progress, ResidualCache& cache) {
  if (&cache.suite() != &suite) throw std::invalid_argument("diagnose: the cache is of another suite");
  Diagnosis d;
  d.alpha = options.alpha;
  d.runs = run_count(suite);
  if (options.cross_validate) d.folds = make_folds(suite);
  const Comparison& before = cache.comparison(model, options.alpha, options.calibration);
  d.before = summarise(before);
  d.kurtosis = before.kurtosis;
  d.heavy_tails = d.kurtosis.valid && d.kurtosis.statistic > 0 && d.kurtosis.p_value < options.alpha;

  // The model's own effects, refitted: the reference every candidate must improve on.
  Round round = start_round(suite, model, before, d.heavy_tails, progress, options.path, cache);
  round.folds.folds = d.folds;
  if (options.cross_validate && d.folds.by != "experiments") round.within.folds = experiment_folds(suite);
  round.seed = options.calibration.seed;
  const std::vector<CandidateType> types =
      round_candidates(suite, model.effects, options.only, options.candidates, options.path == FitPath::fast);

  // The fits: the base refit, one per candidate and the winner's refit (and, as they come, the
  // finalists' folds).
  if (progress) progress->fits_total = static_cast<std::int64_t>(types.size()) + 2;
  std::vector<Candidate> uncomputable;
  std::vector<Trial> trials = fit_trials(round, types, d.runs, options.alpha, uncomputable);
  // Every candidate considered counts in the family, the uncomputable ones too (as in rank_trials).
  const double per_candidate = options.alpha / static_cast<double>(std::max<std::size_t>(1, types.size()));
  plan_full_model(round, trials, per_candidate);
  for (std::size_t i = 0; i < trials.size() && trials[i].c.significant && !d.best; ++i) {
    if (judge(round, trials[i], per_candidate, d.before, d.runs)) d.best = i;
  }
  if (d.best) d.best = prefer_nested_simpler(round, trials, *d.best, per_candidate, d.before, d.runs);
  if (d.best) d.best = prefer_consistent_rival(round, trials, *d.best, per_candidate, d.before, d.runs, options.calibration);
  if (d.best) d.best = prefer_by_tails(round, trials, *d.best, per_candidate, d.before, d.runs, options.calibration);
  for (Trial& t : trials) d.candidates.push_back(std::move(t.c));
  for (Candidate& c : uncomputable) d.candidates.push_back(std::move(c));
  if (progress) progress->fits_done = progress->fits_total.load();
  explain_outcome(d, suite, model, cache, options.calibration);
  return d;
}

Diagnosis diagnose(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::string>& only, DiagnoseProgress* progress,
                   const EffectList& candidates, FitPath path, const CalibrationOptions& calibration) {
  DiagnoseOptions options;
  options.alpha = alpha;
  options.only = only;
  options.candidates = candidates;
  options.path = path;
  options.calibration = calibration;
  return diagnose(suite, model, options, progress);
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
  const std::string note = c.note + (c.note.empty() || c.tails_note.empty() ? "" : "; ") + c.tails_note;
  if (!note.empty()) text += " [" + note + "]";
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
