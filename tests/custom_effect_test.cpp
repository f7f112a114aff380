// Custom effects (docs/effects.md, "Custom effects"): a custom effect written as the catalogue's
// turn_dependent_wheelbase gives the built-in's numbers on both sides; a custom speed-dependent
// scale is fitted back from a synthesised world; definitions round-trip through the writers; bad
// definitions are InputErrors naming file, line and key. (The "consistent with, rejected without"
// check of configs/effects/speed_scale.yaml is effects_test's EffectConfig/speed_scale.)
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/second_order.hpp"
#include "odomcov/io/suite_writer.hpp"
#include "odomcov/measurement/validation.hpp"
#include "odomcov/io/world.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/io/suite_io.hpp"

namespace odomcov {
namespace {

const std::string kTdwConfig = ODOMCOV_SOURCE_DIR "/configs/effects/turn_dependent_wheelbase.yaml";

/// turn_dependent_wheelbase written as a custom effect named `name`.
EffectSpec custom_tdw(double arc, double spin, const std::string& name = "tdw") {
  CustomEffect def;
  def.name = name;
  def.parameters = {"Eb_arc", "Eb_spin"};
  def.wheelbase_factor.text = "Eb_arc + (Eb_spin - Eb_arc) * r";
  return define_custom_effect(def, {arc, spin});
}

std::filesystem::path temp_dir(const std::string& tag) {
  const auto dir = std::filesystem::temp_directory_path() / ("odomcov_custom_" + tag);
  std::filesystem::create_directories(dir);
  return dir;
}

Suite synth_suite(const WorldFile& w, const std::string& tag) {
  const auto dir = temp_dir(tag);
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i));
  }
  std::ofstream(dir / "suite.yaml") << suite_yaml(w);
  return load_suite((dir / "suite.yaml").string());
}

TEST(CustomEffect, TurnDependentWheelbaseGivesTheBuiltInsTheoryExactly) {
  const Config config = load_config(kTdwConfig);
  std::vector<double> durations;
  const auto pieces = model_pieces(config.path, config.robot.wheelbase_m, &durations);
  const EffectList builtin = {{"turn_dependent_wheelbase", {1.002, 1.01}}};
  const EffectList custom = {custom_tdw(1.002, 1.01)};
  const Prediction a = predict(pieces, durations, config.robot, builtin);
  const Prediction b = predict(pieces, durations, config.robot, custom);
  EXPECT_EQ(a.mean, b.mean);
  EXPECT_EQ(a.cov, b.cov);
  EXPECT_NE(a.mean, predict(pieces, durations, config.robot, {}).mean);  // the effect acts
  const Prediction a2 = predict_second_order(pieces, durations, config.robot, builtin);
  const Prediction b2 = predict_second_order(pieces, durations, config.robot, custom);
  EXPECT_EQ(a2.mean, b2.mean);
  EXPECT_EQ(a2.noise_mean, b2.noise_mean);
  EXPECT_EQ(a2.cov, b2.cov);
}

TEST(CustomEffect, TurnDependentWheelbaseGivesTheBuiltInsSimulation) {
  Config config = load_config(kTdwConfig);
  config.simulation.runs = 2000;
  config.model_effects = config.world.effects;
  const Validation a = validate(config, 1e-3);
  config.world.effects = config.model_effects = {custom_tdw(1.002, 1.01)};
  const Validation b = validate(config, 1e-3);
  // Same seed, same samples: the same moments to the last bit, and the same theory.
  EXPECT_EQ(a.simulation.mean, b.simulation.mean);
  EXPECT_EQ(a.simulation.cov, b.simulation.cov);
  EXPECT_EQ(a.theory_mean, b.theory_mean);
  EXPECT_EQ(a.theory_cov, b.theory_cov);
  EXPECT_EQ(b.verdict, "consistent");
}

TEST(CustomEffect, TurnDependentWheelbaseFitsAsTheBuiltInDoes) {
  WorldFile w = load_world(ODOMCOV_SOURCE_DIR "/configs/worlds/standard.yaml");
  w.world.effects = {{"turn_dependent_wheelbase", {1.003, 1.012}}};
  const Suite suite = synth_suite(w, "tdw");
  SuiteModel builtin = suite_model(suite), custom = builtin;
  builtin.effects = {{"turn_dependent_wheelbase", {1.0, 1.0}}};
  custom.effects = {custom_tdw(1.0, 1.0)};
  // compare: the same model gives the same likelihood.
  EXPECT_EQ(compare(suite, builtin, 1e-3).log_likelihood, compare(suite, custom, 1e-3).log_likelihood);
  // fit: the built-in fits log(Eb), the custom Eb itself (an unbounded parameter); both reach the
  // same maximum. The optimiser stops within a small fraction of a standard error of it: we
  // require the two to agree within a tenth of one.
  const FitResult a = fit(suite, builtin, {"turn_dependent_wheelbase.Eb_arc", "turn_dependent_wheelbase.Eb_spin"});
  const FitResult b = fit(suite, custom, {"tdw.Eb_arc", "tdw.Eb_spin"});
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(std::isfinite(a.stderrs(i)) && std::isfinite(b.stderrs(i)));
    EXPECT_LT(std::abs(a.values(i) - b.values(i)), 0.1 * a.stderrs(i)) << i;
    EXPECT_NEAR(b.stderrs(i), a.stderrs(i), 0.05 * a.stderrs(i)) << i;
  }
  EXPECT_NEAR(b.log_likelihood_after, a.log_likelihood_after, 1e-3);
}

// A speed-dependent scale, in no catalogue: the fit recovers a within 3 standard errors
// (alpha = 0.0027 two-sided), the model with it is consistent and the plain one is not.
TEST(CustomEffect, SpeedScaleIsFittedBack) {
  const Suite suite = synth_suite(load_world(ODOMCOV_SOURCE_DIR "/tests/data/worlds/speed_scale.yaml"), "speed");
  SuiteModel model = suite_model(suite);
  EXPECT_EQ(compare(suite, model, 1e-3).verdict.kind, Verdict::Kind::inconsistent);
  CustomEffect def;
  def.name = "speed_scale";
  def.parameters = {"a"};
  def.scale.text = "1 + a * (v - 0.4)";
  model.effects = {define_custom_effect(def, {0.0})};
  EXPECT_EQ(check_fit_parameter("speed_scale.a", model.effects), "");
  EXPECT_NE(check_fit_parameter("speed_scale.a"), "");
  const FitResult r = fit(suite, model, {"speed_scale.a"});
  ASSERT_TRUE(std::isfinite(r.stderrs(0)));
  EXPECT_LT(std::abs(r.values(0) - 0.03), 3 * r.stderrs(0)) << r.values(0) << " +/- " << r.stderrs(0);
  EXPECT_TRUE(compare(suite, r.model, 1e-3).verdict.consistent());
}

// A factor that depends on the history (the distance so far, s) is evaluated per sample by the
// simulator and per model piece by the engine: both sides still agree (speed_scale.yaml's
// path, 10 000 runs, alpha = 0.001, fixed seed), and the plain model is rejected.
TEST(CustomEffect, DistanceDependentScaleAgreesOnBothSides) {
  Config config = load_config(ODOMCOV_SOURCE_DIR "/configs/effects/speed_scale.yaml");
  CustomEffect def;
  def.name = "wear";
  def.parameters = {"a"};
  def.scale.text = "1 + a * min(s, 8)";
  config.world.effects = config.model_effects = {define_custom_effect(def, {0.002})};
  const Validation with = validate(config, 1e-3);
  EXPECT_EQ(with.verdict, "consistent") << with.mean_test.p_value << " " << with.cov_test.p_value;
  config.model_effects.clear();
  EXPECT_EQ(validate(config, 1e-3).verdict, "inconsistent");
}

TEST(CustomEffect, DefinitionsRoundTripThroughTheWriters) {
  const auto dir = temp_dir("roundtrip");
  const EffectSpec spec = custom_tdw(1.0021, 1.013);
  const std::string line = effect_yaml(spec);
  EXPECT_EQ(line, "- custom: {name: tdw, parameters: {Eb_arc: 1.0021, Eb_spin: 1.013}, "
                  "wheelbase_factor: \"Eb_arc + (Eb_spin - Eb_arc) * r\"}");
  std::ofstream(dir / "effects.yaml") << line << "\n- wheelbase_error: {Eb: 1.01}\n";
  const EffectList back = load_effects((dir / "effects.yaml").string());
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0], spec);
  EXPECT_EQ(back[1].name, "wheelbase_error");
  // The suite writer (synth, import) writes the model's custom effects back.
  SuiteDocument doc;
  doc.name = "rt";
  doc.robot = {0.4, {1e-3, 1e-3}};
  doc.model_effects = {spec};
  doc.experiments = {{"line", "{sample_rate: 50, segments: [{line: 1.0}]}", "line.csv", {}}};
  std::ofstream(dir / "line.csv") << "run,x,y,theta\n0,1.001,0,0\n1,0.999,0,0\n";
  std::ofstream(dir / "suite.yaml") << suite_yaml(doc);
  const Suite suite = load_suite((dir / "suite.yaml").string());
  ASSERT_EQ(suite.model_effects.size(), 1u);
  EXPECT_EQ(suite.model_effects[0], spec);
}

/// Writes `text` to a file and returns the InputError loading it as an effect list throws.
InputError load_error(const std::string& text, const std::string& tag) {
  const auto file = temp_dir("bad") / (tag + ".yaml");
  std::ofstream(file) << text;
  try {
    load_effects(file.string());
  } catch (const InputError& e) {
    return e;
  }
  ADD_FAILURE() << tag << ": no error";
  return InputError("", 0, "", "");
}

TEST(CustomEffect, BadDefinitionsNameFileLineAndKey) {
  struct Case {
    const char* tag;
    const char* text;
    int line;
    const char* key;
    const char* message;  // a part of the message (muparser's own where it is the judge)
  };
  const Case cases[] = {
      {"syntax", "- custom:\n    name: x\n    scale: \"1 + * v\"\n", 3, "[0].custom.scale", "Unexpected operator"},
      {"unknown_var", "- custom:\n    name: x\n    parameters: {a: 1}\n    scale: \"1 + b * v\"\n", 4,
       "[0].custom.scale", "Unexpected token \"b\""},
      {"no_name", "- custom:\n    scale: \"1\"\n", 2, "[0].custom.name", "missing required key"},
      {"catalogue_name", "- custom:\n    name: scale_error\n    scale: \"1\"\n", 2, "[0].custom.name", "name clash"},
      {"twice", "- custom: {name: x, scale: \"1\"}\n- custom: {name: x, scale: \"2\"}\n", 2, "[1].custom.name", "name clash"},
      {"param_is_variable", "- custom:\n    name: x\n    parameters: {v: 1}\n    scale: \"v\"\n", 3,
       "[0].custom.parameters.v", "per-sample variable"},
      {"two_results", "- custom:\n    name: x\n    scale: \"1, 2\"\n", 3, "[0].custom.scale", "one expression"},
      {"nothing", "- custom:\n    name: x\n", 2, "[0].custom", "at least one of"},
  };
  for (const Case& c : cases) {
    const InputError e = load_error(c.text, c.tag);
    EXPECT_EQ(e.line(), c.line) << c.tag << ": " << e.what();
    EXPECT_EQ(e.key(), c.key) << c.tag << ": " << e.what();
    EXPECT_NE(e.message().find(c.message), std::string::npos) << c.tag << ": " << e.what();
  }
}

// A value that is not finite at run time (1/(v - 0.5) at the path's speed of 0.5 m/s) is bad
// input naming the expression's line, not a crash.
TEST(CustomEffect, NonFiniteValueAtRunTimeIsAnInputError) {
  const auto file = temp_dir("nonfinite") / "config.yaml";
  std::ofstream(file) << "name: nonfinite\nrobot: {wheelbase: 0.4, k_left: 1.0e-3, k_right: 1.0e-3}\n"
                         "path: {sample_rate: 50, speed: 0.5, segments: [{line: 1.0}]}\n"
                         "world:\n  effects:\n    - custom:\n        name: x\n"
                         "        scale: \"1 / (v - 0.5)\"\n";
  const Config config = load_config(file.string());
  try {
    validate(config, 1e-3);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 8) << e.what();
    EXPECT_EQ(e.key(), "world.effects[0].custom.scale") << e.what();
    EXPECT_NE(e.message().find("evaluates to inf"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace odomcov
