// The honest verdict of diagnose: a lab with an effect in no catalogue (a speed-dependent wheel
// scale) must end unexplained with speed as the feature its misfit lines up with; a plain lab
// must be explained; and the words must never say "explains" when the data are not explained.
#include "odomcov/measurement/residual_features.hpp"

#include <gtest/gtest.h>

#include <boost/math/distributions/binomial.hpp>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/measurement/odometry_correction.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/io/world.hpp"

namespace odomcov {
namespace {

const std::string kSource = ODOMCOV_SOURCE_DIR;

/// Adds world `w`'s experiments to `s` as synth writes them at the world's seed (its robot and
/// measurement noise too), with each run's start heading where the world gives one (synth's
/// heading0 column).
void add_world(Suite& s, const WorldFile& w) {
  s.robot = w.robot;
  s.measurement_noise = w.measurement_noise;
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    SuiteExperiment ex;
    ex.name = w.experiments[i].name;
    ex.path = w.experiments[i].path;
    ex.kind = w.experiments[i].kind;
    ex.group = w.experiments[i].group;
    const std::vector<Vector3> measured = synthesize(w, i);
    const std::vector<double> heading0 = start_headings(w, i);
    for (std::size_t r = 0; r < measured.size(); ++r) {
      ex.runs.push_back({std::to_string(r + 1), measured[r], {}, {}});
      if (!heading0.empty()) ex.runs.back().heading0_rad = heading0[r], ex.runs.back().heading0_given = true;
    }
    s.experiments.push_back(std::move(ex));
  }
}

/// The suite synth would write for these worlds, in memory (the last world's nominal robot).
Suite lab(const std::vector<std::string>& world_files) {
  Suite s;
  s.file = "in-memory";
  s.name = "lab";
  for (const std::string& file : world_files) add_world(s, load_world(file));
  return s;
}

/// One lab of world `w` at its seed, in memory.
Suite seeded_lab(const WorldFile& w) {
  Suite s;
  add_world(s, w);
  return s;
}

TEST(PathFeatures, PlannedPaths) {
  const Suite s = lab({kSource + "/tests/data/worlds/speed_slow.yaml"});
  const double B = s.robot.wheelbase_m;
  auto f = [&](const std::string& name) {
    for (const SuiteExperiment& e : s.experiments) {
      if (e.name == name) return path_features(e, e.runs[0], B);
    }
    throw std::logic_error(name);
  };
  const PathFeatures line = f("line-8m-slow");
  EXPECT_NEAR(line.distance_m, 8.0, 1e-12);
  EXPECT_NEAR(line.speed_mps, 0.15, 1e-12);
  EXPECT_EQ(line.spin_fraction, 0.0);
  EXPECT_EQ(line.travel_direction, 1.0);
  EXPECT_EQ(line.reversals, 0.0);
  const PathFeatures back = f("forward-back-slow");
  EXPECT_NEAR(back.travel_direction, 0.0, 1e-12);
  EXPECT_EQ(back.reversals, 2.0);  // each wheel once
  const PathFeatures spin = f("spin-cw-slow");
  EXPECT_NEAR(spin.angle_turned_rad, -4 * M_PI, 1e-9);
  EXPECT_EQ(spin.turn_direction, -1.0);
  EXPECT_NEAR(spin.spin_fraction, 1.0, 1e-12);
  EXPECT_NEAR(spin.speed_mps, 0.15, 1e-12);  // both wheels at 0.15 m/s
  const PathFeatures arc = f("arc-left-slow");
  EXPECT_NEAR(arc.spin_fraction, 0.2, 1e-12);  // B |kappa| / 2 = 0.4 / 2
  EXPECT_EQ(arc.turn_direction, 1.0);
  // Starts and stops: a start and a stop at 0.15 m/s, per wheel; forward-back also reverses
  // (0.15 -> -0.15); a spin starts and stops each wheel once (-0.15, +0.15).
  EXPECT_NEAR(line.acceleration_mps, 0.3, 1e-12);
  EXPECT_NEAR(back.acceleration_mps, 0.6, 1e-12);
  EXPECT_NEAR(spin.acceleration_mps, 0.3, 1e-12);
}

// The heading's direction, the travel-weighted mean of (cos, sin) of the absolute heading, by
// hand: a line keeps its start heading h; a whole spin averages to 0; a left half circle from h
// sweeps h .. h + pi at a constant rate, mean (sin(h + pi) - sin h, cos h - cos(h + pi))/pi =
// (-2 sin h, 2 cos h)/pi. Without a start heading the feature is not known.
TEST(PathFeatures, HeadingIsTheMeanDirectionInTheReferenceFrame) {
  Suite s = lab({kSource + "/tests/data/worlds/speed_slow.yaml"});
  const double B = s.robot.wheelbase_m, h = 0.7;
  auto f = [&](const std::string& name, bool given) {
    for (SuiteExperiment& e : s.experiments) {
      if (e.name != name) continue;
      e.runs[0].heading0_rad = h;
      e.runs[0].heading0_given = given;
      return path_features(e, e.runs[0], B);
    }
    throw std::logic_error(name);
  };
  const PathFeatures line = f("line-8m-slow", true);
  EXPECT_TRUE(line.heading_known);
  EXPECT_NEAR(line.heading_cos, std::cos(h), 1e-12);
  EXPECT_NEAR(line.heading_sin, std::sin(h), 1e-12);
  const PathFeatures spin = f("spin-cw-slow", true);
  EXPECT_NEAR(spin.heading_cos, 0.0, 1e-12);
  EXPECT_NEAR(spin.heading_sin, 0.0, 1e-12);
  const PathFeatures arc = f("arc-left-slow", true);
  EXPECT_NEAR(arc.heading_cos, -2 * std::sin(h) / M_PI, 1e-9);
  EXPECT_NEAR(arc.heading_sin, 2 * std::cos(h) / M_PI, 1e-9);
  EXPECT_FALSE(f("line-8m-slow", false).heading_known);
  // A logged run: 1 m at h, a quarter turn on the spot (travel B pi/4 at h .. h + pi/2, mean
  // direction (cos, sin)(h + pi/4) 2 sqrt(2)/pi), 1 m at h + pi/2; pieces of 1e-5 rad (the
  // series branch of sinc) give the same mean as one piece.
  SuiteExperiment ex;
  ex.logged = true;
  SuiteRun run;
  const double quarter = 0.25 * M_PI * B;  // each wheel's travel for a quarter turn on the spot
  run.pieces = {{1.0, 1.0}, {-quarter, quarter}, {1.0, 1.0}};
  run.durations_s = {2.0, 1.0, 2.0};
  run.heading0_rad = h;
  run.heading0_given = true;
  ex.runs.push_back(run);
  const double spun = quarter, total = 2.0 + spun;
  const double expect_cos = (std::cos(h) + std::cos(h + M_PI / 2) + spun * 2 * M_SQRT2 / M_PI * std::cos(h + M_PI / 4)) / total;
  const double expect_sin = (std::sin(h) + std::sin(h + M_PI / 2) + spun * 2 * M_SQRT2 / M_PI * std::sin(h + M_PI / 4)) / total;
  const PathFeatures one = path_features(ex, ex.runs[0], B);
  EXPECT_NEAR(one.heading_cos, expect_cos, 1e-12);
  EXPECT_NEAR(one.heading_sin, expect_sin, 1e-12);
  const int steps = static_cast<int>(std::ceil(0.5 * M_PI / 1e-5));
  ex.runs[0].pieces = {{1.0, 1.0}};
  ex.runs[0].durations_s = {2.0};
  for (int i = 0; i < steps; ++i) {
    ex.runs[0].pieces.push_back({-quarter / steps, quarter / steps});
    ex.runs[0].durations_s.push_back(1.0 / steps);
  }
  ex.runs[0].pieces.push_back({1.0, 1.0});
  ex.runs[0].durations_s.push_back(2.0);
  const PathFeatures many = path_features(ex, ex.runs[0], B);
  EXPECT_NEAR(many.heading_cos, expect_cos, 1e-9);
  EXPECT_NEAR(many.heading_sin, expect_sin, 1e-9);
}

TEST(PathFeatures, LoggedRunsUseTheirTimeAndIgnoreJitter) {
  SuiteExperiment ex;
  ex.logged = true;
  SuiteRun run;
  // 1 m forwards at 0.5 m/s, 2 mm of jitter back (not a reversal), then 0.5 m back at 0.25 m/s.
  run.pieces = {{1.0, 1.0}, {-0.002, -0.002}, {0.002, 0.002}, {-0.5, -0.5}};
  run.durations_s = {2.0, 0.1, 0.1, 2.0};
  ex.runs.push_back(run);
  const PathFeatures f = path_features(ex, ex.runs[0], 0.4);
  EXPECT_NEAR(f.distance_m, 1.504, 1e-12);
  EXPECT_EQ(f.reversals, 2.0);  // one per wheel
  EXPECT_NEAR(f.speed_mps, (1.0 * 0.5 + 2 * 0.002 * 0.02 + 0.5 * 0.25) / 1.504, 1e-12);
  EXPECT_NEAR(f.travel_direction, 0.5 / 1.504, 1e-12);
  // 0 -> 0.5 -> -0.25 -> 0 m/s; the jitter (+-0.02 m/s) is below kAccelerationHysteresis_mps.
  EXPECT_NEAR(f.acceleration_mps, 0.5 + 0.75 + 0.25, 1e-12);
}

/// On labs where the model is right (configs/worlds/plain.yaml's standard set, 200 seeds), each
/// feature's mean and scatter tests reject at their nominal 5%: the count of raw p < 0.05 out of
/// 200 stays within the binomial(200, 0.05) interval of probability 1 - 1e-4/16 per test
/// (Bonferroni over the 16 testable tests), [1, 25]. Measured: 8 to 16.
TEST(ResidualFeatures, BothPartsHaveTheirSizeOnCorrectModels) {
  WorldFile w = load_world(kSource + "/configs/worlds/plain.yaml");
  constexpr int kLabs = 200;
  std::map<std::string, int> rejected, tested;
  for (int i = 0; i < kLabs; ++i) {
    w.seed = 1000 + static_cast<std::uint64_t>(i);
    const Suite s = seeded_lab(w);
    const SuiteModel model = suite_model(s);
    for (const ResidualAlignment& a : residual_alignment(s, model, residuals(s, model))) {
      if (!a.testable) continue;
      ++tested[a.feature + ", " + a.part];
      rejected[a.feature + ", " + a.part] += a.p_value_raw < 0.05 ? 1 : 0;
    }
  }
  EXPECT_EQ(tested.size(), 16u);  // 8 features x 2 parts (group: one experiment per group)
  const boost::math::binomial null(kLabs, 0.05);
  const double risk = 1e-4 / static_cast<double>(tested.size());
  const double lower = boost::math::quantile(null, risk / 2), upper = boost::math::quantile(boost::math::complement(null, risk / 2));
  for (const auto& [name, n] : tested) {
    EXPECT_EQ(n, kLabs) << name;
    EXPECT_GE(rejected[name], lower) << name;
    EXPECT_LE(rejected[name], upper) << name;
    std::cout << "  " << name << ": " << rejected[name] << " of " << n << " at 0.05\n";
  }
}

/// The run part (heading, run by run) keeps its size where the model is right and every run
/// starts at its own heading: on 200 labs of configs/worlds/plain.yaml's set with heading0 drawn
/// uniformly per run, its count of raw p < 0.05 stays within the binomial(200, 0.05) interval of
/// probability 1 - 1e-4, [0, 24] (measured: 8). Without per-run headings there is no run part (the test above
/// counts 16 tests).
TEST(ResidualFeatures, RunPartHasItsSizeOnCorrectModels) {
  WorldFile w = load_world(kSource + "/configs/worlds/plain.yaml");
  for (WorldExperiment& ex : w.experiments) ex.heading0 = {true, -3.14159, 3.14159};
  constexpr int kLabs = 200;
  int rejected = 0, tested = 0;
  for (int i = 0; i < kLabs; ++i) {
    w.seed = 3000 + static_cast<std::uint64_t>(i);
    const Suite s = seeded_lab(w);
    ASSERT_TRUE(runs_start_at_different_headings(s));
    const SuiteModel model = suite_model(s);
    for (const ResidualAlignment& a : residual_alignment(s, model, residuals(s, model))) {
      if (a.part != "run") continue;
      ASSERT_TRUE(a.testable);
      ++tested;
      rejected += a.p_value_raw < 0.05 ? 1 : 0;
    }
  }
  EXPECT_EQ(tested, kLabs);
  const boost::math::binomial null(kLabs, 0.05);
  const double lower = boost::math::quantile(null, 0.5e-4), upper = boost::math::quantile(boost::math::complement(null, 0.5e-4));
  std::cout << "  heading, run: " << rejected << " of " << kLabs << " at 0.05 (bounds " << lower << ", " << upper << ")\n";
  EXPECT_GE(rejected, lower);
  EXPECT_LE(rejected, upper);
}

/// The scatter tests with the dispersion from the model's simulated world (SimulatedDispersion,
/// 99 replicates) keep their size where the errors are far from Gaussian: on 100 labs of
/// tests/data/worlds/heavy_tails_lab.yaml (large bumps, a radius per run) against the true model,
/// each feature's count of raw p < 0.05 stays within the binomial(100, 0.05) interval of
/// probability 1 - 1e-4/8 per test (Bonferroni over the 8 testable scatter tests), [0, 17].
/// Measured: 2 to 11. The simulated dispersions of these experiments are 1.1 to 4.6 (lab 0); the
/// same labs with a Gaussian dispersion (phi = 1) rejected 9 to 25 of 100, three features above
/// the bound (a measurement of the development tree, not a test).
TEST(ResidualFeatures, SimulatedDispersionKeepsTheScatterTestsSizeOnHeavyTails) {
  const std::string file = kSource + "/tests/data/worlds/heavy_tails_lab.yaml";
  WorldFile w = load_world(file);
  constexpr int kLabs = 100;
  std::map<std::string, int> rejected, tested;
  for (int i = 0; i < kLabs; ++i) {
    w.seed = 2000 + static_cast<std::uint64_t>(i);
    const Suite s = seeded_lab(w);
    SuiteModel model = suite_model(s);
    model.effects = w.world.effects;
    const SimulatedDispersion simulated{7000 + static_cast<std::uint64_t>(i)};
    for (const ResidualAlignment& a : residual_alignment(s, model, residuals(s, model), &simulated)) {
      if (!a.testable || a.part != "scatter") continue;
      EXPECT_EQ(a.dof2, 0) << a.feature << ": not the simulated dispersion's chi^2 test";
      ++tested[a.feature];
      rejected[a.feature] += a.p_value_raw < 0.05 ? 1 : 0;
    }
  }
  EXPECT_EQ(tested.size(), 8u);  // 8 features (group: one experiment per group)
  const boost::math::binomial null(kLabs, 0.05);
  const double risk = 1e-4 / static_cast<double>(tested.size());
  const double upper = boost::math::quantile(boost::math::complement(null, risk / 2));
  for (const auto& [name, n] : tested) {
    EXPECT_EQ(n, kLabs) << name;
    EXPECT_LE(rejected[name], upper) << name;
    std::cout << "  " << name << ", scatter: " << rejected[name] << " of " << n << " at 0.05 (bound " << upper << ")\n";
  }
}

// Wheel noise that grows with speed (k 0.7e-3 at 0.15 m/s, 2e-3 at 0.6 m/s, against the nominal
// 1e-3): no mean misfit, a spread too small on the slow runs and too large on the fast ones. The
// misfit lines up with speed on the scatter first, significantly.
TEST(ResidualFeatures, SpeedDependentNoiseLinesUpWithSpeedOnTheScatter) {
  const Suite s = lab({kSource + "/tests/data/worlds/noise_slow.yaml",
                       kSource + "/tests/data/worlds/noise_fast.yaml"});
  const SuiteModel model = suite_model(s);
  const std::vector<ResidualAlignment> r = residual_alignment(s, model, residuals(s, model));
  for (const ResidualAlignment& a : r) {
    std::cout << "  " << a.feature << ", " << a.part << ": p = " << a.p_value << (a.testable ? "" : " (untestable)") << "\n";
  }
  ASSERT_GE(r.size(), 2u);
  EXPECT_EQ(r.front().feature, "speed");
  EXPECT_EQ(r.front().part, "scatter");
  EXPECT_LT(r.front().p_value, kDiagnoseAlpha);
}

bool says_explains(const std::string& text) { return text.find("explains") != std::string::npos; }

// A wheel scale of 1 + a (v - 0.375): 0.99 at 0.15 m/s, 1.01 at 0.6 m/s. No catalogue effect
// has it (scale_error sees the mean, 1), so the verdict must be "not explained" and the misfit
// must line up with speed first, significantly.
/// The features' tests on the plain model of a synthesised lab, printed, best first.
std::vector<ResidualAlignment> plain_alignment(const Suite& s) {
  const SuiteModel model = suite_model(s);
  std::vector<ResidualAlignment> r = residual_alignment(s, model, residuals(s, model));
  for (const ResidualAlignment& a : r) {
    std::cout << "  " << a.feature << ", " << a.part << ": p = " << a.p_value << (a.testable ? "" : " (untestable)") << "\n";
  }
  return r;
}

// A floor that slopes (tests/data/worlds/slope_lab.yaml: a sideways slip of -g cos(heading) per
// metre, 2 m lines in 8 directions): the misfit lines up with the heading on the mean first,
// significantly. Without the start headings the same lab cannot test the heading at all.
TEST(ResidualFeatures, ASlopingFloorLinesUpWithTheHeadingOnTheMean) {
  Suite s = lab({kSource + "/tests/data/worlds/slope_lab.yaml"});
  const std::vector<ResidualAlignment> r = plain_alignment(s);
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(r.front().feature, "heading");
  EXPECT_EQ(r.front().part, "mean");
  // Two columns, each modulating the base terms the lab tells apart: its lines, all of one length
  // and ending facing the way they started, give every base term (the offsets in both frames,
  // the factors, the sideways slip) as one offset, so 3 of the 9 (design_rank).
  EXPECT_EQ(r.front().dof1, 6);
  EXPECT_LT(r.front().p_value, kDiagnoseAlpha);
  for (SuiteExperiment& ex : s.experiments) ex.runs.back().heading0_given = false;
  const SuiteModel model = suite_model(s);
  for (const ResidualAlignment& a : residual_alignment(s, model, residuals(s, model))) {
    if (a.feature == "heading") EXPECT_FALSE(a.testable) << a.part;
  }
}

// A floor that pushes every run the same way, in a lab whose runs all start facing the same way
// (the standard set of configs/worlds/plain.yaml, nothing else hidden): each run's end moves by
// g (cos phi, sin phi) per metre of wheel travel in its start frame, written into the measured
// poses as the blind generator's floor_slope worlds do (scripts/diagnose_blind.py, tilt_floor), at
// the bottom of their range of g. No factor error and no offset in the end frame makes that (the
// arcs and spins end facing other ways), so the mean part's design carries an offset fixed in
// the start frame (V_e), and the drift's growth with the distance lines up with distance on the
// mean first, significantly. Without V_e the four floor_slope worlds of open batch 29012028 had
// no feature at p below 0.06.
TEST(ResidualFeatures, AFloorThatPushesAlignedRunsLinesUpWithTheDistanceOnTheMean) {
  Suite s = lab({kSource + "/configs/worlds/plain.yaml"});
  const double g = 0.002, phi = -1.9;
  for (SuiteExperiment& ex : s.experiments) {
    for (SuiteRun& run : ex.runs) {
      const double d = path_features(ex, run, s.robot.wheelbase_m).distance_m;
      run.measured.x() += g * d * std::cos(phi);
      run.measured.y() += g * d * std::sin(phi);
    }
  }
  const std::vector<ResidualAlignment> r = plain_alignment(s);
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(r.front().feature, "distance");
  EXPECT_EQ(r.front().part, "mean");
  EXPECT_LT(r.front().p_value, kDiagnoseAlpha);
}

// A sideways slip of a v per metre (tests/data/worlds/lateral_speed_two_speeds.yaml, every path
// at 0.15 and 0.6 m/s): no factor error makes a sideways slip, so the mean part's design carries
// a sideways slip direction (S's fourth column) and the slip's change with the speed lines up
// with speed on the mean first, significantly. Without that direction (main at 36e6912) the
// blind generator's four lateral_speed worlds of seed 15012028 had speed at p = 0.31 to 1.
TEST(ResidualFeatures, ASidewaysSlipThatGrowsWithSpeedLinesUpWithSpeedOnTheMean) {
  const Suite s = lab({kSource + "/tests/data/worlds/lateral_speed_two_speeds.yaml"});
  const std::vector<ResidualAlignment> r = plain_alignment(s);
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(r.front().feature, "speed");
  EXPECT_EQ(r.front().part, "mean");
  EXPECT_EQ(r.front().dof1, 7);  // one column modulating the 7 terms a feature varies, all told apart
  EXPECT_LT(r.front().p_value, kDiagnoseAlpha);
}

// Done-when of issue 21: white wheel noise that grows with the square of the speed
// (tests/data/worlds/speed_noise_lab.yaml, `noise: "1 + c * v^2"`, c = 10). Under the plain model
// `speed` on the scatter is among the two features the misfit lines up with best, significantly;
// the noise expression fitted from a wrong start (c = 2) lands within 3 standard errors of the
// truth (a two-sided alpha of 0.0027), and compare finds the fitted model consistent at
// kDiagnoseAlpha while the plain one is not.
TEST(ResidualFeatures, SpeedNoiseLinesUpWithSpeedOnTheScatterAndANoiseExpressionFitsIt) {
  const std::string file = kSource + "/tests/data/worlds/speed_noise_lab.yaml";
  const Suite s = lab({file});
  const std::vector<ResidualAlignment> r = plain_alignment(s);
  const auto speed_scatter = [](const ResidualAlignment& a) { return a.feature == "speed" && a.part == "scatter"; };
  const auto top = std::find_if(r.begin(), r.end(), speed_scatter);
  ASSERT_NE(top, r.end());
  EXPECT_LT(top - r.begin(), 2) << "speed, scatter is not among the top two";
  EXPECT_LT(top->p_value, kDiagnoseAlpha);
  SuiteModel model = suite_model(s);
  EXPECT_FALSE(compare(s, model, kDiagnoseAlpha).verdict.consistent());
  constexpr double kTrue = 10.0, kStart = 2.0;
  model.effects = load_world(file).world.effects;
  model.effects.front().values.front() = kStart;
  const FitResult f = fit(s, model, {"speed_noise.c"});
  const double c = f.values(0), se = f.stderrs(0);
  std::cout << "  speed_noise.c = " << c << " +/- " << se << " (true " << kTrue << ", start " << kStart << ")\n";
  ASSERT_TRUE(std::isfinite(se));
  EXPECT_LT(std::abs(c - kTrue), 3.0 * se);
  const Comparison after = compare(s, f.model, kDiagnoseAlpha);
  std::cout << "  fitted model: " << after.verdict.name() << ", calibration "
            << calibration_name(after.calibration.method) << ", p = " << after.calibration.p_value << "\n";
  EXPECT_TRUE(after.verdict.consistent());
}

// The scatter shape rule (diagnose's rule 5, docs/calibrate.md): in the same lab, a wheel noise
// level (a constant factor on the noise) changes the spread's size, not how it grows with the
// speed, so with it the scatter still lines up with speed and it is not adopted; diagnose stops
// it by that rule and names the feature. No constant-shape noise may leave the model explained.
TEST(Verdict, ConstantNoiseLevelIsNotAdoptedForNoiseThatGrowsWithSpeed) {
  const Suite s = lab({kSource + "/tests/data/worlds/speed_noise_lab.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s));
  const auto level = std::find_if(d.candidates.begin(), d.candidates.end(),
                                  [](const Candidate& c) { return c.effect == kWheelNoiseLevel; });
  ASSERT_NE(level, d.candidates.end());
  std::cout << "  " << level->effect << ": " << level->verdict << " (" << level->rule << ") " << level->decision << "\n";
  EXPECT_EQ(level->verdict, "stopped");
  EXPECT_EQ(level->rule, "scatter shape");
  EXPECT_NE(level->decision.find("lines up with speed"), std::string::npos) << level->decision;
  if (d.best) std::cout << "  adopted: " << d.candidates[*d.best].effect << "\n";
  EXPECT_FALSE(d.explained);
  // The noise correlation gains in-sample and in all held out, but predicts one kind of path
  // worse by more than kMaxFoldLoss and significantly (fold_loss_bound): a compromise between
  // kinds, a mimic.
  const auto correlation = std::find_if(d.candidates.begin(), d.candidates.end(),
                                        [](const Candidate& c) { return c.effect == "wheel_noise_correlation"; });
  ASSERT_NE(correlation, d.candidates.end());
  EXPECT_TRUE(correlation->significant);
  EXPECT_EQ(correlation->verdict, "mimic");
  EXPECT_EQ(correlation->rule, "held-out likelihood");
  const auto tested = static_cast<std::size_t>(
      std::count_if(correlation->held_out_by_fold.begin(), correlation->held_out_by_fold.end(),
                    [](const Candidate::FoldGain& g) { return g.counted; }));
  EXPECT_TRUE(std::any_of(correlation->held_out_by_fold.begin(), correlation->held_out_by_fold.end(),
                          [&](const Candidate::FoldGain& g) {
                            return g.counted && g.gain < -fold_loss_bound(g, correlation->mean_dispersion, tested);
                          }));
  EXPECT_NE(correlation->decision.find("is a mimic"), std::string::npos) << correlation->decision;
}

TEST(Verdict, WheelbaseImitatingASpeedScaleIsStoppedByTheScatterItLeaves) {
  // Every kind of path at both speeds: a turn-dependent wheelbase imitates a sliver of the
  // scale's misfit on each kind's turns at the suite's mix of speeds, significantly by the
  // likelihood ratio and on every held-out kind, but the experiments' mean errors still scatter
  // two hundred times what the model predicts, and against that scatter its gain is nothing.
  const Suite s = lab({kSource + "/tests/data/worlds/speed_scale_two_speeds.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s));
  const auto wheelbase = std::find_if(d.candidates.begin(), d.candidates.end(),
                                      [](const Candidate& c) { return c.effect == "turn_dependent_wheelbase"; });
  ASSERT_NE(wheelbase, d.candidates.end());
  std::cout << "  " << wheelbase->effect << ": " << wheelbase->verdict << " (" << wheelbase->rule << ") "
            << wheelbase->decision << "\n";
  EXPECT_TRUE(wheelbase->significant);
  EXPECT_LT(wheelbase->mean_p_value, d.alpha / static_cast<double>(d.candidates.size()));
  EXPECT_GT(wheelbase->mean_dispersion, 10.0);
  EXPECT_GE(wheelbase->mean_p_value_dispersed, d.alpha);
  EXPECT_EQ(wheelbase->verdict, "stopped");
  EXPECT_EQ(wheelbase->rule, "overdispersed mean");
  EXPECT_FALSE(d.best.has_value());
  EXPECT_FALSE(d.explained);
  ASSERT_FALSE(d.residuals.empty());
  EXPECT_EQ(d.residuals.front().feature, "speed");
}

// The overdispersed-mean rule with each experiment's covariance scaled by the scatter of its own
// runs (docs/calibrate.md). In a lab whose wheel noise grows with the speed
// (tests/data/worlds/speed_noise_second_order.yaml, a blind world the rule failed on), the fast
// runs' larger heading noise shortens their mean travel, and a scale error imitates that on the
// fast long line: significant by the likelihood ratio under the model's too small covariances,
// not against the scatter the fast runs show. So it is stopped by that rule, nothing is adopted,
// and speed on the scatter is the misfit's first feature. With a true scale error beside the
// same noise (speed_noise_with_scale.yaml), the rule lets it through and it is adopted. (Only
// scale_error is offered: the full catalogue's verdicts on this world are the blind batch's.)
// Whether a lab draws the case depends on its realisation; measured over seeds 1-30 with the
// random stream of 2026-12: scale_error is significant by the likelihood ratio in 6 of the 30
// noise-only labs and the rule stops it in 5 (dispersed p 0.02-0.20; seed 9, p = 0.0013, is
// adopted: a mimic in 1 lab of 30), and speed on the scatter comes first in all 30; with the
// true scale error the rule never stops it (dispersed p <= 1.1e-4 in all 30) and it is adopted
// in all 30 (25 before the held-out rule judged a fold's loss against the spread of its runs'
// gains: in the other 5 one kind of path held out lost more than kMaxFoldLoss, and it was called
// a mimic; measured again by odomcov synth and diagnose --effects scale_error, which give the
// noise-only lab the same outcome with and without that change). The test takes seed 2 and seed
// 1, the first of each case.
TEST(Verdict, ASecondOrderMeanOfSpeedNoiseIsNotAScaleError) {
  WorldFile noise = load_world(kSource + "/tests/data/worlds/speed_noise_second_order.yaml");
  noise.seed = 2;
  const Suite s = seeded_lab(noise);
  const Diagnosis d = diagnose(s, suite_model(s), kDiagnoseAlpha, {"scale_error"});
  const auto scale = std::find_if(d.candidates.begin(), d.candidates.end(),
                                  [](const Candidate& c) { return c.effect == "scale_error"; });
  ASSERT_NE(scale, d.candidates.end());
  std::cout << "  " << scale->effect << ": " << scale->verdict << " (" << scale->rule << ") " << scale->decision << "\n";
  if (d.best) std::cout << "  adopted: " << d.candidates[*d.best].effect << "\n";
  EXPECT_LT(scale->mean_p_value, d.alpha);
  EXPECT_GE(scale->mean_p_value_dispersed, d.alpha);
  EXPECT_EQ(scale->rule, "overdispersed mean");
  EXPECT_NE(scale->decision.find("each experiment's runs scatter up to"), std::string::npos) << scale->decision;
  EXPECT_FALSE(d.best.has_value());
  EXPECT_FALSE(d.explained);
  ASSERT_FALSE(d.residuals.empty());
  EXPECT_EQ(d.residuals.front().feature, "speed");
  EXPECT_EQ(d.residuals.front().part, "scatter");

  WorldFile with_true_scale = load_world(kSource + "/tests/data/worlds/speed_noise_with_scale.yaml");
  with_true_scale.seed = 1;
  const Suite real = seeded_lab(with_true_scale);
  const Diagnosis with_scale = diagnose(real, suite_model(real), kDiagnoseAlpha, {"scale_error"});
  ASSERT_TRUE(with_scale.best.has_value());
  const Candidate& adopted = with_scale.candidates[*with_scale.best];
  std::cout << "  with a true scale error: adopted " << adopted.effect << ", dispersed p = "
            << adopted.mean_p_value_dispersed << "\n";
  EXPECT_EQ(adopted.effect, "scale_error");
  EXPECT_LT(adopted.mean_p_value_dispersed, with_scale.alpha);
}

// The held-out rule on the quasi-likelihood's scale (docs/calibrate.md, "Selection by
// prediction"). In a lab with backlash and unequal wheel diameters, recorded over days with 7
// runs per experiment (tests/data/worlds/backlash_beside_diameter_ratio.yaml, a blind world the
// rule failed on), the diameter ratio predicts the held-out lines, arcs and squares far better
// but the spins, where the backlash it does not model dominates, a little worse: 6.1 units of
// log-likelihood, more than kMaxFoldLoss, but less than kMaxFoldLoss times the dispersion of
// the experiments' means that its model leaves. It is adopted, not called a mimic.
TEST(Verdict, AFoldLossIsJudgedAgainstTheDispersionTheModelLeaves) {
  const Suite s = lab({kSource + "/tests/data/worlds/backlash_beside_diameter_ratio.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s), kDiagnoseAlpha, {"wheel_diameter_ratio"});
  ASSERT_TRUE(d.best.has_value());
  const Candidate& ratio = d.candidates[*d.best];
  std::cout << "  " << ratio.effect << ": " << ratio.verdict << ", dispersion " << ratio.mean_dispersion << "; "
            << ratio.decision << "\n";
  EXPECT_EQ(ratio.effect, "wheel_diameter_ratio");
  const auto spin = std::find_if(ratio.held_out_by_fold.begin(), ratio.held_out_by_fold.end(),
                                 [](const Candidate::FoldGain& g) { return g.fold == "spin"; });
  ASSERT_NE(spin, ratio.held_out_by_fold.end());
  EXPECT_TRUE(spin->counted);
  EXPECT_LT(spin->gain, -kMaxFoldLoss);  // a mimic by the unscaled rule
  EXPECT_GE(spin->gain, -kMaxFoldLoss * ratio.mean_dispersion);
}

// The held-out rule against the sampling spread of a fold's gain (docs/calibrate.md, "Selection
// by prediction"). In a lab whose wheel diameter ratio varies between days
// (tests/data/worlds/group_ed_spread_spin_loss.yaml, a blind world the rule failed on), the true
// spread between the days predicts the held-out lines, arcs and squares far better but the spins
// a little worse, by more than kMaxFoldLoss: as much as it loses on them in-sample, and within
// the scatter of the spins' runs' gains. That is noise, not a worse prediction: it is adopted,
// not called a mimic (which left a fixed diameter ratio named in its place).
TEST(Verdict, AFoldLossWithinTheSpreadOfItsRunsGainsIsNoise) {
  const Suite s = lab({kSource + "/tests/data/worlds/group_ed_spread_spin_loss.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s));
  ASSERT_TRUE(d.best.has_value());
  const Candidate& spread = d.candidates[*d.best];
  std::cout << "  " << spread.effect << ": " << spread.verdict << "; " << spread.decision << "\n";
  EXPECT_EQ(spread.effect, "group_variation(wheel_diameter_ratio.Ed)");
  const auto spin = std::find_if(spread.held_out_by_fold.begin(), spread.held_out_by_fold.end(),
                                 [](const Candidate::FoldGain& g) { return g.fold == "spin"; });
  ASSERT_NE(spin, spread.held_out_by_fold.end());
  std::cout << "  spins held out: " << spin->gain << ", spread " << spin->spread << " over " << spin->parts
            << " runs\n";
  EXPECT_TRUE(spin->counted);
  EXPECT_LT(spin->gain, -kMaxFoldLoss);  // a mimic by the rule without the spread
  EXPECT_GT(spin->gain, -2.0 * spin->spread);
  EXPECT_EQ(spin->parts, 83U);  // the runs of its seven days' 14 spins
}

// In this lab every run starts from rest and stops once at one speed, so its acceleration feature
// (the swings of its wheel speeds) is close to twice its speed: the two columns are nearly
// proportional, their tests agree to the second digit (1.51e-27 and 1.53e-27), and either may
// come first. Both must lead, significantly.
TEST(Verdict, SpeedDependentScaleIsNotExplainedAndPointsAtSpeed) {
  const Suite s = lab({kSource + "/tests/data/worlds/speed_slow.yaml",
                       kSource + "/tests/data/worlds/speed_fast.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s));
  EXPECT_FALSE(d.explained);
  ASSERT_GE(d.residuals.size(), 2u);
  const std::set<std::string> top = {d.residuals[0].feature, d.residuals[1].feature};
  EXPECT_EQ(top, (std::set<std::string>{"speed", "acceleration"}));
  EXPECT_EQ(d.residuals[0].part, "mean");
  EXPECT_EQ(d.residuals[1].part, "mean");
  EXPECT_LT(d.residuals[1].p_value, d.alpha);
  for (const ResidualAlignment& a : d.residuals) {
    std::cout << "  " << a.feature << ": p = " << a.p_value << (a.testable ? "" : " (untestable)") << "\n";
    if (a.feature == "group") EXPECT_FALSE(a.testable);  // one experiment per group
  }
  const std::string words = verdict_text(d);
  EXPECT_FALSE(says_explains(words)) << words;
  EXPECT_NE(words.find("still inconsistent"), std::string::npos) << words;
  EXPECT_NE(words.find("speed, mean (p = "), std::string::npos) << words;
}

TEST(Verdict, PlainLabIsExplained) {
  const Suite s = lab({kSource + "/configs/worlds/plain.yaml"});
  const Diagnosis d = diagnose(s, suite_model(s));
  EXPECT_FALSE(d.best.has_value());
  EXPECT_TRUE(d.explained);
  EXPECT_TRUE(d.residuals.empty());
  EXPECT_TRUE(says_explains(verdict_text(d)));
}

// The words follow the flag, whatever produced it.
TEST(Verdict, WordsNeverSayExplainedWhenNot) {
  Diagnosis d;
  d.after.nees_mean = 23.5;
  for (bool best : {false, true}) {
    d.best = best ? std::optional<std::size_t>(0) : std::nullopt;
    d.explained = false;
    d.residuals.clear();
    EXPECT_FALSE(says_explains(verdict_text(d))) << verdict_text(d);
    ResidualAlignment a;
    a.feature = "angle_turned";
    a.testable = true;
    a.p_value = 1e-6;
    a.description = "x";
    d.residuals = {a};
    EXPECT_FALSE(says_explains(verdict_text(d))) << verdict_text(d);
    d.explained = true;
    EXPECT_TRUE(says_explains(verdict_text(d)));
  }
}

/// The lab's runs moved to where the model's systematic effects take the robot (no noise), on
/// the encoders' sample arcs (what the simulator drives, and what the correction re-integrates).
Suite noise_free(Suite s, const SuiteModel& model) {
  for (SuiteExperiment& ex : s.experiments) {
    std::vector<double> durations;
    for (const SampleRun& r : sample_schedule(ex.path)) durations.push_back(static_cast<double>(r.count) * r.duration_s);
    const Vector3 truth = predict(sample_arcs(ex.path), durations, s.robot, model.effects).true_end_pose;
    for (SuiteRun& r : ex.runs) r.measured = truth;
  }
  return s;
}

// Runs that land exactly where the perturbed robot goes (no noise): the corrected odometry must
// reproduce them to rounding, and the nominal odometry must not.
TEST(OdometryCorrection, NoiseFreeRunsAreReproducedByTheCorrectedOdometry) {
  const Suite plain = lab({kSource + "/configs/worlds/standard.yaml"});
  SuiteModel model = suite_model(plain);
  EXPECT_FALSE(odometry_correction(plain, model).has_value());
  model.effects = {{"reference_offset", {0.01, 0.0}}};  // moves the reference, not the odometry
  EXPECT_FALSE(odometry_correction(plain, model).has_value());
  model.effects = {{"wheel_diameter_ratio", {1.003}}, {"wheelbase_error", {1.01}}, {"scale_error", {0.998}}};
  const Suite s = noise_free(plain, model);
  const auto c = odometry_correction(s, model);
  ASSERT_TRUE(c.has_value());
  // Constant factors: every kind gets the same values, [Chong97] eq. 11 times Es. They are
  // ratios of sums over ~1e4 pieces, so equal to the closed form to ~1e4 roundings.
  EXPECT_FALSE(c->motion_dependent);
  EXPECT_NEAR(c->parameters.wheelbase_m, 1.01 * 0.4, 1e-12);
  EXPECT_NEAR(c->parameters.scale_left, 0.998 * 2 / 2.003, 1e-12);
  EXPECT_NEAR(c->parameters.scale_right, 0.998 * 2 * 1.003 / 2.003, 1e-12);
  for (const CorrectionByKind& k : c->by_kind) {
    EXPECT_LT(k.mean_xy_after_m, 1e-9) << k.kind;
    EXPECT_LT(k.emax_after_m, 1e-9) << k.kind;
    // Forward-back returns to the start under any scale (no before error); spins barely move.
    if (k.kind != "spin" && k.kind != "forward") EXPECT_GT(k.emax_before_m, 1e-2) << k.kind;
  }
}

// A correction that depends on the motion (turn_dependent_wheelbase): the re-integration applies
// it piece by piece, so noise-free runs are reproduced on every kind of path, and each kind
// reports the wheelbase its own turns see: B Eb_spin on the spins (spin fraction 1), B Eb_arc on
// the lines (spin fraction 0, where nothing turns and the plain mean applies), in between on
// the arcs.
TEST(OdometryCorrection, AMotionDependentWheelbaseIsReportedPerKindOfPath) {
  const Suite plain = lab({kSource + "/configs/worlds/standard.yaml"});
  SuiteModel model = suite_model(plain);
  const double B = plain.robot.wheelbase_m, arc = 1.005, spin = 1.02;
  model.effects = {{"turn_dependent_wheelbase", {arc, spin}}, {"scale_error", {0.998}}};
  const Suite s = noise_free(plain, model);
  const auto c = odometry_correction(s, model);
  ASSERT_TRUE(c.has_value());
  EXPECT_TRUE(c->motion_dependent);
  for (const CorrectionByKind& k : c->by_kind) {
    EXPECT_LT(k.mean_xy_after_m, 1e-9) << k.kind;
    EXPECT_NEAR(k.parameters.scale_left, 0.998, 1e-12) << k.kind;
    EXPECT_NEAR(k.parameters.scale_right, 0.998, 1e-12) << k.kind;
    if (k.kind == "spin") EXPECT_NEAR(k.parameters.wheelbase_m, spin * B, 1e-12);
    if (k.kind == "line") EXPECT_NEAR(k.parameters.wheelbase_m, arc * B, 1e-12);
    if (k.kind == "arc") {
      EXPECT_GT(k.parameters.wheelbase_m, arc * B);
      EXPECT_LT(k.parameters.wheelbase_m, spin * B);
    }
  }
  // A single wheelbase (the all-runs value, which the spins dominate) misses the arcs.
  SuiteModel constant = model;
  constant.effects = {{"wheelbase_error", {c->parameters.wheelbase_m / B}}, {"scale_error", {0.998}}};
  const auto single = odometry_correction(s, constant);
  ASSERT_TRUE(single.has_value());
  for (const CorrectionByKind& k : single->by_kind) {
    if (k.kind == "arc") EXPECT_GT(k.mean_xy_after_m, 1e-3) << k.kind;
  }
}

}  // namespace
}  // namespace odomcov
