#include "odomcov/diagnosis.hpp"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <limits>

#include "odomcov/format.hpp"

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

/// Systematic candidates move the mean and are judged on the full likelihood; the others only
/// add randomness and are judged on the scatter part, which a mean misfit cannot inflate.
bool systematic(const std::string& effect) { return find_candidate(effect)->systematic; }

/// The parameters a candidate fits (CandidateType::fitted, from the effect's own metadata).
const std::vector<std::string>& fitted_names(const std::string& effect) {
  return find_candidate(effect)->fitted;
}

/// The fitted parameters of a model's effects, split into systematic and random ones.
struct FittedNames {
  std::vector<std::string> systematic, random;
};
FittedNames split_fitted_names(const EffectList& effects) {
  FittedNames out;
  for (const EffectSpec& e : effects) {
    for (const std::string& n : fitted_names(e.name)) {
      (systematic(e.name) ? out.systematic : out.random).push_back(n);
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

/// True when every fitted parameter's "no effect" value is the edge of its range (a size that
/// cannot be negative): the likelihood-ratio statistic is then a 50:50 mixture of chi^2_0 and
/// chi^2_dof [Self87], so the p-value is half the chi^2 one.
bool on_boundary(const std::string& effect) { return find_candidate(effect)->on_boundary; }

/// The candidate's reported parameters, values and standard errors from its fit: a robot
/// candidate's fitted parameters; an effect's every parameter (NaN standard error where not
/// fitted), completed by the effect's own hook (EffectInfo::complete).
void describe_fit(const Suite& suite, const FitResult& f, Eigen::Index offset, const Eigen::VectorXd& se,
                  Candidate& c) {
  const CandidateType& type = *find_candidate(c.effect);
  if (type.robot) {
    for (std::size_t i = 0; i < type.fitted.size(); ++i) {
      const auto k = offset + static_cast<Eigen::Index>(i);
      c.parameters.push_back(type.fitted[i]);
      c.values.push_back(f.values(k));
      c.stderrs.push_back(se(k));
    }
    return;
  }
  EffectSpec* spec = nullptr;
  for (EffectSpec& e : c.model.effects) spec = e.name == c.effect ? &e : spec;
  const EffectInfo& info = *find_effect(c.effect);
  std::vector<double> stderrs(info.parameters.size(), kNaN);
  for (std::size_t p = 0; p < info.parameters.size(); ++p) {
    c.parameters.push_back(info.parameters[p].name);
    for (std::size_t i = 0; i < type.fitted.size(); ++i) {
      if (type.fitted[i] == c.effect + "." + info.parameters[p].name) {
        stderrs[p] = se(offset + static_cast<Eigen::Index>(i));
      }
    }
  }
  if (type.complete) c.note = type.complete(suite, c.model.robot.wheelbase_m, *spec, stderrs);
  c.values = spec->values;
  c.stderrs = stderrs;
}

/// The signature rule for the pairs a Gaussian likelihood cannot separate
/// (EffectInfo::confused_with): when both are significant, the one the tails speak against
/// moves to just below the other (the rest of the order stands).
void apply_tail_rule(std::vector<Candidate>& candidates, bool heavy_tails) {
  auto at = [&](const std::string& n) {
    return std::find_if(candidates.begin(), candidates.end(), [&](const Candidate& c) { return c.effect == n; });
  };
  for (const CandidateType& type : candidate_types()) {
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

}  // namespace

Diagnosis diagnose(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::string>& only, DiagnoseProgress* progress, FitPath path) {
  // Every exact propagation of the round, kept: the fast path's anchors and difference points
  // around the base model are shared by all candidates.
  ResidualCache cache(suite);
  Diagnosis d;
  d.alpha = alpha;
  d.runs = run_count(suite);
  const Comparison before = compare(suite, model, alpha);
  d.before = summarise(before);
  d.kurtosis = before.kurtosis;
  d.heavy_tails = d.kurtosis.valid && d.kurtosis.statistic > 0 && d.kurtosis.p_value < alpha;

  // The model's own effects, refitted: the reference every candidate must improve on. Each
  // candidate refits the model's effects of its own kind with it (systematic ones on the full
  // likelihood, random ones on the scatter part); the others stay at their refitted values.
  const FittedNames nuisance = split_fitted_names(model.effects);
  const SuiteModel base = refit(suite, model, progress, path, cache);
  const auto& base_residuals = cache.at(base);
  const double base_full = log_likelihood(base_residuals);
  const double base_scatter = scatter_log_likelihood(base_residuals);
  const std::vector<double> base_by_experiment = experiment_log_likelihoods(base_residuals);

  std::vector<std::string> names;
  for (const CandidateType& type : candidate_types()) {
    bool in_model = false;
    for (const EffectSpec& e : model.effects) in_model = in_model || e.name == type.name;
    if (!in_model) names.push_back(type.name);
  }
  if (!only.empty()) {
    std::vector<std::string> kept;
    for (const std::string& n : names) {
      if (std::find(only.begin(), only.end(), n) != only.end()) kept.push_back(n);
    }
    names = kept;
  }

  // The fits: the base refit, one per candidate and the winner's refit.
  if (progress) progress->fits_total = static_cast<std::int64_t>(names.size()) + 2;
  const double log_runs = std::log(static_cast<double>(d.runs));
  for (const std::string& name : names) {
    Candidate c;
    c.effect = name;
    c.systematic = systematic(name);
    std::vector<std::string> fitted = c.systematic ? nuisance.systematic : nuisance.random;
    const std::vector<std::string> own = fitted_names(name);
    fitted.insert(fitted.end(), own.begin(), own.end());
    const Likelihood kind = c.systematic ? Likelihood::full : Likelihood::scatter;
    const FitResult f =
        fit(suite, base, fitted, kind, progress ? &progress->evaluations : nullptr, path, &cache);
    // With heavy tails the observed information understates the uncertainty: sandwich SEs.
    const Eigen::VectorXd& se = d.heavy_tails ? f.robust_stderrs : f.stderrs;
    c.model = f.model;
    c.dof = static_cast<int>(own.size());
    // Each candidate is judged on the part of the likelihood it explains: the full one for a
    // systematic effect, the scatter part for a random one (whose extra variance would
    // otherwise also "explain" any mean misfit). The gains are on one scale; delta BIC ranks.
    c.delta_log_likelihood = f.log_likelihood_after - (c.systematic ? base_full : base_scatter);
    c.delta_bic = -2.0 * c.delta_log_likelihood + c.dof * log_runs;
    double lr = 2.0 * c.delta_log_likelihood;
    // Heavy tails widen the null distribution of a Gaussian variance LRT by the kurtosis factor
    // (the scaled test of [Browne84]); the same factor compare uses.
    if (!c.systematic && d.heavy_tails && before.mardia_b2 > before.mardia_expected) {
      lr /= before.mardia_b2 / before.mardia_expected;
    }
    lr = std::max(0.0, lr);
    c.p_value = lr == 0.0 ? 1.0 : (on_boundary(name) ? 0.5 : 1.0) * chi2_sf(lr, c.dof);
    describe_fit(suite, f, static_cast<Eigen::Index>(fitted.size() - own.size()), se, c);
    const auto& candidate_residuals = cache.at(c.model);
    c.delta_full_log_likelihood = log_likelihood(candidate_residuals) - base_full;
    const std::vector<double> by_experiment = experiment_log_likelihoods(candidate_residuals);
    std::vector<std::pair<std::string, double>> gains;
    for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
      gains.push_back({suite.experiments[e].name, by_experiment[e] - base_by_experiment[e]});
    }
    std::sort(gains.begin(), gains.end(), [](const auto& a, const auto& b) { return a.second > b.second; });
    for (std::size_t i = 0; i < gains.size() && i < 2; ++i) {
      if (gains[i].second > 0) c.evidence.push_back(gains[i]);
    }
    d.candidates.push_back(std::move(c));
    if (progress) ++progress->fits_done;
  }

  const double per_candidate = alpha / static_cast<double>(std::max<std::size_t>(1, d.candidates.size()));
  for (Candidate& c : d.candidates) c.significant = c.p_value < per_candidate;
  // Ranking: significant candidates first, each group by delta BIC.
  std::stable_sort(d.candidates.begin(), d.candidates.end(), [&](const Candidate& a, const Candidate& b) {
    return a.significant != b.significant ? a.significant : a.delta_bic < b.delta_bic;
  });
  apply_tail_rule(d.candidates, d.heavy_tails);
  if (!d.candidates.empty() && d.candidates.front().significant) {
    d.best = 0;
    // The model to adopt: everything refitted by its part of the likelihood, now that the new
    // effect is in (the earlier effects were sized without it).
    Candidate& best = d.candidates.front();
    // (When every effect is of the candidate's kind and nothing was completed after its fit,
    // the candidate's own fit was already that refit: all of them jointly on its likelihood.)
    bool other_kind = find_candidate(best.effect)->complete != nullptr;
    for (const EffectSpec& e : best.model.effects) other_kind = other_kind || systematic(e.name) != best.systematic;
    if (other_kind) best.model = refit(suite, best.model, progress, path, cache);
    if (find_candidate(best.effect)->robot) {
      for (std::size_t i = 0; i < best.parameters.size(); ++i) {
        for (const RobotParameter& p : robot_parameters()) {
          if (p.name == best.parameters[i]) best.values[i] = p.ref(best.model.robot);
        }
      }
    } else {
      for (const EffectSpec& e : best.model.effects) {
        if (e.name == best.effect) best.values = e.values;  // completed ones stay, fitted ones refitted
      }
    }
  }
  if (progress) progress->fits_done = progress->fits_total.load();
  d.after = d.best ? summarise(compare(suite, d.candidates[*d.best].model, alpha)) : d.before;
  d.explained = d.after.verdict == "consistent";
  d.odometry_correction = odometry_correction(suite, d.best ? d.candidates[*d.best].model : model);
  if (!d.explained) {
    const SuiteModel& final_model = d.best ? d.candidates[*d.best].model : model;
    d.residuals = residual_alignment(suite, final_model, cache.at(final_model));
  }
  return d;
}

std::string explain(const Candidate& c) {
  const CandidateType& type = *find_candidate(c.effect);
  std::string text = type.physics + ": ";
  const std::string& signature = type.signature;
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
                  ? "The remaining misfit lines up with (p family-wise over the features):\n"
                  : "The remaining misfit lines up with no path feature at alpha; the closest "
                    "(p family-wise over the features):\n";
    }
    if (shown > 0 && !(a.p_value < d.alpha)) break;
    text += "  " + a.feature + " (p = " + format_number(a.p_value, "%.2g") + "): " + a.description + "\n";
    ++shown;
  }
  if (shown == 0) text += "No path feature varies across the experiments enough to test.\n";
  return text;
}

std::string candidate_yaml(const Candidate& c, const SuiteModel& model) {
  if (find_candidate(c.effect)->robot) {
    Robot robot = model.robot;
    for (std::size_t i = 0; i < c.parameters.size(); ++i) {
      for (const RobotParameter& p : robot_parameters()) {
        if (p.name == c.parameters[i]) p.ref(robot) = c.values[i];
      }
    }
    return robot_yaml(robot);
  }
  for (const EffectSpec& e : c.model.effects) {
    if (e.name == c.effect) return effect_yaml(e);
  }
  return "";
}

}  // namespace odomcov
