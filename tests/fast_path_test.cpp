// The fast fit path (FitPath::fast: a per-run quadratic surrogate from exact anchors, re-anchored
// until the exact log-likelihood stops improving) against the exact one (every evaluation
// propagates every run), on a synthetic suite and on real OptiOdom runs.
//
// Tolerances. Both paths maximise the same exact log-likelihood; the fast one stops when a step
// gains less than kFitTolerance (1e-3) or the surrogate foretold the gain to that accuracy, so
// near a quadratic optimum its log-likelihood is at most ~kFitTolerance below the maximum and
// its parameters within sqrt(2 kFitTolerance) = 0.045 standard errors of the optimum. We allow
// 0.1 standard errors and 0.01 in log-likelihood (ten times kFitTolerance: the exact path's own
// BOBYQA stopping error comes on top). Standard errors agree to 10%: both are the curvature
// at the optimum, by central differences of the exact model resp. of its surrogate.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/io/world.hpp"
#include "odomcov/io/suite_io.hpp"
#include "synth_util.hpp"

namespace odomcov {
namespace {

namespace fs = std::filesystem;

constexpr double kLogLikelihoodTolerance = 0.01;
constexpr double kStandardErrors = 0.1;

Suite synth_suite(const WorldFile& w, const std::string& tag) {
  const auto dir = fs::temp_directory_path() / ("odomcov_fast_" + tag + "_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i));
  }
  std::ofstream(dir / "suite.yaml") << suite_yaml(w);
  Suite s = load_suite((dir / "suite.yaml").string());
  fs::remove_all(dir);
  return s;
}

void expect_same_fit(const Suite& suite, const SuiteModel& start, const std::vector<std::string>& names,
                     Likelihood kind) {
  const FitResult exact = fit(suite, start, names, kind, nullptr, FitPath::exact);
  const FitResult fast = fit(suite, start, names, kind, nullptr, FitPath::fast);
  EXPECT_NEAR(fast.log_likelihood_after, exact.log_likelihood_after, kLogLikelihoodTolerance);
  EXPECT_DOUBLE_EQ(fast.log_likelihood_before, exact.log_likelihood_before);
  for (std::size_t i = 0; i < names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    ASSERT_TRUE(std::isfinite(exact.stderrs(k))) << names[i];
    EXPECT_NEAR(fast.values(k), exact.values(k), kStandardErrors * exact.stderrs(k)) << names[i];
    EXPECT_NEAR(fast.stderrs(k), exact.stderrs(k), 0.1 * exact.stderrs(k)) << names[i];
  }
  // The fast path propagates the suite far fewer times.
  EXPECT_LT(fast.evaluations, exact.evaluations);
}

TEST(FastPath, FitMatchesExactOnASyntheticSuite) {
  const Suite lab = synth_suite(load_world(ODOMCOV_SOURCE_DIR "/configs/worlds/standard.yaml"), "std");
  const SuiteModel plain = suite_model(lab);
  expect_same_fit(lab, plain, {"wheel_diameter_ratio.Ed", "wheelbase_error.Eb"}, Likelihood::full);
  expect_same_fit(lab, plain, {"k_left", "k_right"}, Likelihood::scatter);
  SuiteModel informed = plain;
  informed.effects = {{"wheel_diameter_ratio", {1.003}}, {"wheelbase_error", {1.01}}};
  expect_same_fit(lab, informed, {"wheel_noise_correlation.rho"}, Likelihood::scatter);
}

TEST(FastPath, FitMatchesExactOnOptiOdomSquares) {
  const Suite squares = test::optiodom_suite({"square"}, "fast");
  ASSERT_GE(squares.experiments.size(), 10u);
  expect_same_fit(squares, suite_model(squares), {"wheel_diameter_ratio.Ed", "wheelbase_error.Eb"},
                  Likelihood::full);
}

TEST(FastPath, AWallBesideAnAnchorIsSteppedAround) {
  // A custom noise factor that is the parameter itself, started just above 0: the fast path's
  // first difference point (start - h) gives a negative factor, which a custom expression may
  // not. The path takes it as a wall and differences on the other side (h, 2h), as beside a
  // bound; until 2026-12 the error ended the fit, and calibrate with it (exit 2 on the OptiOdom
  // runs with a custom noise "1 + c*abs(a)", whose fit walked up to the wall at the largest
  // deceleration). The optimum, a factor near 1 (the world's own noise), is the exact path's.
  const Suite lab = synth_suite(load_world(ODOMCOV_SOURCE_DIR "/configs/worlds/standard.yaml"), "wall");
  CustomEffect def;
  def.name = "noise_factor";
  def.parameters = {"c"};
  def.noise.text = "c";
  SuiteModel start = suite_model(lab);
  start.effects = {define_custom_effect(def, {1e-4})};
  const EffectParameterInfo* c = effect_parameter_info(start, "noise_factor.c");
  ASSERT_NE(c, nullptr);
  const FitCoordinate f = fit_coordinate(*c);
  ASSERT_LT(1e-4 - std::max(f.fd_abs, f.fd_rel * std::abs(1e-4 - f.fd_origin)), 0.0)
      << "the first difference point must lie beyond the wall";
  expect_same_fit(lab, start, {"noise_factor.c"}, Likelihood::scatter);

  // Walls on both sides of the start, closer than a difference step (5e-4 here): no surrogate
  // can be built; the fit takes the exact path, which cannot leave the start either.
  CustomEffect pinned = def;
  pinned.noise.text = "1 - 1e8 * (c - 0.5)^2";
  start.effects = {define_custom_effect(pinned, {0.5})};
  const FitResult walled = fit(lab, start, {"noise_factor.c"}, Likelihood::scatter, nullptr, FitPath::fast);
  EXPECT_NEAR(walled.values(0), 0.5, 1e-4);
  EXPECT_NEAR(walled.log_likelihood_after, walled.log_likelihood_before, kLogLikelihoodTolerance);
}

/// Every candidate: same significance and the same best, gains within the tolerance, and where
/// a parameter has a standard error, the same value within 0.1 of it. `fast_out` receives the
/// fast diagnosis.
void expect_same_diagnosis(const Suite& suite, const SuiteModel& model,
                           const std::vector<std::string>& only = {}, Diagnosis* fast_out = nullptr) {
  const Diagnosis exact = diagnose(suite, model, kDiagnoseAlpha, only, nullptr, {}, FitPath::exact);
  const Diagnosis fast = diagnose(suite, model, kDiagnoseAlpha, only, nullptr, {}, FitPath::fast);
  ASSERT_EQ(fast.candidates.size(), exact.candidates.size());
  ASSERT_TRUE(exact.best.has_value());
  ASSERT_TRUE(fast.best.has_value());
  EXPECT_EQ(fast.candidates[*fast.best].effect, exact.candidates[*exact.best].effect);
  for (const Candidate& e : exact.candidates) {
    const auto f = std::find_if(fast.candidates.begin(), fast.candidates.end(),
                                [&](const Candidate& c) { return c.effect == e.effect; });
    ASSERT_NE(f, fast.candidates.end()) << e.effect;
    EXPECT_NEAR(f->delta_log_likelihood, e.delta_log_likelihood, kLogLikelihoodTolerance) << e.effect;
    EXPECT_EQ(f->significant, e.significant) << e.effect;
    for (std::size_t i = 0; i < e.values.size(); ++i) {
      if (std::isfinite(e.stderrs[i])) {
        EXPECT_NEAR(f->values[i], e.values[i], kStandardErrors * e.stderrs[i]) << e.effect << " " << e.parameters[i];
      }
    }
  }
  EXPECT_NEAR(fast.after.log_likelihood, exact.after.log_likelihood, kLogLikelihoodTolerance);
  if (fast_out) *fast_out = fast;
}

TEST(FastPath, DiagnoseMatchesExact) {
  const Suite lab = synth_suite(load_world(ODOMCOV_SOURCE_DIR "/configs/worlds/standard.yaml"), "diag");
  SuiteModel model = suite_model(lab);
  model.effects = {{"wheel_diameter_ratio", {1.0}}};
  expect_same_diagnosis(lab, model);
}

TEST(FastPath, GroupCandidatesMatchExact) {
  // The fast path starts a group candidate at sd = 0 (its anchor is then the base model's), the
  // exact one at sd's typical size: the same optimum within the same tolerances. The world of
  // configs/effects/group_variation.yaml: Eb varies between six sessions.
  const Suite days = synth_suite(load_world(ODOMCOV_SOURCE_DIR "/configs/effects/group_variation.yaml"), "group");
  SuiteModel model = suite_model(days);
  model.effects = {{"wheelbase_error", {1.0}}};
  Diagnosis fast;
  expect_same_diagnosis(days, model, {kGroupVariation, "wheel_diameter_ratio"}, &fast);
  ASSERT_TRUE(fast.best.has_value());
  EXPECT_EQ(fast.candidates[*fast.best].effect, "group_variation(wheelbase_error.Eb)");
  EXPECT_GE(fast.candidates.size(), 3u);  // the group variations of Eb and Ed, and Ed
}

TEST(FastPath, EveryRegisteredParameterHasAFitCoordinateAndEveryEffectACandidate) {
  // From the registry: a new effect is covered without touching this test.
  for (const EffectInfo& e : effect_catalogue()) {
    const CandidateType* c = find_candidate(e.name);
    ASSERT_NE(c, nullptr) << e.name;
    EXPECT_FALSE(c->fitted.empty()) << e.name;
    EXPECT_EQ(c->systematic, e.systematic) << e.name;
    for (const EffectParameterInfo& p : e.parameters) {
      EXPECT_EQ(check_fit_parameter(e.name + "." + p.name), "") << e.name << "." << p.name;
      const FitCoordinate f = fit_coordinate(p);
      EXPECT_LT(f.lower_u, f.upper_u) << p.name;
      EXPECT_GT(f.step_u, 0.0) << p.name;
      // The typical size lies strictly inside the box the optimiser sees.
      double u = p.typical;
      switch (f.transform) {
        case FitCoordinate::Transform::log: u = std::log(p.typical); break;
        case FitCoordinate::Transform::atanh: u = std::atanh((p.typical - f.mid) / f.half); break;
        case FitCoordinate::Transform::sqrt: u = std::sqrt(p.typical); break;
        case FitCoordinate::Transform::identity: break;
      }
      EXPECT_GT(u, f.lower_u) << e.name << "." << p.name;
      EXPECT_LT(u, f.upper_u) << e.name << "." << p.name;
      if (p.lower <= -1e300) EXPECT_EQ(f.transform, FitCoordinate::Transform::identity) << p.name;
    }
  }
  for (const RobotParameter& p : robot_parameters()) EXPECT_EQ(check_fit_parameter(p.name), "");
}

}  // namespace
}  // namespace odomcov
