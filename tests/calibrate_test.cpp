// calibrate and diagnose's decisions: the folds of cross-validation, held-out likelihoods, exact
// decisions on a nonlinear candidate, mimics, the guards on every adoption, the training domain
// and the loop end to end, on simulated labs whose truth is known.
#include "odomcov/measurement/calibrate.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <map>
#include <utility>

#include "odomcov/base/format.hpp"
#include "odomcov/measurement/domain.hpp"
#include "synth_util.hpp"

namespace odomcov {
namespace {

const std::string kStandard = ODOMCOV_SOURCE_DIR "/configs/worlds/standard.yaml";

/// The standard experiment set (lines, forward-back, spins, arcs, UMBmark squares) in a world
/// with these hidden effects instead of standard.yaml's.
WorldFile standard_world(EffectList effects, std::uint64_t seed) {
  WorldFile w = load_world(kStandard);
  w.world.effects = std::move(effects);
  w.seed = seed;
  return w;
}

const Candidate& candidate(const Diagnosis& d, const std::string& effect) {
  const auto it = std::find_if(d.candidates.begin(), d.candidates.end(),
                               [&](const Candidate& c) { return c.effect == effect; });
  if (it == d.candidates.end()) throw std::runtime_error("no candidate " + effect);
  return *it;
}

SuiteExperiment experiment(const std::string& name, const std::string& kind, const std::string& group) {
  SuiteExperiment ex;
  ex.name = name;
  ex.kind = kind;
  ex.group = group;
  return ex;
}

/// The standard lab recorded on two days (alternate experiments), and a model whose scale error
/// varies between them.
std::pair<Suite, SuiteModel> two_day_scale_lab(const std::string& tag) {
  Suite lab = test::synth_suite(load_world(kStandard), tag);
  for (std::size_t i = 0; i < lab.experiments.size(); ++i) lab.experiments[i].group = i % 2 == 0 ? "day-1" : "day-2";
  SuiteModel model = suite_model(lab);
  model.effects.push_back({"scale_error", {1.002}});
  model.effects.push_back({kGroupVariation, {0.002}, "scale_error.Es"});
  return {std::move(lab), std::move(model)};
}

TEST(Folds, KindsThenGroupsThenExperiments) {
  Suite s;
  for (const char* name : {"line-a", "line-b", "spin-a", "arc-a"}) s.experiments.push_back(experiment(name, default_kind(name), ""));
  Folds f = make_folds(s);
  EXPECT_EQ(f.by, "kind");
  EXPECT_EQ(f.names, (std::vector<std::string>{"line", "spin", "arc"}));
  EXPECT_EQ(f.of_experiment, (std::vector<int>{0, 0, 1, 2}));
  EXPECT_EQ(f.training(0), (std::vector<bool>{false, false, true, true}));
  // Two kinds: each fit would see one kind only; K folds over the experiments instead, or the
  // groups when every experiment has one.
  s.experiments.pop_back();
  EXPECT_EQ(make_folds(s).by, "experiments");
  EXPECT_EQ(make_folds(s).size(), 3u);
  for (std::size_t i = 0; i < s.experiments.size(); ++i) s.experiments[i].group = i < 2 ? "day-1" : "day-2";
  EXPECT_EQ(make_folds(s).by, "group");
  EXPECT_EQ(make_folds(s).names, (std::vector<std::string>{"day-1", "day-2"}));
  // More kinds than kMaxFolds share folds round robin; one experiment has none.
  Suite many;
  for (int k = 0; k < 7; ++k) many.experiments.push_back(experiment("e" + std::to_string(k), "k" + std::to_string(k), ""));
  f = make_folds(many);
  ASSERT_EQ(f.size(), kMaxFolds);
  EXPECT_EQ(f.names[0], "k0+k5");
  EXPECT_EQ(f.of_experiment[6], 1);
  many.experiments.resize(1);
  EXPECT_EQ(make_folds(many).size(), 0u);
}

TEST(Folds, FeatureHalvesSplitAtTheMedian) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // Speeds: below the median (0.5) against at or above it; a runless experiment joins fold 0.
  Folds f = feature_folds({0.2, 0.8, 0.5, 0.2, nan, 0.8}, "speed");
  EXPECT_EQ(f.by, "feature");
  EXPECT_EQ(f.names, (std::vector<std::string>{"speed below 0.5", "speed from 0.5"}));
  EXPECT_EQ(f.of_experiment, (std::vector<int>{0, 1, 1, 0, 0, 1}));
  // Ties at the bottom: the median is the smallest value, so the split is above it.
  f = feature_folds({1, 1, 1, -1, 1}, "travel_direction");
  EXPECT_EQ(f.names, (std::vector<std::string>{"travel_direction below 1", "travel_direction from 1"}));
  f = feature_folds({0, 0, 0, 1}, "reversals");
  EXPECT_EQ(f.names, (std::vector<std::string>{"reversals up to 0", "reversals above 0"}));
  EXPECT_EQ(f.of_experiment, (std::vector<int>{0, 0, 0, 1}));
  // Nothing varies, or a single value: no folds.
  EXPECT_EQ(feature_folds({0.3, 0.3, 0.3}, "speed").size(), 0u);
  EXPECT_EQ(feature_folds({0.3, nan}, "speed").size(), 0u);
}

TEST(CrossValidation, HeldOutLikelihoodOfIndependentRunsIsTheirOwnDensity) {
  const Suite lab = test::synth_suite(load_world(kStandard), "cv_density");
  const SuiteModel model = suite_model(lab);
  ResidualCache cache(lab);
  const auto& all = cache.at(model);
  const Folds folds = make_folds(lab);
  ASSERT_EQ(folds.by, "kind");
  for (std::size_t f = 0; f < folds.size(); ++f) {
    const std::vector<bool> training = folds.training(f);
    // A view holds the parent's residuals of its experiments, and propagates nothing new.
    ResidualCache view(cache, training);
    const std::int64_t before = cache.computed();
    const auto& mine = view.at(model);
    EXPECT_EQ(cache.computed(), before);
    ASSERT_EQ(mine.size(), static_cast<std::size_t>(std::count(training.begin(), training.end(), true)));
    double held = 0.0;
    const std::vector<double> terms = run_log_likelihoods(all, false);
    std::size_t i = 0;
    for (std::size_t e = 0; e < all.size(); ++e) {
      for (std::size_t r = 0; r < all[e].size(); ++r, ++i) held += training[e] ? 0.0 : terms[i];
    }
    EXPECT_NEAR(held_out_log_likelihood(all, training, Likelihood::full), held, 1e-9 * std::abs(held)) << folds.names[f];
  }
}

TEST(CrossValidation, HeldOutPartsSumToTheHeldOutLikelihoodWithinGroups) {
  // With a spread between groups the held-out runs are not independent of the training runs of
  // their group: each part is a run's density given the runs before it (the chain rule), and the
  // parts of every fold sum to log L(all) - log L(training), for both parts of the likelihood.
  const auto [lab, model] = two_day_scale_lab("cv_parts");
  const std::vector<std::vector<RunResidual>> all = residuals(lab, model);
  const Folds folds = make_folds(lab);
  ASSERT_GE(folds.size(), 2u);
  for (const Likelihood kind : {Likelihood::full, Likelihood::scatter}) {
    for (std::size_t f = 0; f < folds.size(); ++f) {
      const std::vector<bool> training = folds.training(f);
      const std::vector<double> parts = held_out_parts(all, training, kind);
      std::size_t held_runs = 0;
      for (std::size_t e = 0; e < all.size(); ++e) held_runs += training[e] ? 0 : all[e].size();
      EXPECT_EQ(parts.size(), held_runs) << folds.names[f];
      const double held = held_out_log_likelihood(all, training, kind);
      EXPECT_NEAR(std::accumulate(parts.begin(), parts.end(), 0.0), held, 1e-9 * std::abs(held)) << folds.names[f];
    }
  }
  // The spread of a sum of parts: sqrt(n) times their sample standard deviation.
  EXPECT_DOUBLE_EQ(spread_of_sum({1.0, 2.0, 3.0, 4.0}), std::sqrt(4.0 * 5.0 / 3.0));
  EXPECT_TRUE(std::isnan(spread_of_sum({1.0})));
}

TEST(CrossValidation, AViewAndTheWholeSuiteShareOnePropagation) {
  // A fold's fit asks its training view for residuals at points no one else asks for; its
  // held-out score then asks for the whole suite at the fitted point. The store propagates
  // only what is missing each time, and every experiment's residuals are residuals()'s, bit for
  // bit, with the group indices of the whole suite.
  const auto [lab, model] = two_day_scale_lab("cv_partial");
  const std::vector<std::vector<RunResidual>> direct = residuals(lab, model);
  const Folds folds = make_folds(lab);
  ASSERT_GE(folds.size(), 2u);
  ResidualCache cache(lab);
  const std::vector<bool> training = folds.training(0);
  ResidualCache view(cache, training);
  view.at(model);
  EXPECT_EQ(cache.computed(), 1);
  const auto& all = cache.full(model);
  EXPECT_EQ(cache.computed(), 2);  // the held-out experiments only
  cache.full(model);
  ResidualCache(cache, folds.training(1)).at(model);
  EXPECT_EQ(cache.computed(), 2);  // nothing is missing any more
  ASSERT_EQ(all.size(), direct.size());
  for (std::size_t e = 0; e < all.size(); ++e) {
    ASSERT_EQ(all[e].size(), direct[e].size()) << e;
    for (std::size_t r = 0; r < all[e].size(); ++r) {
      EXPECT_EQ(all[e][r].error, direct[e][r].error) << e;
      EXPECT_EQ(all[e][r].mean, direct[e][r].mean) << e;
      EXPECT_EQ(all[e][r].cov, direct[e][r].cov) << e;
      EXPECT_EQ(all[e][r].group, direct[e][r].group) << e;
      EXPECT_EQ(all[e][r].group_column, direct[e][r].group_column) << e;
    }
  }
  // Two groups, so the indices carry something to check.
  EXPECT_TRUE(std::any_of(direct.begin(), direct.end(), [&](const auto& ex) {
    return !ex.empty() && ex.front().group != direct.front().front().group;
  }));
}

TEST(CrossValidation, TheCacheKeepsVerdictsAndForgetsWhatARoundDidNotRead) {
  // calibrate shares one cache over its rounds: a verdict read twice is the referee's once, and
  // is the verdict a new compare gives (the referee is seeded); what a round did not read is
  // forgotten at the next round's start.
  const Suite lab = test::synth_suite(load_world(kStandard), "cache_age");
  const SuiteModel model = suite_model(lab);
  SuiteModel other = model;
  other.effects.push_back({"scale_error", {1.001}});
  CalibrationOptions referee;
  referee.method = CalibrationMethod::simulation;
  referee.max_replicates = 99;
  ResidualCache cache(lab);
  const Comparison& kept = cache.comparison(model, 0.01, referee);
  EXPECT_EQ(&cache.comparison(model, 0.01, referee), &kept);
  const Comparison fresh = compare(lab, model, 0.01, referee);
  EXPECT_EQ(kept.calibration.replicates, fresh.calibration.replicates);
  EXPECT_EQ(kept.calibration.p_value, fresh.calibration.p_value);
  EXPECT_EQ(kept.log_likelihood, fresh.log_likelihood);
  // Other options are another verdict, and so is a training domain (the verdict names what
  // lies outside it).
  EXPECT_NE(&cache.comparison(model, 0.05, referee), &kept);
  SuiteModel bounded = model;
  bounded.domain = Domain{{0.0, 0.1}, {0.0, 0.1}, {0.0, 1.0}, {0.0, 1.0}};
  const Comparison& flagged = cache.comparison(bounded, 0.01, referee);
  EXPECT_NE(&flagged, &kept);
  EXPECT_TRUE(std::any_of(flagged.experiments.begin(), flagged.experiments.end(),
                          [](const ExperimentComparison& e) { return !e.extrapolation.empty(); }));
  cache.at(other);
  const std::int64_t computed = cache.computed();
  cache.age();  // a round starts: everything above was read in the last one, and is kept
  cache.at(model);
  EXPECT_EQ(cache.computed(), computed);
  cache.age();  // `other` was not read since: it goes, `model` stays
  cache.at(model);
  EXPECT_EQ(cache.computed(), computed);
  cache.at(other);
  EXPECT_EQ(cache.computed(), computed + 1);
}

/// A scale that fades with time, 1 + a exp(-t/tau): strongly nonlinear in tau.
EffectSpec warmup(double a, double tau) {
  CustomEffect def;
  def.name = "warmup";
  def.parameters = {"a", "tau"};
  def.scale.text = "1 + a*exp(-t/tau)";
  return define_custom_effect(def, {a, tau});
}

TEST(Diagnose, FastAndExactAgreeOnTheWinnerWithANonlinearCandidate) {
  // The world's scale fades from 1.03 with a time constant of 8 s. The user's hypothesis starts
  // from a = 0.05, tau = 0.5 s, far from it in a strongly nonlinear parameter: the fast path's
  // quadratic surrogates mispredict on the way and its fit is not verified: it stops in another
  // basin (tau near 0.4 s), from whose optimum no local exact step escapes. diagnose refits such
  // a finalist exactly from there and from its given values, keeps the better optimum, and names
  // warmup with the exact path's gain, as the exact path does on its own.
  const Suite lab = test::synth_suite(standard_world({warmup(0.03, 8.0)}, 2026), "warmup");
  const SuiteModel model = suite_model(lab);
  const EffectList given = {warmup(0.05, 0.5)};
  const std::vector<std::string> only = {"scale_error", "wheelbase_error"};
  ResidualCache cache(lab);
  SuiteModel start = model;
  start.effects = given;
  const FitResult fast = fit(lab, start, {"warmup.a", "warmup.tau"}, Likelihood::full, nullptr, FitPath::fast, &cache);
  EXPECT_FALSE(fast.verified);
  const FitResult refitted =
      refit_exactly_from_both(fast, start, {"warmup.a", "warmup.tau"}, Likelihood::full, nullptr, cache);
  EXPECT_GT(refitted.log_likelihood_after, fast.log_likelihood_after + kFitTolerance);
  EXPECT_NEAR(refitted.values(1), 8.0, 3 * refitted.stderrs(1));
  const Diagnosis d = diagnose(lab, model, kDiagnoseAlpha, only, nullptr, given, FitPath::fast);
  const Diagnosis exact = diagnose(lab, model, kDiagnoseAlpha, only, nullptr, given, FitPath::exact);
  ASSERT_TRUE(d.best && exact.best);
  EXPECT_EQ(d.candidates[*d.best].effect, "warmup");
  EXPECT_EQ(exact.candidates[*exact.best].effect, "warmup");
  EXPECT_TRUE(candidate(d, "warmup").exact);
  // The same optimum, to the fast path's tolerance (0.01 in log-likelihood, as fast_path_test).
  EXPECT_NEAR(candidate(d, "warmup").delta_log_likelihood, candidate(exact, "warmup").delta_log_likelihood, 0.01);
  for (const Candidate& c : exact.candidates) EXPECT_EQ(candidate(d, c.effect).significant, c.significant) << c.effect;
}

TEST(Diagnose, TwoLargeEffectsAreEachJudgedAgainstTheScatterTheirOwnModelLeaves) {
  // A wheel scale and a wheelbase, both large. Against the base's scatter (both misfits) no
  // gain would stand out; against the scatter its own model leaves (the other's misfit, here
  // a dispersion above 1000) the first-ranked one does, because it explains more than the
  // other leaves over the experiments' many degrees of freedom. It is adopted, and the next
  // round adopts the other.
  const Suite lab = test::synth_suite(standard_world({{"scale_error", {1.01}}, {"wheelbase_error", {1.02}}}, 13), "two");
  const Diagnosis d = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"scale_error", "wheelbase_error"});
  ASSERT_TRUE(d.best);
  const Candidate& first = d.candidates[*d.best];
  std::printf("%s: dispersion %.3g, p %.2g\n", first.effect.c_str(), first.mean_dispersion, first.mean_p_value_dispersed);
  EXPECT_GT(first.mean_dispersion, 100.0);
  EXPECT_LT(first.mean_p_value_dispersed, kDiagnoseAlpha);
  const Diagnosis next = diagnose(lab, first.model, kDiagnoseAlpha, {"scale_error", "wheelbase_error"});
  ASSERT_TRUE(next.best);
  const Candidate& second = next.candidates[*next.best];
  EXPECT_LT(second.mean_dispersion, 2.0);  // nothing left beside it
  std::vector<std::string> named = {first.effect, second.effect};
  std::sort(named.begin(), named.end());
  EXPECT_EQ(named, (std::vector<std::string>{"scale_error", "wheelbase_error"}));
}

TEST(Diagnose, AMimicIsNamedAndNotAdopted) {
  // Tyre scrub on arcs only (Eb_arc = 1.02, spins at 1): offered only a single wheelbase, the
  // loop finds it significant in-sample (a compromise between arcs and spins), but with it
  // (and with a scale error beside it) the experiments' mean errors still scatter a hundred
  // times what the model predicts: against that its gain is nothing. So is a scale error's.
  // (Fitted without the spins it also predicts them wrong: before the overdispersed-mean rule
  // the held-out likelihood named it a mimic. The held-out rule is now tested on the noise
  // correlation of Verdict.ConstantNoiseLevelIsNotAdoptedForNoiseThatGrowsWithSpeed.)
  const Suite lab = test::synth_suite(standard_world({{"turn_dependent_wheelbase", {1.02, 1.0}}}, 7), "mimic");
  const Diagnosis d = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"wheelbase_error", "scale_error"});
  EXPECT_FALSE(d.best);
  EXPECT_FALSE(d.explained);
  for (const char* name : {"wheelbase_error", "scale_error"}) {
    const Candidate& c = candidate(d, name);
    EXPECT_TRUE(c.significant) << name;
    EXPECT_LT(c.mean_p_value, kDiagnoseAlpha / 2) << name;
    EXPECT_GT(c.mean_dispersion, 10.0) << name;
    EXPECT_EQ(c.verdict, "stopped") << name;
    EXPECT_EQ(c.rule, "overdispersed mean") << name;
    EXPECT_NE(c.decision.find("a misfit that it does not explain"), std::string::npos) << c.decision;
  }
  // With the true effect among the candidates, it is adopted. Only the arcs show it, and
  // fitted without them its arc part is not determined: no kind of path can test it. It is then
  // cross-validated over held-out experiments with every kind in training (one arc held out,
  // the other fitted), where it predicts better.
  const Diagnosis right = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"wheelbase_error", "turn_dependent_wheelbase"});
  ASSERT_TRUE(right.best);
  const Candidate& tdw = right.candidates[*right.best];
  EXPECT_EQ(tdw.effect, "turn_dependent_wheelbase");
  EXPECT_GT(tdw.delta_held_out, 0.0);
  ASSERT_FALSE(tdw.held_out_by_fold.empty());
  EXPECT_EQ(tdw.held_out_by_fold.front().fold.rfind(lab.experiments.front().name + "+", 0), 0u);  // experiment folds
  EXPECT_NE(tdw.decision.find("predicts the held-out folds better"), std::string::npos) << tdw.decision;
}

TEST(Diagnose, ACandidateThatCannotPredictAFoldsRunsIsContradictedByIt) {
  // A custom noise factor 1 + c*v where the model overstates the wheel noise twice on runs at
  // 0.2 and 1 m/s: fitted without the fast runs it wants c = -3.75, a negative factor on them.
  // That fold contradicts it, in words, and the candidate is a mimic; until 2026-12 the error of
  // the expression ended diagnose (exit 2).
  const Suite lab = test::synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/noise_overstated_two_speeds.yaml"),
                                      "wall_fold");
  CustomEffect def;
  def.name = "vnoise";
  def.parameters = {"c"};
  def.noise.text = "1 + c * v";
  const Diagnosis d = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"backlash"}, nullptr, {define_custom_effect(def, {0.0})});
  const Candidate& c = candidate(d, "vnoise");
  ASSERT_TRUE(c.significant);
  const auto fast = std::find_if(c.held_out_by_fold.begin(), c.held_out_by_fold.end(),
                                 [](const Candidate::FoldGain& g) { return g.fold.rfind("fastline", 0) == 0; });
  ASSERT_NE(fast, c.held_out_by_fold.end());
  EXPECT_NE(fast->wall.find("must be >= 0"), std::string::npos) << fast->wall;
  EXPECT_TRUE(fast->contradicts);
  EXPECT_FALSE(fast->counted);
  EXPECT_EQ(c.verdict, "mimic");
  EXPECT_NE(c.decision.find("cannot predict these runs at all"), std::string::npos) << c.decision;
}

TEST(Calibrate, AModelThatCannotPredictTheHeldOutRunsIsStillWritten) {
  // Calibrated on the slow runs, the adopted noise factor 1 + c*v (c near -2.5) is negative at
  // the held-out runs' 0.6 m/s. The hold-out says so, with the experiments outside the training
  // domain, and the menu of next experiments leaves out those at 0.6 m/s; until 2026-12 the
  // expression's error ended calibrate (exit 2) and nothing was written.
  const Suite lab = test::synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/noise_below_one_when_slow.yaml"),
                                      "wall_holdout");
  Suite train = lab, fast = lab;
  train.experiments.clear();
  fast.experiments.clear();
  for (const SuiteExperiment& ex : lab.experiments) (ex.kind == "fast" ? fast : train).experiments.push_back(ex);
  CustomEffect def;
  def.name = "vnoise";
  def.parameters = {"c"};
  def.noise.text = "1 + c * v";
  CalibrateOptions options;
  options.diagnose.candidates = {define_custom_effect(def, {0.0})};
  const CalibrateResult c = calibrate(train, suite_model(train), options, &fast);
  ASSERT_NE(std::find(c.named.begin(), c.named.end(), "vnoise"), c.named.end());
  SuiteModel model = c.model;
  const double slope = fitted_parameter(model, "vnoise.c");
  ASSERT_LT(1 + slope * 0.6, 0.0);
  ASSERT_TRUE(c.holdout);
  EXPECT_NE(c.holdout->cannot_predict.find("must be >= 0"), std::string::npos) << c.holdout->cannot_predict;
  EXPECT_EQ(c.holdout->summary.verdict, "inconsistent");
  EXPECT_EQ(c.holdout->experiments, 1u);
  EXPECT_FALSE(c.holdout->extrapolation.empty());  // 0.6 m/s above the training runs' speeds
  ASSERT_FALSE(c.next_experiments.empty());
  for (const NextExperiment& n : c.next_experiments) {
    EXPECT_EQ(n.experiment.path_yaml.find("speed: 0.6,"), std::string::npos) << n.experiment.name;
  }
  // The items left out are named, with the error, and they are the 0.6 m/s ones.
  ASSERT_FALSE(c.unpredictable_experiments.empty());
  for (const UnpredictableExperiment& u : c.unpredictable_experiments) {
    EXPECT_EQ(u.name.substr(u.name.size() - 6), "0.6mps") << u.name;
    EXPECT_NE(u.why.find("must be >= 0"), std::string::npos) << u.why;
  }
  std::size_t fast_items = 0;
  for (const MenuExperiment& m : experiment_menu(train)) fast_items += m.path_yaml.find("speed: 0.6,") != std::string::npos;
  EXPECT_EQ(c.unpredictable_experiments.size(), fast_items);
}

TEST(Diagnose, AFoldThatLeavesTheModelUndeterminedTestsNothing) {
  // The model's turn-dependent wheelbase is right, and the wheel diameters differ (Ed = 0.998).
  // Only the arcs turn along arcs, so with the arcs held out the model's arc wheelbase is not
  // determined: that fold cannot test the diameter ratio, whatever its gain there (with and
  // without it the prediction of the arcs extrapolates the arc wheelbase). The folds that do
  // not turn leave the model determined and test it, and it is adopted. (The spins hold 94% of
  // the information about the spin wheelbase, the squares' turns on the spot the rest: with
  // them held out it is not determined either, at 4 times its standard error.)
  const EffectSpec tdw{"turn_dependent_wheelbase", {1.02, 1.01}};
  const Suite lab = test::synth_suite(standard_world({tdw, {"wheel_diameter_ratio", {0.998}}}, 21), "undetermined");
  SuiteModel model = suite_model(lab);
  model.effects = {tdw};
  const Diagnosis d = diagnose(lab, model, kDiagnoseAlpha, {"wheel_diameter_ratio"});
  const Candidate& c = candidate(d, "wheel_diameter_ratio");
  ASSERT_FALSE(c.held_out_by_fold.empty());
  for (const Candidate::FoldGain& g : c.held_out_by_fold) {
    if (g.fold == "arc") {
      EXPECT_FALSE(g.counted);
      EXPECT_FALSE(g.contradicts);
      EXPECT_EQ(g.undetermined, "turn_dependent_wheelbase.Eb_arc");
      EXPECT_GT(g.model_stderr_ratio, kMaxFoldStderrRatio);
      EXPECT_NE(c.decision.find("the model's turn_dependent_wheelbase.Eb_arc is not determined"), std::string::npos)
          << c.decision;
    } else if (g.fold == "line" || g.fold == "forward") {  // no turning: the rest fix the model
      EXPECT_TRUE(g.undetermined.empty()) << g.fold << ": " << g.undetermined;
      EXPECT_LE(g.model_stderr_ratio, kMaxFoldStderrRatio) << g.fold;
    }
  }
  EXPECT_EQ(c.verdict, "adopted") << c.decision;
}

TEST(Diagnose, ASystematicCandidateThatOnlyInflatesTheCovarianceIsStopped) {
  // Negatively correlated wheel noise inflates the heading variance on straight lines. A custom
  // wheelbase on lines only cannot move any mean there (nothing turns), but a smaller wheelbase
  // inflates the predicted heading variance: its gain is all covariance.
  const Suite lab = test::synth_suite(standard_world({{"wheel_noise_correlation", {-0.9}}}, 11), "rho");
  CustomEffect def;
  def.name = "line_wheelbase";
  def.parameters = {"a"};
  def.wheelbase_factor.text = "1 + a*(r < 0.01)";
  const Diagnosis d = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"wheelbase_error"}, nullptr,
                               {define_custom_effect(def, {0.0})});
  const Candidate& c = candidate(d, "line_wheelbase");
  EXPECT_TRUE(c.significant);
  EXPECT_EQ(c.verdict, "stopped");
  EXPECT_EQ(c.rule, "covariance, not mean");
  EXPECT_LT(c.delta_mean_log_likelihood, 0.1 * c.delta_log_likelihood);
  EXPECT_TRUE(!d.best || d.candidates[*d.best].effect != "line_wheelbase");
}

TEST(Diagnose, ANoiseIsNotAdoptedForAScatterThatFollowsTheStartHeading) {
  // A floor that slopes: a sideways slip of a cos(heading) per metre, in no catalogue, and each
  // run starts at its own heading, so the runs of one experiment end apart, and more than the
  // model predicts. Random candidates widen the prediction to take that spread up (before the
  // run-by-run rule bumps were adopted in such blind worlds); but the runs' errors about their
  // experiment's mean follow their heading, so the spread is systematic: each random candidate
  // that gets that far is stopped by the rule, nothing is adopted, and the heading, run by run,
  // is what the misfit lines up with first.
  WorldFile w = standard_world({}, 1812);
  CustomEffect slope;
  slope.name = "slope";
  slope.parameters = {"a"};
  slope.lateral.text = "a * cos(heading)";
  w.world.effects = {define_custom_effect(slope, {0.006})};
  for (WorldExperiment& ex : w.experiments) {
    ex.heading0.given = true;
    ex.heading0.lo = -3.14159;
    ex.heading0.hi = 3.14159;
  }
  const Suite lab = test::synth_suite(w, "run_by_run");
  const Diagnosis d = diagnose(lab, suite_model(lab));
  EXPECT_FALSE(d.best) << d.candidates[*d.best].effect;
  int stopped = 0;
  for (const Candidate& c : d.candidates) {
    if (c.rule != "run by run") continue;
    EXPECT_FALSE(c.systematic) << c.effect;
    ++stopped;
  }
  EXPECT_GE(stopped, 1);
  ASSERT_FALSE(d.residuals.empty());
  EXPECT_EQ(d.residuals.front().feature, "heading");
  EXPECT_EQ(d.residuals.front().part, "run");
  EXPECT_LT(d.residuals.front().p_value, kDiagnoseAlpha);
}

/// The standard experiment set recorded on four days, 7 runs each (a lab of few runs per
/// session, like the blind generator's grouped ones: no experiment has the ten runs compare's
/// kurtosis test needs), with these hidden effects and the wheels' noise k in the world.
WorldFile few_runs_world(EffectList effects, double k, std::uint64_t seed) {
  WorldFile w = standard_world(std::move(effects), seed);
  w.world.noise = {k, k};
  std::vector<WorldExperiment> days;
  for (int day = 1; day <= 4; ++day) {
    for (WorldExperiment ex : w.experiments) {
      ex.kind = ex.name;
      ex.name += "-day" + std::to_string(day);
      ex.group = "day-" + std::to_string(day);
      ex.runs = 7;
      days.push_back(ex);
    }
  }
  w.experiments = std::move(days);
  return w;
}

TEST(Diagnose, TheTailsDecideBetweenANoiseLevelAndBumps) {
  // A wheel noise level and bumps add the same variance per metre, and the Gaussian likelihood
  // ties them; bumps have one parameter fewer, so the ranking named bumps in blind worlds whose
  // noise was only larger (worlds 67 and 105 of the mixed batch 15122026). With 7 runs per
  // experiment compare cannot see the tails either. The tails rule reads them against each
  // model's own world: Gaussian errors name the noise level, bumps of the blind generator's
  // sizes (rate 0.3/m, a jolt of 10 mm) name bumps. Two labs of each, seeds drawn for this
  // test (of three drawn, two kept to keep the emulated aarch64 run short; the third of each
  // named right too). Smaller jolts, 5 mm at 0.5/m, leave tails that 252 runs hardly show
  // (p = 0.004 to 0.12 against the noise level's world): the rule then names the noise level in
  // two labs of three.
  const std::vector<std::string> only = {"bumps", kWheelNoiseLevel};
  const EffectList systematic = {{"wheel_diameter_ratio", {1.003}}, {"wheelbase_error", {1.01}}};
  int stopped = 0;
  for (std::uint64_t seed : {11261, 11262}) {
    const Suite lab = test::synth_suite(few_runs_world(systematic, 2.2e-3, seed), "tails_gaussian");
    SuiteModel model = suite_model(lab);
    model.effects = systematic;
    const Diagnosis d = diagnose(lab, model, kDiagnoseAlpha, only);
    ASSERT_TRUE(d.best) << seed;
    EXPECT_EQ(d.candidates[*d.best].effect, kWheelNoiseLevel) << seed;
    stopped += candidate(d, "bumps").rule == "tails" ? 1 : 0;
  }
  for (std::uint64_t seed : {11264, 11265}) {
    EffectList effects = systematic;
    effects.push_back({"bumps", {0.3, 0.010}});
    const Suite lab = test::synth_suite(few_runs_world(effects, 1e-3, seed), "tails_bumps");
    SuiteModel model = suite_model(lab);
    model.effects = systematic;
    const Diagnosis d = diagnose(lab, model, kDiagnoseAlpha, only);
    ASSERT_TRUE(d.best) << seed;
    EXPECT_EQ(d.candidates[*d.best].effect, "bumps") << seed;
    stopped += candidate(d, kWheelNoiseLevel).rule == "tails" ? 1 : 0;
    // The jolt's size comes from the tails of every experiment (no straight line of 7 runs
    // shows them to the completion, which keeps its 5 mm start): closer to the true 10 mm.
    const Candidate& bumps = candidate(d, "bumps");
    std::printf("seed %llu: bumps sigma %.4g m (true 0.010), %s\n", static_cast<unsigned long long>(seed),
                bumps.values[1], bumps.tails_note.c_str());
    EXPECT_NE(bumps.tails_note.find("simulated method of moments"), std::string::npos) << bumps.tails_note;
    EXPECT_LT(std::abs(std::log(bumps.values[1] / 0.010)), std::log(2.0)) << seed;
  }
  std::printf("tails rule: decided against the ranking in %d of 4 labs\n", stopped);
  EXPECT_GE(stopped, 1);  // the rule, not the ranking, decided somewhere
}

TEST(Diagnose, ACandidateAtABoundOrConfoundedIsStopped) {
  // The standard lab's lines and spins only (standard.yaml's seed): turn_dependent_wheelbase's
  // arc part is not determined (no arc), and its fit runs to the edge of its range.
  WorldFile w = load_world(kStandard);
  w.experiments.erase(std::remove_if(w.experiments.begin(), w.experiments.end(),
                                     [](const WorldExperiment& e) { return e.name.rfind("line", 0) && e.name.rfind("spin", 0); }),
                      w.experiments.end());
  ASSERT_EQ(w.experiments.size(), 4u);
  const Suite lab = test::synth_suite(w, "bound");
  const Diagnosis d = diagnose(lab, suite_model(lab), kDiagnoseAlpha, {"turn_dependent_wheelbase"});
  const Candidate& tdw = candidate(d, "turn_dependent_wheelbase");
  EXPECT_TRUE(tdw.significant);
  EXPECT_EQ(tdw.verdict, "stopped");
  EXPECT_EQ(tdw.rule, "parameter at bound");
  EXPECT_EQ(tdw.at_bound, (std::vector<std::string>{"turn_dependent_wheelbase.Eb_arc"}));
  EXPECT_FALSE(d.best);
  // A custom scale in a model that has scale_error already: the two are one parameter.
  SuiteModel model = suite_model(lab);
  model.effects = {{"scale_error", {1.0}}};
  CustomEffect def;
  def.name = "another_scale";
  def.parameters = {"a"};
  def.scale.text = "1 + a";
  const Diagnosis twice = diagnose(lab, model, kDiagnoseAlpha, {"wheelbase_error"}, nullptr, {define_custom_effect(def, {0.0})});
  const Candidate& again = candidate(twice, "another_scale");
  EXPECT_GT(again.confounded, kConfoundedCorrelation);
  if (again.significant) EXPECT_EQ(again.rule, "confounded");
}

TEST(Diagnose, ANestedRicherCandidateMustFitSignificantlyBetter) {
  // turn_dependent_wheelbase contains wheelbase_error (Eb_arc = Eb_spin). When it ranks first by
  // delta BIC (its extra parameter gains more than ln(runs)/2 in log-likelihood) but that gain
  // is not significant at the per-candidate level (Wilks, 1 dof), the simpler effect must be
  // adopted in its place. The lab of tests/data/worlds/nested_wheelbase.yaml (a blind world on
  // which a plain wheelbase error once drew that case, p = 0.016; with the random stream of
  // 2026-12 its seed no longer does, nor do seeds 1-160) is given a turn dependence too small for its runs
  // to show at the family-wise level (Eb_arc 1.0038 against Eb_spin 1.0045), so that the extra
  // gain falls between the two thresholds in some seeds: on each of 8 seeds, either the richer
  // effect does not rank first, or its extra gain is significant and it is adopted, or it is
  // stopped by the nested rule and wheelbase_error adopted; the last case must occur.
  WorldFile w = load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/nested_wheelbase.yaml");
  w.world.effects = {{"turn_dependent_wheelbase", {1.0038, 1.0045178}}};
  int stopped = 0;
  for (std::uint64_t seed = 1; seed <= 8; ++seed) {
    w.seed = seed;
    const Suite lab = test::synth_suite(w, "nested" + std::to_string(seed));
    const Diagnosis d = diagnose(lab, suite_model(lab), DiagnoseOptions{});
    ASSERT_TRUE(d.best) << seed;
    const Candidate& rich = candidate(d, "turn_dependent_wheelbase");
    const Candidate& plain = candidate(d, "wheelbase_error");
    const double per_candidate = kDiagnoseAlpha / static_cast<double>(d.candidates.size());
    const double p = boost::math::cdf(boost::math::complement(
        boost::math::chi_squared(1), 2.0 * (rich.delta_log_likelihood - plain.delta_log_likelihood)));
    const std::string& adopted = d.candidates[*d.best].effect;
    if (!(rich.delta_bic < plain.delta_bic)) {
      EXPECT_EQ(adopted, "wheelbase_error") << seed;
    } else if (p < per_candidate) {
      EXPECT_EQ(adopted, "turn_dependent_wheelbase") << seed;
    } else {
      ++stopped;
      EXPECT_EQ(adopted, "wheelbase_error") << seed;
      EXPECT_EQ(rich.verdict, "stopped") << seed;
      EXPECT_EQ(rich.rule, "nested") << seed;
    }
  }
  EXPECT_GE(stopped, 1);
  std::printf("the nested rule stopped the richer effect on %d of 8 seeds\n", stopped);
  // The same lab with a large turn dependence (Eb_arc 1.004, Eb_spin 1.010): the richer effect
  // fits significantly better and keeps its place.
  w = load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/nested_wheelbase.yaml");
  w.world.effects = {{"turn_dependent_wheelbase", {1.004, 1.010}}};
  const Suite turn = test::synth_suite(w, "nested_turn");
  const Diagnosis t = diagnose(turn, suite_model(turn), DiagnoseOptions{});
  ASSERT_TRUE(t.best);
  EXPECT_EQ(t.candidates[*t.best].effect, "turn_dependent_wheelbase");
}

TEST(Diagnose, AVarianceCandidatesRatioIsScaledForHeavyTails) {
  // tests/data/worlds/bumps_then_turn_slip.yaml (a blind world): bumps alone. With the bumps
  // adopted, a turn slip's likelihood ratio on the Gaussian scatter likelihood would pass the
  // per-candidate level; scaled by its sandwich variance over the observed information (the
  // bumps' heavy tails), it does not, and the bumps alone are named.
  const Suite lab = test::synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/bumps_then_turn_slip.yaml"), "tails_scale");
  CalibrateOptions options;
  options.rounds = 3;
  const CalibrateResult c = calibrate(lab, suite_model(lab), options);
  EXPECT_EQ(c.named, std::vector<std::string>{"bumps"});
  ASSERT_GE(c.rounds.size(), 2u);
  const Diagnosis& second = c.rounds[1];
  const Candidate& slip = candidate(second, "turn_slip");
  const double level = second.alpha / static_cast<double>(second.candidates.size());
  const double unscaled = lrt_p_value(slip.delta_log_likelihood, slip.dof, true);
  std::cout << "  turn_slip: d logL " << slip.delta_log_likelihood << ", p " << slip.p_value << " (unscaled " << unscaled
            << ", level " << level << ")\n";
  EXPECT_LT(unscaled, level);  // the Gaussian ratio alone would call it significant
  EXPECT_FALSE(slip.significant);
  EXPECT_GT(slip.p_value, 10.0 * unscaled);
  EXPECT_TRUE(c.explained);
}

TEST(Diagnose, TheNeesRuleAllowsSamplingError) {
  // 2 sqrt(6/n): 0.49 for 100 runs.
  const ModelSummary before{0.0, 3.2, "inconsistent"};
  EXPECT_FALSE(moves_nees_away(before, {0.0, 3.6, ""}, 100));
  EXPECT_TRUE(moves_nees_away(before, {0.0, 3.8, ""}, 100));
  EXPECT_TRUE(moves_nees_away(before, {0.0, 2.2, ""}, 100));
  EXPECT_FALSE(moves_nees_away({0.0, 50.0, ""}, {0.0, 7.0, ""}, 100));
  EXPECT_FALSE(moves_nees_away({0.0, 2.0, ""}, {0.0, 3.3, ""}, 100));
}

TEST(Domain, TrainingRangesAndExtrapolation) {
  const Suite lab = test::synth_suite(load_world(kStandard), "domain");
  const Domain d = training_domain(lab, lab.robot.wheelbase_m);
  // Every experiment at speed 0.3 (its faster wheel): lines and spins drive both wheels at it,
  // the 1 m arcs (B = 0.4 m) their outer wheel on a radius of 1.2 m, so the mean wheel speed
  // is 0.3 / 1.2 = 0.25 m/s.
  EXPECT_NEAR(d.speed_mps.hi, 0.3, 1e-9);
  EXPECT_LT(d.speed_mps.lo, 0.3);
  EXPECT_NEAR(d.spin_fraction.lo, 0.0, 1e-12);
  EXPECT_NEAR(d.spin_fraction.hi, 1.0, 1e-12);
  EXPECT_NEAR(d.length_m.hi, 10.0, 1e-9);  // forward-back 5 m and back
  // An experiment faster and longer than any training run.
  SuiteExperiment fast = lab.experiments[1];  // line-8m
  fast.path.keyframes = keyframes_from_segments({{PathSegment::Kind::line, 20.0, 0.0, 0.0}}, lab.robot.wheelbase_m, 0.9);
  const std::vector<std::string> x = extrapolation(d, fast, lab.robot.wheelbase_m);
  ASSERT_EQ(x.size(), 2u);
  EXPECT_EQ(x[0], "speed 0.9 m/s is above the training range " + format_number(d.speed_mps.lo, "%.3g") + "-0.3 m/s");
  EXPECT_EQ(x[1], "length 20 m is above the training range " + format_number(d.length_m.lo, "%.3g") + "-10 m");
  EXPECT_TRUE(extrapolation(d, lab.experiments[1], lab.robot.wheelbase_m).empty());
  // compare with a model that has the domain says so per experiment.
  Suite with_fast = lab;
  with_fast.experiments.push_back(fast);
  SuiteModel model = suite_model(lab);
  model.domain = d;
  const Comparison c = compare(with_fast, model, 0.01);
  EXPECT_EQ(c.experiments.back().extrapolation, x);
  EXPECT_TRUE(c.experiments.front().extrapolation.empty());
}

TEST(Domain, ModelYamlRoundTrips) {
  // A suite whose model block is model_yaml's (robot line, domain, effects) reads back the same
  // domain, to the 9 digits it is written with.
  const WorldFile w = load_world(kStandard);
  const auto dir = test::scratch_dir("odomcov_domain_yaml");
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i));
  }
  const std::string plain = suite_yaml(w);
  std::ofstream(dir / "plain.yaml") << plain;
  const Suite lab = load_suite((dir / "plain.yaml").string());
  SuiteModel model = suite_model(lab);
  model.domain = training_domain(lab, lab.robot.wheelbase_m);
  model.effects = {{"wheelbase_error", {1.01}}};
  std::string text;
  for (const std::string& line : {std::string("name: lab\n"), model_yaml(model),
                                  plain.substr(plain.find("experiments:"))}) {
    text += line;
  }
  std::ofstream(dir / "suite.yaml") << text;
  const Suite back = load_suite((dir / "suite.yaml").string());
  ASSERT_TRUE(back.model_domain);
  EXPECT_EQ(back.model_effects, model.effects);
  for (const auto& [a, b] : {std::pair{back.model_domain->speed_mps, model.domain->speed_mps},
                             std::pair{back.model_domain->spin_fraction, model.domain->spin_fraction},
                             std::pair{back.model_domain->length_m, model.domain->length_m},
                             std::pair{back.model_domain->duration_s, model.domain->duration_s}}) {
    EXPECT_NEAR(a.lo, b.lo, 1e-8 * std::max(1.0, b.lo));
    EXPECT_NEAR(a.hi, b.hi, 1e-8 * std::max(1.0, b.hi));
  }
  // Its own training runs lie inside the domain read back.
  for (const SuiteExperiment& ex : back.experiments) {
    EXPECT_TRUE(extrapolation(*back.model_domain, ex, back.robot.wheelbase_m).empty()) << ex.name;
  }
}

TEST(Calibrate, TheStandardLabEndToEnd) {
  // standard.yaml hides Ed = 1.003 and Eb = 1.01. Train on all but the arcs, judge on the arcs.
  const Suite lab = test::synth_suite(load_world(kStandard), "calibrate");
  Suite train = lab, test_arcs = lab;
  train.experiments.clear();
  test_arcs.experiments.clear();
  for (const SuiteExperiment& ex : lab.experiments) (ex.kind == "arc" ? test_arcs : train).experiments.push_back(ex);
  const CalibrateResult c = calibrate(train, suite_model(train), {}, &test_arcs);
  EXPECT_EQ(c.named, (std::vector<std::string>{"wheelbase_error", "wheel_diameter_ratio"}));
  EXPECT_TRUE(c.explained);
  EXPECT_TRUE(c.stand_ins.empty());  // causes: one size on both halves of every feature
  EXPECT_TRUE(c.joint_adopted);
  ASSERT_EQ(c.joint.names, (std::vector<std::string>{"wheelbase_error.Eb", "wheel_diameter_ratio.Ed"}));
  for (std::size_t i = 0; i < 2; ++i) {
    const double truth = i == 0 ? 1.01 : 1.003;
    EXPECT_NEAR(c.joint.values(static_cast<Eigen::Index>(i)), truth, 3 * c.joint.stderrs(static_cast<Eigen::Index>(i))) << c.joint.names[i];
  }
  ASSERT_TRUE(c.model.domain);
  EXPECT_TRUE(c.confounded.empty());
  ASSERT_FALSE(c.next_experiments.empty());
  // diff_drive: the multipliers are the corrected odometry's (constant factors: Eb and the
  // wheels' 2/(Ed + 1), 2 Ed/(Ed + 1)).
  const double Eb = c.joint.values(0), Ed = c.joint.values(1);
  EXPECT_NEAR(c.diff_drive.wheel_separation_multiplier, Eb, 1e-9);
  EXPECT_NEAR(c.diff_drive.left_wheel_radius_multiplier, 2 / (Ed + 1), 1e-9);
  EXPECT_NEAR(c.diff_drive.right_wheel_radius_multiplier, 2 * Ed / (Ed + 1), 1e-9);
  EXPECT_FALSE(c.diff_drive.motion_dependent);
  // Held out: the arcs, predicted from the other kinds, consistent at alpha (NEES of 60 runs:
  // chi^2_180 / 60, two-sided 0.01 bounds 2.32 and 3.76).
  ASSERT_TRUE(c.holdout);
  EXPECT_EQ(c.holdout->summary.verdict, "consistent");
  EXPECT_GT(c.holdout->summary.nees_mean, 2.32);
  EXPECT_LT(c.holdout->summary.nees_mean, 3.76);
  ASSERT_EQ(c.holdout->nees_by_kind.size(), 1u);
  EXPECT_EQ(c.holdout->nees_by_kind[0].first, "arc");
  // The same effects refitted on the held-out arcs: from the held-out model's likelihood, never
  // below it, and (two parameters on 60 runs) as consistent as the prediction.
  ASSERT_TRUE(c.holdout->refitted);
  const HoldoutSummary::Refitted& refit = *c.holdout->refitted;
  EXPECT_EQ(refit.fit.names, c.joint.names);
  EXPECT_NEAR(refit.fit.log_likelihood_before, c.holdout->summary.log_likelihood,
              1e-9 * std::abs(c.holdout->summary.log_likelihood));
  EXPECT_GE(refit.fit.log_likelihood_after, refit.fit.log_likelihood_before);
  EXPECT_GT(refit.nees_mean, 2.32);
  EXPECT_LT(refit.nees_mean, 3.76);
  ASSERT_EQ(refit.nees_by_kind.size(), 1u);
  EXPECT_DOUBLE_EQ(refit.nees_by_kind[0].second, refit.nees_mean);
  // Predicted with what the training runs leave unknown (the posterior predictive). The world has
  // no groups, so no run is conditioned on another and the plug-in marginal NEES is compare's.
  // The posterior predictive's NEES is not held to chi^2_180/60 bounds here: every held-out arc
  // shares the training posterior's one error (e.g. a reference offset the training runs size
  // only through their heading noise, whose posterior mean is a draw about the truth and which
  // a half circle doubles), so the 60 runs' mean NEES does not average it away. Its calibration
  // is tested over 200 worlds, one run each (Design.APredictionCarriesWhatItsTrainingCouldNotSize).
  // (Under the random stream before 2026-12 this lab gave 2.3-3.8; under that of 2026-12 its sized
  // posterior puts the offset's dy at -6.7 mm, 2.4 posterior sd from the truth, and the arcs'
  // NEES at 7.6.) The training has no arcs, so it cannot size a wheelbase that differs on arcs;
  // that is said.
  ASSERT_TRUE(c.holdout->predictive);
  const HoldoutSummary::Predictive& pred = *c.holdout->predictive;
  EXPECT_NEAR(pred.plugin_nees_mean, c.holdout->summary.nees_mean, 1e-9 * c.holdout->summary.nees_mean);
  for (const double nees : {pred.sized_nees_mean, pred.nees_mean}) {
    EXPECT_TRUE(std::isfinite(nees) && nees > 0.0) << nees;
  }
  ASSERT_EQ(pred.sized_by_kind.size(), 1u);
  EXPECT_DOUBLE_EQ(pred.sized_by_kind[0].second, pred.sized_nees_mean);
  const auto arc = std::find_if(pred.parameters.begin(), pred.parameters.end(),
                                [](const auto& q) { return q.name == "turn_dependent_wheelbase.Eb_arc"; });
  ASSERT_NE(arc, pred.parameters.end());
  EXPECT_FALSE(arc->sized);
  for (const auto& q : pred.parameters) EXPECT_GE(q.spread, kPredictiveSpreadShown) << q.name;
  std::printf("arcs held out: marginal NEES %.3f, with the training uncertainty %.3f, with the priors %.3f\n",
              pred.plugin_nees_mean, pred.sized_nees_mean, pred.nees_mean);
  // The training runs by kind: every training kind once, in order of first appearance, and
  // their run-weighted mean is the whole NEES mean.
  std::vector<std::string> kinds;
  std::map<std::string, double> runs;
  for (const SuiteExperiment& ex : train.experiments) {
    if (!runs.count(ex.kind)) kinds.push_back(ex.kind);
    runs[ex.kind] += static_cast<double>(ex.runs.size());
  }
  ASSERT_EQ(c.nees_by_kind.size(), kinds.size());
  double weighted = 0.0, total = 0.0;
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    EXPECT_EQ(c.nees_by_kind[i].first, kinds[i]);
    weighted += c.nees_by_kind[i].second * runs[kinds[i]];
    total += runs[kinds[i]];
  }
  EXPECT_NEAR(weighted / total, c.after.nees_mean, 1e-12 * c.after.nees_mean);
  // The arcs' mean wheel speed (0.25 m/s) is below every training run's.
  ASSERT_FALSE(c.holdout->extrapolation.empty());
  EXPECT_EQ(c.holdout->extrapolation[0].rfind("arc-left: speed 0.25 m/s is below the training range", 0), 0u);
}

TEST(Calibrate, AScaleThatFadesIsAStandInNotACause) {
  // The distance scale fades from 1.02 as the tyres warm (time constant 20 s), physics in no
  // catalogue. A constant scale_error predicts every held-out kind of path better than no
  // scale, and is adopted; but fitted on the shorter runs it is larger than on the longer ones,
  // which a cause would not be. calibrate keeps it, calls it a stand-in and the runs not
  // explained.
  const Suite lab = test::synth_suite(standard_world({warmup(0.02, 20.0)}, 2027), "warm");
  const CalibrateResult c = calibrate(lab, suite_model(lab), {});
  ASSERT_FALSE(c.named.empty());
  EXPECT_EQ(c.named.front(), "scale_error");
  EXPECT_FALSE(c.explained);
  const auto s = std::find_if(c.stand_ins.begin(), c.stand_ins.end(), [](const StandIn& x) { return x.effect == "scale_error"; });
  ASSERT_NE(s, c.stand_ins.end());
  EXPECT_EQ(s->parameter, "scale_error.Es");
  EXPECT_LT(s->p_value, s->level);
  EXPECT_GT(s->level, 0.0);
  EXPECT_LE(s->level, kDiagnoseAlpha);
  EXPECT_GE(s->phi, 1.0);
  // The longer side's scale is the smaller one (nearer 1: the transient is a smaller share).
  if (s->feature == "distance") EXPECT_GT(s->value[0], s->value[1]);
  EXPECT_NE(s->text.find("stands in for something that changes with " + s->feature), std::string::npos);
}

}  // namespace
}  // namespace odomcov

namespace odomcov {
namespace {

/// A world whose runs hardly separate a travel scale Es from a wheelbase factor Eb: spins on the
/// spot, whose heading fixes only Es/Eb, and one short line, which alone measures Es (weakly:
/// 0.5 m); plus one more experiment (name, runs, path) when `extra_name` is not empty.
std::string confounded_world(const std::string& extra_name, std::int64_t extra_runs, const std::string& extra_path) {
  std::string text =
      "name: confounded\n"
      "robot: {wheelbase: 0.4, k_left: 1.0e-3, k_right: 1.0e-3}\n"
      "world:\n  effects:\n    - scale_error: {Es: 1.01}\n    - wheelbase_error: {Eb: 1.02}\n"
      "measurement_noise: {xy: 0.002, theta_deg: 0.1}\n"
      "seed: 2311\n"
      "experiments:\n"
      "  - name: spin-a\n    runs: 30\n    path: {sample_rate: 50, speed: 0.3, segments: [{turn_deg: 360}]}\n"
      "  - name: line-a\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{line: 0.5}]}\n";
  if (!extra_name.empty()) {
    text += "  - name: " + extra_name + "\n    runs: " + std::to_string(extra_runs) + "\n    path: " + extra_path + "\n";
  }
  return text;
}

double worst_stderr(const FitResult& f) { return f.stderrs.maxCoeff(); }

TEST(Calibrate, ANestedEffectIsSimplifiedAfterTheRounds) {
  // tests/data/worlds/nested_after.yaml (a blind world): a wheel diameter ratio and a plain
  // wheelbase error. The first round adopts turn_dependent_wheelbase, whose arc part takes up
  // the ratio's share of the arcs' heading; once the ratio is in, the turn dependence is not
  // significant and the check after the rounds puts wheelbase_error in its place. Both
  // parameters then lie within 3 standard errors of the world's.
  const Suite lab = test::synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/nested_after.yaml"), "nested_after");
  CalibrateOptions options;
  options.rounds = 3;
  const CalibrateResult c = calibrate(lab, suite_model(lab), options);
  ASSERT_FALSE(c.rounds.empty());
  ASSERT_TRUE(c.rounds.front().best);
  EXPECT_EQ(c.rounds.front().candidates[*c.rounds.front().best].effect, "turn_dependent_wheelbase");
  ASSERT_EQ(c.simplified.size(), 1u);
  EXPECT_EQ(c.named, (std::vector<std::string>{"wheelbase_error", "wheel_diameter_ratio"}));
  ASSERT_EQ(c.joint.names, (std::vector<std::string>{"wheelbase_error.Eb", "wheel_diameter_ratio.Ed"}));
  const double truth[] = {1.0046103, 1.0021668};
  for (Eigen::Index k = 0; k < 2; ++k) EXPECT_NEAR(c.joint.values(k), truth[k], 3 * c.joint.stderrs(k)) << c.joint.names[static_cast<std::size_t>(k)];
  // The standard lab's plain wheelbase, adopted as such: nothing to simplify.
  const Suite standard = test::synth_suite(load_world(kStandard), "nested_none");
  EXPECT_TRUE(calibrate(standard, suite_model(standard), options).simplified.empty());
}

TEST(Calibrate, AnEffectTheOthersMadeUnnecessaryIsTakenOutAfterTheRounds) {
  // tests/data/worlds/offset_before_backlash.yaml (a blind world): backlash and a wheelbase
  // error. A reference offset adopted in round 2, before the backlash, takes up part of what the
  // backlash does; with the backlash refitted beside it, it is not significant, and the check
  // after the rounds takes it out.
  const Suite lab = test::synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/offset_before_backlash.yaml"), "drop");
  CalibrateOptions options;
  options.rounds = 3;
  const CalibrateResult c = calibrate(lab, suite_model(lab), options);
  std::vector<std::string> adopted;
  for (const Diagnosis& d : c.rounds) {
    if (d.best) adopted.push_back(d.candidates[*d.best].effect);
  }
  ASSERT_EQ(adopted, (std::vector<std::string>{"turn_dependent_wheelbase", "reference_offset", "backlash"}));
  ASSERT_EQ(c.simplified.size(), 2u);
  EXPECT_EQ(c.simplified[1].rfind("reference_offset taken out", 0), 0u) << c.simplified[1];
  EXPECT_EQ(c.named, (std::vector<std::string>{"wheelbase_error", "backlash"}));
  EXPECT_EQ(find_spec(c.model.effects, "reference_offset"), nullptr);
  EXPECT_TRUE(c.explained);
  // What stays passes the check: the backlash, taken out with the rest refitted, loses more
  // than the level allows (its two parameters, without the boundary's halving).
  SuiteModel without = c.model;
  without.effects.erase(std::remove_if(without.effects.begin(), without.effects.end(),
                                       [](const EffectSpec& e) { return e.name == "backlash"; }),
                        without.effects.end());
  const FitResult refit = fit(lab, without, {"wheelbase_error.Eb"}, Likelihood::full);
  const double level = options.diagnose.alpha / static_cast<double>(c.rounds.back().candidates.size());
  EXPECT_LT(lrt_p_value(c.joint.log_likelihood_after - refit.log_likelihood_after, 2, false), level);
}

/// The training runs of a lab whose external reference tracks a point off the axle centre: every
/// path ends facing where it started (full spins, a line there and back, UMBmark squares, full
/// circles), so the offset never shows and the runs cannot size it. `world_effects` is the
/// world's effect block.
std::string facing_start_world(const std::string& world_effects, const std::string& experiments, std::uint64_t seed) {
  return "name: facing_start\n"
         "robot: {wheelbase: 0.3, k_left: 1.0e-3, k_right: 1.0e-3}\n"
         "world:\n  effects: " + world_effects + "\n"
         "measurement_noise: {xy: 0.001, theta_deg: 0.1}\n"
         "seed: " + std::to_string(seed) + "\n"
         "experiments:\n" + experiments;
}

TEST(Design, AMenuItemWhoseGainIsNotANumberIsLeftOutAndNamed) {
  // A per-run radius fitted to random end poses (tests/data/suites/order2_by_candidate.yaml)
  // comes out at an absurd size (sigma ~7), where the model's information is not finite. The
  // menu printed "gain -nan nats" in an order NaN cannot give; now every ranked gain is a
  // number, and the items whose gain is not are named, with why.
  const Suite suite = load_suite(ODOMCOV_SOURCE_DIR "/tests/data/suites/order2_by_candidate.yaml");
  const FitResult f = fit(suite, suite_model(suite), {"per_run_radius.sigma"});
  std::vector<UnpredictableExperiment> left_out;
  const std::vector<NextExperiment> next = next_experiments(suite, f, &left_out);
  for (const NextExperiment& n : next) EXPECT_TRUE(std::isfinite(n.information_gain)) << n.experiment.name;
  EXPECT_TRUE(std::any_of(left_out.begin(), left_out.end(), [](const UnpredictableExperiment& u) {
    return u.why.find("information gain is not a number") != std::string::npos;
  }));
}

TEST(Design, APredictionCarriesWhatItsTrainingCouldNotSize) {
  // The predictive check judged the way a prediction is: over worlds drawn from its prior. Each
  // of M worlds has a reference offset (dx, dy) from the catalogue's prior N(0, 10 mm) (a
  // stratified draw: normal quantiles at (m + 1/2) / M, dy's in another order) and its own
  // training runs and held-out run. The model is the truth without the offset; the training
  // runs all end facing their start, so they cannot size it. The held-out run is a half turn on
  // the spot, where the offset shows twice over. One run per world counts, so the M NEES values
  // are independent and, if the posterior predictive is right, each is chi^2_3: their mean lies
  // within the chi^2_3M / M bounds at two-sided alpha = 0.01. The plug-in prediction, and the
  // one with only what the training runs sized, lie far above them.
  const std::string training_experiments =
      "  - name: spin-ccw\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{turn_deg: 360}]}\n"
      "  - name: spin-cw\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{turn_deg: -360}]}\n"
      "  - name: there-and-back\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{line: 2}, {line: -2}]}\n"
      "  - name: circle\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{arc: {radius: 1, angle_deg: 360}}]}\n"
      "  - name: square-ccw\n    runs: 10\n    path: {sample_rate: 50, speed: 0.3, segments: [{line: 1}, {turn_deg: 90}, "
      "{line: 1}, {turn_deg: 90}, {line: 1}, {turn_deg: 90}, {line: 1}, {turn_deg: 90}]}\n";
  const double prior = 0.01;
  constexpr int kWorlds = 200;
  const boost::math::normal standard;
  double plugin = 0.0, sized = 0.0, predictive = 0.0;
  for (int m = 0; m < kWorlds; ++m) {
    const double x = prior * boost::math::quantile(standard, (m + 0.5) / kWorlds);
    const double y = prior * boost::math::quantile(standard, ((m * 77) % kWorlds + 0.5) / kWorlds);
    const std::string effects = "[{reference_offset: {dx: " + format_number(x, "%.17g") + ", dy: " + format_number(y, "%.17g") + "}}]";
    const std::string tag = "fs_" + std::to_string(m);
    const Suite training = test::synth_suite(
        test::world_from_text(facing_start_world(effects, training_experiments, 5000 + m), tag + "t"), tag + "t");
    SuiteModel model = suite_model(training);
    model.effects.clear();  // the truth without the offset
    const TrainingUncertainty u = training_uncertainty(training, model, {});
    if (m == 0) {
      const auto dx = std::find(u.names.begin(), u.names.end(), "reference_offset.dx") - u.names.begin();
      ASSERT_LT(static_cast<std::size_t>(dx), u.names.size());
      EXPECT_EQ(u.prior_sd[static_cast<std::size_t>(dx)], prior);
      EXPECT_GT(std::sqrt(u.covariance(dx, dx)), 0.9 * prior);  // not sized by the training runs
      EXPECT_FALSE(u.sized[static_cast<std::size_t>(dx)]);
      EXPECT_EQ(u.covariance_sized(dx, dx), 0.0);
    }
    Suite held = test::synth_suite(test::world_from_text(facing_start_world(effects,
        "  - name: half-turn\n    runs: 2\n    path: {sample_rate: 50, speed: 0.3, segments: [{turn_deg: 180}]}\n", 4200 + m), tag), tag);
    held.experiments[0].runs.resize(1);  // a world's runs share its offset: one counts
    const PredictiveCheck c = predictive_check(held, u);
    plugin += c.plugin_mean / kWorlds;
    sized += c.sized_mean / kWorlds;
    predictive += c.predictive_mean / kWorlds;
  }
  const boost::math::chi_squared chi2(3.0 * kWorlds);
  const double lo = boost::math::quantile(chi2, 0.005) / kWorlds, hi = boost::math::quantile(chi2, 0.995) / kWorlds;
  EXPECT_GT(predictive, lo);
  EXPECT_LT(predictive, hi);
  EXPECT_GT(plugin, hi);
  EXPECT_GT(sized, hi);  // the training runs alone cannot know the offset
  std::printf("half turns held out, %d worlds: NEES mean with the priors %.3f (bounds %.3f-%.3f), with the training "
              "uncertainty %.3f, plug-in %.3f\n", kWorlds, predictive, lo, hi, sized, plugin);
}

TEST(Design, ThePosteriorMeanOfAnAbsentEffectIsWhereAFitPutsIt) {
  // The training posterior's mean is one Newton step from the model. For an effect the model
  // lacks and the runs size well (standard.yaml's lab with a scale error of 0.3% besides; the
  // model is the rest of the truth), it must land where fit puts the parameter. The step also
  // moves the other absent effects (the fit holds them at neutral, where the world has them), so
  // the two differ by the estimate's sampling error given the others against without them: for
  // Gaussian estimates the variance of that difference is sd^2 - se^2 (Hausman), the step's
  // posterior sd and the fit's standard error; within 3 of its standard deviations. The prior
  // (sd 0.005) shrinks the step by about (sd / 0.005)^2 = 2e-4 of its size, and the likelihood
  // is nearly quadratic in Es over 0.3%. Both recover the world's Es within 3 of their own
  // standard errors.
  WorldFile w = load_world(kStandard);
  w.world.effects.push_back({"scale_error", {1.003}});
  const Suite lab = test::synth_suite(w, "posterior_mean");
  SuiteModel model = suite_model(lab);
  model.effects = load_world(kStandard).world.effects;  // the truth without the scale error
  const TrainingUncertainty u = training_uncertainty(lab, model, {});
  const auto es = std::find(u.names.begin(), u.names.end(), "scale_error.Es") - u.names.begin();
  ASSERT_LT(static_cast<std::size_t>(es), u.names.size());
  SuiteModel with = model;
  with.effects.push_back({"scale_error", {1.0}});
  const FitResult f = fit(lab, with, {"scale_error.Es"});
  const double se = f.stderrs(0), sd = std::sqrt(u.covariance(es, es));
  EXPECT_NEAR(1.0 + u.shift(es), f.values(0), 3 * std::sqrt(std::max(sd * sd - se * se, 0.0)));
  EXPECT_NEAR(1.0 + u.shift(es), 1.003, 3 * sd);
  EXPECT_NEAR(f.values(0), 1.003, 3 * se);
  EXPECT_TRUE(u.sized[static_cast<std::size_t>(es)]);
  std::printf("Es: fit %.6f +/- %.2g, posterior mean %.6f (sd %.2g)\n", f.values(0), se, 1.0 + u.shift(es),
              std::sqrt(u.covariance(es, es)));
}

TEST(Design, TheRecommendedExperimentReducesTheWorstStandardErrorMost) {
  // The next-experiment advice, checked the way a user would: each item of the menu is recorded
  // (synthesised from the same world), added to the suite and the two parameters refitted. The
  // one the D-optimal ranking recommends must leave the smallest worst standard error of all.
  const std::vector<std::string> names = {"scale_error.Es", "wheelbase_error.Eb"};
  const Suite lab = test::synth_suite(test::world_from_text(confounded_world("", 0, ""), "conf"), "conf");
  const FitResult before = fit(lab, suite_model(lab), names);
  const std::vector<ConfoundedPair> pairs = confounded_pairs(before.names, estimate_covariance(lab, before));
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_GT(std::abs(pairs[0].correlation), kConfoundedCorrelation);
  const std::vector<NextExperiment> ranked = next_experiments(lab, before);
  ASSERT_GE(ranked.size(), 2u);
  std::vector<double> worst;
  for (std::size_t i = 0; i < ranked.size(); ++i) {
    const MenuExperiment& m = ranked[i].experiment;
    const std::string tag = "conf" + std::to_string(i);
    const Suite more = test::synth_suite(test::world_from_text(confounded_world(m.name, m.runs, m.path_yaml), tag), tag);
    worst.push_back(worst_stderr(fit(more, suite_model(more), names)));
    // The expected standard errors foretell the refit's (observed information at the new
    // estimate; for parameters that move the mean, nearly the expected one): within 10%.
    double expected = 0.0;
    for (const auto& [name, se] : ranked[i].expected_stderr) expected = std::max(expected, se);
    EXPECT_NEAR(worst.back(), expected, 0.1 * expected) << m.name;
  }
  const double best_other = *std::min_element(worst.begin() + 1, worst.end());
  EXPECT_LT(worst.front(), worst_stderr(before));
  EXPECT_LE(worst.front(), best_other) << ranked.front().experiment.name;
  std::printf("worst stderr: before %.3g, after the recommended %s %.3g, best other %.3g (%zu items)\n",
              worst_stderr(before), ranked.front().experiment.name.c_str(), worst.front(), best_other, ranked.size());
}

TEST(Design, CalibrateAdvisesTheRunsThatSizeWhatItCouldNotSeparate) {
  // The loop closed by the advice: on spins and one short line, calibrate adopts
  // wheelbase_error and stops scale_error as confounded with it. It must neither adopt nor
  // forget it: the design counts Es beside Eb, so the advice is a run that sizes Es. Recording
  // that run (synthesised from the same world) and calibrating again adopts scale_error, and
  // both estimates lie within 3 standard errors of the world's (Es 1.01, Eb 1.02).
  const Suite lab = test::synth_suite(test::world_from_text(confounded_world("", 0, ""), "unres"), "unres");
  const CalibrateResult before = calibrate(lab, suite_model(lab), {});
  EXPECT_EQ(before.named, (std::vector<std::string>{"wheelbase_error"}));
  EXPECT_EQ(before.unresolved, (std::vector<std::string>{"scale_error"}));
  ASSERT_FALSE(before.confounded.empty());
  EXPECT_EQ(before.confounded.front().a + " " + before.confounded.front().b, "wheelbase_error.Eb scale_error.Es");
  ASSERT_FALSE(before.next_experiments.empty());
  const NextExperiment& advice = before.next_experiments.front();
  const auto& se = advice.expected_stderr;
  ASSERT_TRUE(std::any_of(se.begin(), se.end(), [](const auto& p) { return p.first == "scale_error.Es"; }));

  const MenuExperiment& m = advice.experiment;
  const Suite more = test::synth_suite(test::world_from_text(confounded_world(m.name, m.runs, m.path_yaml), "unres2"), "unres2");
  const CalibrateResult after = calibrate(more, suite_model(more), {});
  EXPECT_TRUE(after.unresolved.empty());
  ASSERT_EQ(after.joint.names.size(), 2u) << m.name;
  for (std::size_t i = 0; i < 2; ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double truth = after.joint.names[i] == "scale_error.Es" ? 1.01 : 1.02;
    EXPECT_NEAR(after.joint.values(k), truth, 3 * after.joint.stderrs(k)) << after.joint.names[i];
  }
  std::printf("advice %s; named after it:", m.name.c_str());
  for (const std::string& n : after.named) std::printf(" %s", n.c_str());
  std::printf("\n");
}

}  // namespace
}  // namespace odomcov
