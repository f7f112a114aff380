#include "odomcov/measurement/calibrate.hpp"

#include <algorithm>
#include <Eigen/Cholesky>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <tuple>

#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/measurement/cross_validation.hpp"
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

/// The specs that one named entry of the loop put into the model (indices into `model.effects`),
/// empty when it cannot be taken out alone: a robot candidate (wheel_noise_level), an effect a
/// group_variation varies, or an effect of the starting model. A group candidate's entry holds its
/// group_variation and, unless another entry or the start has it, the effect it varies (which the
/// candidate added at its neutral value).
std::vector<std::size_t> specs_of_entry(const SuiteModel& model, const SuiteModel& start,
                                        const std::vector<std::string>& named, const std::string& entry) {
  const auto index = [&](const std::string& name, const std::string& target) -> std::optional<std::size_t> {
    for (std::size_t i = 0; i < model.effects.size(); ++i) {
      if (model.effects[i].name == name && model.effects[i].target == target) return i;
    }
    return std::nullopt;
  };
  const auto in_start = [&](const std::string& name) { return find_spec(start.effects, name) != nullptr; };
  const std::string group_prefix = std::string(kGroupVariation) + "(";
  if (entry.rfind(group_prefix, 0) == 0 && entry.back() == ')') {
    const std::string target = entry.substr(group_prefix.size(), entry.size() - group_prefix.size() - 1);
    const std::optional<std::size_t> group = index(kGroupVariation, target);
    if (!group || in_start(kGroupVariation)) return {};
    std::vector<std::size_t> out{*group};
    const std::string varied = target.substr(0, target.find('.'));
    const std::optional<std::size_t> v = index(varied, "");
    if (v && !in_start(varied) && std::find(named.begin(), named.end(), varied) == named.end()) out.push_back(*v);
    return out;
  }
  const std::optional<std::size_t> i = index(entry, "");
  if (!i || in_start(entry) || varied_by_group(model, entry)) return {};
  return {*i};
}

/// True when every one of `names` does nothing at the closed lower edge of its range: the
/// likelihood ratio for taking them out is then a 50:50 chi^2 mixture [Self87].
bool removal_on_boundary(const SuiteModel& model, const std::vector<std::string>& names) {
  return std::all_of(names.begin(), names.end(), [&](const std::string& n) {
    const EffectParameterInfo* p = effect_parameter_info(model, n);
    return p && p->neutral_at_edge();
  });
}

/// The Wald statistic of `names` in `fit` against their neutral values (from the fit's
/// covariance); NaN when the covariance does not give one (singular, not finite).
double wald_statistic(const FitResult& fit, const std::vector<std::string>& names) {
  constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  const auto n = static_cast<Eigen::Index>(names.size());
  if (fit.covariance.rows() != static_cast<Eigen::Index>(fit.names.size())) return kNone;
  Eigen::VectorXd delta(n);
  std::vector<Eigen::Index> at;
  for (const std::string& name : names) {
    const auto it = std::find(fit.names.begin(), fit.names.end(), name);
    const EffectParameterInfo* p = effect_parameter_info(fit.model, name);
    if (it == fit.names.end() || !p) return kNone;
    at.push_back(static_cast<Eigen::Index>(it - fit.names.begin()));
    delta(static_cast<Eigen::Index>(at.size() - 1)) = fit.values(at.back()) - p->neutral;
  }
  const Eigen::MatrixXd cov = fit.covariance(at, at);
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(cov);
  if (!cov.allFinite() || ldlt.info() != Eigen::Success || !(ldlt.vectorD().array() > 0).all()) return kNone;
  return delta.dot(ldlt.solve(delta));
}

/// The test of taking one named entry out of the loop's model (drop_unsupported).
struct Removal {
  double p = -1.0;      // the likelihood ratio's p-value; -1 when it stays without one
  double delta = 0.0;   // what it gains in log-likelihood, the rest refitted
  FitResult without;    // the model without it, refitted
};

/// The test of taking `entry` (of out.named) out of the loop's model, `with` that model fitted
/// jointly: p = -1 when it stays without a fit (the Wald test finds it, it cannot be taken out
/// alone, or the fit without it ends at a bound), else the likelihood ratio's p-value.
Removal test_removal(const Suite& suite, const SuiteModel& start, const CalibrateOptions& options,
                     DiagnoseProgress* progress, ResidualCache& cache, const CalibrateResult& out,
                     const FitResult& with, const std::string& entry, double level) {
  const bool noise = named_noise_level(out.named);
  std::vector<std::size_t> specs = specs_of_entry(out.loop_model, start, out.named, entry);
  std::sort(specs.rbegin(), specs.rend());  // erased from the back
  SuiteModel without = out.loop_model;
  for (std::size_t i : specs) without.effects.erase(without.effects.begin() + static_cast<std::ptrdiff_t>(i));
  const std::vector<std::string> kept = joint_parameters(without, noise);
  std::vector<std::string> removed;
  for (const std::string& n : with.names) {
    if (std::find(kept.begin(), kept.end(), n) == kept.end()) removed.push_back(n);
  }
  Removal r;
  if (specs.empty() || removed.empty()) return r;
  const bool on_boundary = removal_on_boundary(out.loop_model, removed);
  const int dof = static_cast<int>(removed.size());
  const double wald = wald_statistic(with, removed);
  if (std::isfinite(wald) && lrt_p_value(0.5 * wald, dof, on_boundary) < level) return r;
  if (kept.empty()) {  // nothing left to fit: the model without it as it is
    r.without.model = without;
    r.without.log_likelihood_after = log_likelihood(cache.at(without));
  } else {
    r.without = fit_all(suite, without, noise, options, progress, cache);
  }
  if (!r.without.at_bound.empty()) return r;
  r.delta = with.log_likelihood_after - r.without.log_likelihood_after;
  r.p = lrt_p_value(r.delta, dof, on_boundary);
  return r;
}

/// The backward step after the rounds: each round adopted its effect against the model of its
/// round, and an effect adopted later may explain what an earlier one took up (a per-run radius
/// adopted for the spread of bumps before the bumps were in). With every other effect refitted,
/// an adopted effect must still pass the test that admitted it: the likelihood ratio for it,
/// significant at the last round's per-candidate level (alpha over its candidates). The least
/// supported one that fails (largest p) is taken out, the rest refitted, and the check repeats.
/// The fits are screened by the Wald test of the joint fit: an effect whose parameters it finds
/// significant at the level stays without a fit of the model without it; one whose Wald test
/// does not (or that has no covariance) is fitted without it, and taken out only when the
/// likelihood ratio agrees and the fit without it ends at no bound. Both tests are on the full
/// likelihood, the joint fit's, on which a random effect's variance also takes up part of any
/// misfit of the means, and whose ratio for a variance is not scaled for heavy tails as diagnose's
/// is (tails_scale): both can keep a random effect in, never take a needed one out.
void drop_unsupported(const Suite& suite, const SuiteModel& start, const CalibrateOptions& options,
                      DiagnoseProgress* progress, ResidualCache& cache, CalibrateResult& out) {
  if (out.rounds.empty()) return;
  const double level = options.diagnose.alpha / static_cast<double>(std::max<std::size_t>(1, out.rounds.back().candidates.size()));
  while (!out.named.empty()) {
    const FitResult with = fit_all(suite, out.loop_model, named_noise_level(out.named), options, progress, cache);
    std::size_t worst = 0;
    Removal best;
    for (std::size_t k = 0; k < out.named.size(); ++k) {
      Removal r = test_removal(suite, start, options, progress, cache, out, with, out.named[k], level);
      if (r.p >= level && r.p > best.p) std::tie(worst, best) = std::forward_as_tuple(k, std::move(r));
    }
    if (best.p < 0.0) return;
    const std::string gain = best.delta > 0.0 ? "only " + format_number(best.delta, "%.3g") : std::string("nothing");
    out.simplified.push_back(out.named[worst] + " taken out: with every other effect refitted it gains " + gain +
                             " in log-likelihood (likelihood ratio p = " + format_number(best.p, "%.2g") +
                             ", not significant at " + format_number(level, "%.2g") + ")");
    out.named.erase(out.named.begin() + static_cast<std::ptrdiff_t>(worst));
    out.loop_model = best.without.model;
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

/// The stand-in check's fits of the final model on the halves of the training experiments.
class StabilityCheck {
 public:
  StabilityCheck(const CalibrateOptions& options, DiagnoseProgress* progress, ResidualCache& cache,
                 const CalibrateResult& out)
      : options_(options), progress_(progress), cache_(cache), model_(out.model),
        names_(joint_parameters(out.model, named_noise_level(out.named))) {
    for (const EffectSpec& e : model_.effects) {
      const EffectInfo* info = info_of(e);
      if (!info || !info->systematic || e.name == kGroupVariation || varied_by_group(model_, e.name)) continue;
      for (const std::string& p : effect_candidate(*info).fitted) {
        const auto at = std::find(names_.begin(), names_.end(), p);
        if (at != names_.end()) tested_.emplace_back(e.name, static_cast<std::size_t>(at - names_.begin()));
      }
    }
    for (const std::string& n : names_) systematic_ += n.rfind(std::string(kGroupVariation) + ".", 0) != 0;
  }

  bool empty() const { return tested_.empty(); }

  /// Each tested parameter fitted on each half along `feature` (nothing when a half cannot be
  /// fitted: too few runs for the model); `exact`: refitted exactly after the fast path.
  std::vector<StandIn> test(const std::string& feature, const Folds& halves, bool exact) {
    std::vector<StandIn> found;
    if (progress_) {
      if (progress_->cancel.load()) throw Cancelled();
      progress_->fits_total += 2;
    }
    std::atomic<std::int64_t>* counter = progress_ ? &progress_->evaluations : nullptr;
    FoldFits fits;
    try {
      fits = fit_folds(cache_, halves, model_, names_, {}, Likelihood::full, counter, options_.diagnose.path, exact);
    } catch (const Cancelled&) {
      throw;
    } catch (const std::exception&) {
      fits.models.clear();
    }
    if (progress_) progress_->fits_done += 2;
    if (fits.models.size() != 2) return found;
    // The dispersion of the means with each half under its own fit (the unrestricted model of
    // a Chow test: a drift of the parameter does not inflate it), over 3 m - 2 p.
    std::vector<std::vector<RunResidual>> own;
    for (std::size_t h = 0; h < 2; ++h) {  // fold 1 - h is fitted on half h
      ResidualCache half(cache_, halves.training(1 - h));
      const std::vector<std::vector<RunResidual>>& r = half.at(fits.models[1 - h], counter);
      own.insert(own.end(), r.begin(), r.end());
    }
    const double phi = mean_dispersion(own, 2 * systematic_).phi;
    for (const auto& [effect, k] : tested_) {
      StandIn s;
      s.effect = effect, s.parameter = names_[k], s.feature = feature, s.phi = phi;
      s.halves = {halves.names[0], halves.names[1]};
      for (std::size_t h = 0; h < 2; ++h) {
        SuiteModel m = fits.models[1 - h];
        s.value[h] = fitted_parameter(m, names_[k]);
        s.stderr_[h] = fits.stderrs[1 - h][k];
      }
      const double var = phi * (s.stderr_[0] * s.stderr_[0] + s.stderr_[1] * s.stderr_[1]);
      if (!(std::isfinite(var) && var > 0) || !std::isfinite(s.value[0]) || !std::isfinite(s.value[1])) continue;
      s.z = (s.value[0] - s.value[1]) / std::sqrt(var);
      s.p_value = std::erfc(std::abs(s.z) / std::sqrt(2.0));
      found.push_back(std::move(s));
    }
    return found;
  }

 private:
  const CalibrateOptions& options_;
  DiagnoseProgress* progress_;
  ResidualCache& cache_;
  const SuiteModel& model_;
  std::vector<std::string> names_;
  std::vector<std::pair<std::string, std::size_t>> tested_;  // (effect, index in names_)
  std::size_t systematic_ = 0;
};

/// The finding in words.
std::string stand_in_text(const StandIn& s, std::size_t tests) {
  const auto number = [](double v, double se) { return format_number(v, "%.6g") + " +/- " + format_number(se, "%.2g"); };
  return s.effect + " stands in for something that changes with " + s.feature + ": fitted on the experiments with " +
         s.halves[0] + ", " + s.parameter + " = " + number(s.value[0], s.stderr_[0]) + "; on those with " + s.halves[1] +
         ", " + number(s.value[1], s.stderr_[1]) + " (z = " + format_number(s.z, "%.3g") +
         (s.phi > 1 ? ", the variances scaled by the halves' mean dispersion " + format_number(s.phi, "%.3g") : std::string()) +
         ", p = " + format_number(s.p_value, "%.2g") + " against " + format_number(s.level, "%.2g") + " over the " +
         std::to_string(tests) +
         " pairs of a feature and a parameter tested). A cause would have one size on both sides: it is in the model "
         "because it predicts the runs better, not as their cause; the physics that changes with " + s.feature +
         " is not in the model";
}

/// The parameter stability check: a cause has one size wherever it acts. For each feature of
/// the path (residual_feature_names; a feature that splits the experiments as an earlier one
/// does is skipped) the training experiments are split at its median (feature_folds), and the
/// final model is fitted on each half, every parameter refitted. The two halves' runs are
/// independent, so under the model the difference of a parameter's two estimates is normal with
/// the sum of their variances, each scaled by the mean dispersion phi of the two halves under
/// their own fits when their means scatter more than predicted (the quasi-likelihood's
/// [McCullagh89, §9.2], estimated under the alternative as a Chow test's variance is, so that
/// the drift tested does not inflate it). A systematic effect whose parameter differs at the
/// family-wise alpha (Bonferroni over every feature and parameter tested) stands in for
/// something that changes with that feature [Chow60]. The fast path screens; a feature where
/// it finds a difference is fitted again exactly (refit_exactly) before the decision. A half
/// that leaves a parameter undetermined gives it no standard error and tests nothing.
void find_stand_ins(const Suite& suite, const CalibrateOptions& options, DiagnoseProgress* progress,
                    ResidualCache& cache, CalibrateResult& out) {
  StabilityCheck check(options, progress, cache, out);
  if (check.empty()) return;
  const bool screened = options.diagnose.path == FitPath::fast;
  std::vector<std::pair<std::string, Folds>> features;
  std::vector<std::vector<StandIn>> results;
  std::size_t tests = 0;
  for (const std::string& feature : residual_feature_names()) {
    Folds halves = feature_folds(experiment_feature_values(suite, out.model.robot.wheelbase_m, feature), feature);
    const auto same_halves = [&](const auto& f) { return f.second.of_experiment == halves.of_experiment; };
    if (halves.size() < 2 || std::any_of(features.begin(), features.end(), same_halves)) continue;
    results.push_back(check.test(feature, halves, !screened));
    features.emplace_back(feature, std::move(halves));
    tests += results.back().size();
  }
  if (tests == 0) return;
  const double level = options.diagnose.alpha / static_cast<double>(tests);
  const auto significant = [&](const StandIn& s) { return s.p_value < level; };
  for (std::size_t f = 0; f < features.size(); ++f) {
    if (screened && std::any_of(results[f].begin(), results[f].end(), significant)) {
      results[f] = check.test(features[f].first, features[f].second, true);  // nothing when the exact fit fails
    }
  }
  for (std::vector<StandIn>& feature : results) {
    for (StandIn& s : feature) {
      if (!significant(s)) continue;
      s.level = level;
      s.text = stand_in_text(s, tests);
      const auto same = std::find_if(out.stand_ins.begin(), out.stand_ins.end(),
                                     [&](const StandIn& x) { return x.effect == s.effect; });
      if (same == out.stand_ins.end()) {
        out.stand_ins.push_back(std::move(s));
      } else if (s.p_value < same->p_value) {
        *same = std::move(s);
      }
    }
  }
}

/// The final model's account: compare, the stand-in check when compare rejects it, residuals, corrected odometry, what
/// the runs cannot separate and what to record next.
void account(const Suite& suite, const CalibrateOptions& options, DiagnoseProgress* progress, ResidualCache& cache,
             CalibrateResult& out) {
  const Comparison& c = cache.comparison(out.model, options.diagnose.alpha, options.diagnose.calibration);
  out.after = summarise(c);
  out.nees_by_kind = nees_by_kind(suite, c);
  out.explained = c.verdict.consistent();
  // Gatekeeping: a model that compare finds consistent is not searched for stand-ins, so the
  // claims that the runs are not explained (compare's, then the stand-ins') are made at alpha
  // together when the model is right.
  if (!out.explained) find_stand_ins(suite, options, progress, cache, out);
  if (!out.explained) out.residuals = residual_alignment(cache, out.model);
  out.odometry_correction = odometry_correction(suite, out.model);
  FitResult at = design_point(out);
  if (at.names.empty()) return;
  out.confounded = confounded_pairs(at.names, estimate_covariance(suite, at));
  out.next_experiments = next_experiments(suite, at, &out.unpredictable_experiments);
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

NeesByKind nees_by_kind(const Suite& suite, const std::vector<double>& nees_mean) {
  std::vector<std::string> kinds;
  std::map<std::string, std::pair<double, double>> nees;  // kind -> (sum of NEES, runs)
  for (std::size_t e = 0; e < suite.experiments.size() && e < nees_mean.size(); ++e) {
    const auto n = static_cast<double>(suite.experiments[e].runs.size());
    if (n == 0) continue;
    const std::string kind = experiment_kind(suite.experiments[e]);
    if (!nees.count(kind)) kinds.push_back(kind);
    nees[kind].first += nees_mean[e] * n;
    nees[kind].second += n;
  }
  NeesByKind out;
  for (const std::string& k : kinds) out.push_back({k, nees[k].first / nees[k].second});
  return out;
}

NeesByKind nees_by_kind(const Suite& suite, const Comparison& comparison) {
  std::vector<double> nees_mean;
  for (const ExperimentComparison& c : comparison.experiments) nees_mean.push_back(c.nees_mean);
  return nees_by_kind(suite, nees_mean);
}

namespace {

/// HoldoutSummary::refitted: the model's effects fitted on the held-out runs as joint_fit fits
/// them on the training runs.
std::optional<HoldoutSummary::Refitted> refit_on_holdout(const Suite& holdout, const SuiteModel& model,
                                                         bool noise_level, const CalibrateOptions& options,
                                                         DiagnoseProgress* progress) {
  if (joint_parameters(model, noise_level).empty()) return std::nullopt;
  ResidualCache cache(holdout);
  HoldoutSummary::Refitted out;
  out.fit = fit_all(holdout, model, noise_level, options, progress, cache);
  CalibrationOptions gaussian;
  gaussian.method = CalibrationMethod::gaussian;
  const Comparison c = compare(holdout, out.fit.model, options.diagnose.alpha, cache.at(out.fit.model), gaussian);
  out.nees_mean = summarise(c).nees_mean;
  out.nees_by_kind = nees_by_kind(holdout, c);
  return out;
}

/// HoldoutSummary::predictive: the held-out runs predicted from the training runs' posterior of
/// the joint fit's parameters and of every absent systematic catalogue effect's.
HoldoutSummary::Predictive predict_holdout(const Suite& training, const Suite& holdout, const SuiteModel& model,
                                           bool noise_level) {
  const TrainingUncertainty u = training_uncertainty(training, model, joint_parameters(model, noise_level));
  const PredictiveCheck check = predictive_check(holdout, u);
  HoldoutSummary::Predictive out;
  out.plugin_nees_mean = check.plugin_mean;
  out.sized_nees_mean = check.sized_mean;
  out.nees_mean = check.predictive_mean;
  out.plugin_by_kind = nees_by_kind(holdout, check.plugin);
  out.sized_by_kind = nees_by_kind(holdout, check.sized);
  out.nees_by_kind = nees_by_kind(holdout, check.predictive);
  for (std::size_t k = 0; k < u.names.size(); ++k) {
    if (check.spread[k] < kPredictiveSpreadShown) continue;
    out.parameters.push_back({u.names[k], u.prior_sd[k], check.posterior_sd[k], u.shift(static_cast<Eigen::Index>(k)),
                              u.sized[k], check.spread[k]});
  }
  std::stable_sort(out.parameters.begin(), out.parameters.end(),
                   [](const auto& a, const auto& b) { return a.spread > b.spread; });
  return out;
}

/// The hold-out of a model that cannot predict the held-out runs, and why (`why`): their
/// experiments and where they lie outside the training domain, nothing judged.
HoldoutSummary unpredictable_holdout(const Suite& holdout, const SuiteModel& model, const std::string& why) {
  HoldoutSummary out;
  out.cannot_predict = why;
  out.summary.verdict = "inconsistent";
  out.summary.nees_mean = std::numeric_limits<double>::quiet_NaN();
  out.summary.log_likelihood = -std::numeric_limits<double>::infinity();
  for (const SuiteExperiment& ex : holdout.experiments) {
    ++out.experiments;
    if (!model.domain) continue;
    for (const std::string& x : extrapolation(*model.domain, ex, model.robot.wheelbase_m)) {
      out.extrapolation.push_back(ex.name + ": " + x);
    }
  }
  return out;
}

}  // namespace

HoldoutSummary judge_holdout(const Suite& holdout, const SuiteModel& model, double alpha,
                             const CalibrationOptions& calibration) {
  HoldoutSummary out;
  out.comparison = compare(holdout, model, alpha, calibration);
  out.summary = summarise(out.comparison);
  out.nees_by_kind = nees_by_kind(holdout, out.comparison);
  for (const ExperimentComparison& c : out.comparison.experiments) {
    ++out.experiments;
    out.consistent += c.verdict.consistent();
    for (const std::string& x : c.extrapolation) out.extrapolation.push_back(c.name + ": " + x);
  }
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
  drop_unsupported(suite, start, options, progress, cache, out);
  joint_fit(suite, options, progress, cache, out);
  account(suite, options, progress, cache, out);
  out.model.domain = training_domain(suite, out.model.robot.wheelbase_m);
  out.diff_drive = diff_drive_parameters(suite, out.model);
  if (holdout) {
    SuiteModel judged = out.model;
    judged.measurement_noise = holdout->measurement_noise;
    try {
      out.holdout = judge_holdout(*holdout, judged, options.diagnose.alpha, options.diagnose.calibration);
      out.holdout->refitted = refit_on_holdout(*holdout, judged, named_noise_level(out.named), options, progress);
      out.holdout->predictive = predict_holdout(suite, *holdout, out.model, named_noise_level(out.named));
    } catch (const InputError& e) {
      // The held-out runs were read and checked when loaded (their size for the order too):
      // what fails now is the calibrated model on them, in practice a custom expression of it
      // out of its range there. The calibration stands and is written; the hold-out says why it
      // cannot be judged.
      out.holdout = unpredictable_holdout(*holdout, judged, e.what());
    }
  }
  // An interrupt during the steps after the rounds: nothing is returned, so nothing is written.
  if (progress && progress->cancel.load()) throw Cancelled();
  return out;
}

}  // namespace odomcov
