// group_variation and grouped runs: the suite's `group:` key, the world side (one draw per
// group, thread-count invariant), the grouped likelihood against a dense evaluation, "consistent
// with, rejected without" on a synthesised lab, the fit of the between-group spread, and a
// held-out group predicted with that spread.
#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include <tbb/task_arena.h>

#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/io/world.hpp"
#include "odomcov/io/suite_io.hpp"

namespace odomcov {
namespace {

constexpr double kAlpha = 1e-3;
const std::string kWorld = ODOMCOV_SOURCE_DIR "/configs/effects/group_variation.yaml";

/// Synthesises the world's experiments whose names start with one of `prefixes` (all when
/// empty) into a suite and loads it back.
Suite synth_suite(const WorldFile& w, const std::string& name,
                  const std::vector<std::string>& prefixes = {}) {
  const auto dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::create_directories(dir);
  WorldFile kept = w;
  kept.experiments.clear();
  SuiteDocument doc = world_suite(w);
  doc.experiments.clear();
  const SuiteDocument all = world_suite(w);
  for (std::size_t i = 0; i < w.experiments.size(); ++i) {
    bool keep = prefixes.empty();
    for (const std::string& p : prefixes) keep = keep || w.experiments[i].name.rfind(p, 0) == 0;
    if (!keep) continue;
    std::ofstream(dir / (w.experiments[i].name + ".csv")) << measurements_csv(synthesize(w, i));
    doc.experiments.push_back(all.experiments[i]);
  }
  std::ofstream(dir / "suite.yaml") << suite_yaml(doc);
  return load_suite((dir / "suite.yaml").string());
}

SuiteModel world_model(const WorldFile& w, const EffectList& effects) {
  SuiteModel m;
  m.robot = {w.robot.wheelbase_m, w.world.noise};
  m.effects = effects;
  m.measurement_noise = w.measurement_noise;
  return m;
}

EffectList without_group_variation(const EffectList& list) {
  EffectList out;
  for (const EffectSpec& e : list) {
    if (e.name != kGroupVariation) out.push_back(e);
  }
  return out;
}

/// The joint Gaussian log-density of every run, built densely: one (3n x 3n) covariance with
/// blockdiag(cov_i) + u_i u_j^T + u2_i u2_j^T for runs i, j of one group, factorised by Eigen's
/// LLT.
double dense_log_likelihood(const std::vector<std::vector<RunResidual>>& res) {
  std::vector<RunResidual> runs;
  for (const auto& ex : res) runs.insert(runs.end(), ex.begin(), ex.end());
  const auto n = static_cast<Eigen::Index>(3 * runs.size());
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd r(n);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const auto a = static_cast<Eigen::Index>(3 * i);
    r.segment<3>(a) = runs[i].error - runs[i].mean;
    S.block<3, 3>(a, a) += runs[i].cov;
    for (std::size_t j = 0; j < runs.size(); ++j) {
      if (runs[i].group != runs[j].group) continue;
      S.block<3, 3>(a, static_cast<Eigen::Index>(3 * j)) +=
          runs[i].group_column * runs[j].group_column.transpose() +
          runs[i].group_column2 * runs[j].group_column2.transpose();
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(S);
  const Eigen::MatrixXd L = llt.matrixL();
  const double log_det = 2.0 * L.diagonal().array().log().sum();
  return -0.5 * (r.dot(llt.solve(r)) + log_det + static_cast<double>(n) * std::log(2.0 * M_PI));
}

TEST(GroupLikelihood, MatchesTheDenseEvaluation) {
  // Random residuals: 3 experiments, groups shared across experiments, random SPD covariances
  // and group columns of the size of the covariances' square roots (a strong correlation); in
  // the odd trials also second group columns (rank two).
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<std::vector<RunResidual>> res(3);
    for (std::size_t e = 0; e < res.size(); ++e) {
      for (int i = 0; i < 4 + trial % 3; ++i) {
        RunResidual r;
        Eigen::Matrix3d A;
        for (int k = 0; k < 9; ++k) A(k / 3, k % 3) = 0.01 * u(rng);
        r.cov = A * A.transpose() + 1e-5 * Matrix3::Identity();
        r.mean = Vector3(u(rng), u(rng), u(rng)) * 0.01;
        r.error = r.mean + Vector3(u(rng), u(rng), u(rng)) * 0.02;
        r.group_column = Vector3(u(rng), u(rng), u(rng)) * 0.01;
        if (trial % 2 == 1) r.group_column2 = Vector3(u(rng), u(rng), u(rng)) * 0.01;
        r.group = static_cast<int>((e + static_cast<std::size_t>(i)) % 2);  // 2 groups across experiments
        res[e].push_back(r);
      }
    }
    const double dense = dense_log_likelihood(res);
    const double fast = log_likelihood(res);
    EXPECT_LT(std::abs(fast - dense), 1e-9 * std::abs(dense)) << "trial " << trial;
    // Without group columns the runs are independent: the plain sum.
    auto plain = res;
    double sum = 0.0;
    for (auto& ex : plain) {
      for (RunResidual& r : ex) {
        r.group_column.setZero();
        r.group_column2.setZero();
        sum += gaussian_log_density(r.error, r.mean, r.cov);
      }
    }
    EXPECT_EQ(log_likelihood(plain), sum);
  }
}

TEST(GroupWorld, OneDrawPerGroupWhateverTheThreads) {
  const WorldFile w = load_world(kWorld);
  // The draw depends on (seed, group) only.
  const EffectList a = group_effects(w.world.effects, w.seed, "group:day-1");
  ASSERT_EQ(a.size(), 1u);  // group_variation itself is gone
  EXPECT_EQ(a, group_effects(w.world.effects, w.seed, "group:day-1"));
  EXPECT_NE(a, group_effects(w.world.effects, w.seed, "group:day-2"));
  EXPECT_NE(a, group_effects(w.world.effects, w.seed + 1, "group:day-1"));
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(synthesize(w, i, 1), synthesize(w, i, 3));
  std::printf("the world's sessions draw Eb =");
  for (int day = 1; day <= 6; ++day) {
    std::printf(" %.5f", group_effects(w.world.effects, w.seed, "group:day-" + std::to_string(day))[0].values[0]);
  }
  std::printf("\n");
  // The draws are N(value, sd^2): over 4000 groups the sample mean lies within 4.42 standard
  // errors (two-sided alpha = 1e-5) and (n-1) s^2/sd^2 within its chi^2 quantiles at alpha 1e-5.
  const int n = 4000;
  double sum = 0.0, sum2 = 0.0;
  for (int g = 0; g < n; ++g) {
    const double v = group_effects(w.world.effects, w.seed, "g" + std::to_string(g))[0].values[0];
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n, var = (sum2 - n * mean * mean) / (n - 1), sd = 0.004;
  EXPECT_LT(std::abs(mean - 1.01), 4.42 * sd / std::sqrt(n));
  const boost::math::chi_squared chi2(n - 1);
  const double stat = (n - 1) * var / (sd * sd);
  EXPECT_GT(stat, boost::math::quantile(chi2, 0.5e-5));
  EXPECT_LT(stat, boost::math::quantile(boost::math::complement(chi2, 0.5e-5)));
}

TEST(GroupWorld, ConsistentWithTheEffectRejectedWithout) {
  const WorldFile w = load_world(kWorld);
  const Suite suite = synth_suite(w, "odomcov_group_all");
  ASSERT_EQ(suite.experiments[0].group, "day-1");
  const Comparison with = compare(suite, world_model(w, w.world.effects), kAlpha);
  const Comparison without = compare(suite, world_model(w, without_group_variation(w.world.effects)), kAlpha);
  std::printf("with group_variation: log L %.2f, %s; without: log L %.2f, %s\n",
              with.log_likelihood, with.verdict.name(), without.log_likelihood,
              without.verdict.name());
  EXPECT_STREQ(with.verdict.name(), "consistent");
  EXPECT_STREQ(without.verdict.name(), "inconsistent");
  EXPECT_GT(with.log_likelihood, without.log_likelihood);
}

TEST(GroupWorld, FitFindsTheSpreadAndAHeldOutGroupIsPredictedWithIt) {
  const WorldFile w = load_world(kWorld);
  // Fit on four sessions, starting from the nominal Eb and sd at half the truth.
  const Suite train = synth_suite(w, "odomcov_group_train", {"day1", "day2", "day3", "day4"});
  const Suite held_out = synth_suite(w, "odomcov_group_held_out", {"day5", "day6"});
  const SuiteModel start = world_model(
      w, {{"wheelbase_error", {1.0}}, {kGroupVariation, {0.002}, "wheelbase_error.Eb"}});
  const FitResult f = fit(train, start, {"wheelbase_error.Eb", "group_variation.sd"});
  std::printf("fit on 4 sessions: Eb %.5f +/- %.5f, sd %.5f +/- %.5f\n", f.values(0),
              f.stderrs(0), f.values(1), f.stderrs(1));
  // Eb: the truth within 3.29 standard errors (two-sided alpha = 1e-3). sd, a variance
  // component seen through four groups, is far from quadratic in the likelihood, so its
  // check is the likelihood-ratio one: the profile likelihood at the true sd (Eb refitted)
  // within chi^2_1(1 - alpha)/2 = 10.83/2 of the maximum.
  ASSERT_TRUE(std::isfinite(f.stderrs(0)) && std::isfinite(f.stderrs(1)));
  EXPECT_LT(std::abs(f.values(0) - 1.01), 3.29 * f.stderrs(0));
  SuiteModel at_truth = start;
  at_truth.effects[1].values[0] = 0.004;
  const FitResult profile = fit(train, at_truth, {"wheelbase_error.Eb"});
  const double lr = 2.0 * (f.log_likelihood_after - profile.log_likelihood_after);
  std::printf("likelihood ratio at the true sd: %.3g\n", lr);
  EXPECT_GE(lr, -1e-6);
  EXPECT_LT(lr, 10.83);

  // The held-out sessions: no run of theirs was in the fit. With the between-group spread each
  // run's covariance includes it and compare (whitening the groups jointly) finds the
  // prediction consistent; the same fitted model without the spread is rejected.
  const Comparison with = compare(held_out, f.model, kAlpha);
  SuiteModel no_spread = f.model;
  no_spread.effects = without_group_variation(no_spread.effects);
  const Comparison without = compare(held_out, no_spread, kAlpha);
  // The joint NEES of the held-out runs: whitened jointly they are independent N(0, I), so the
  // sum of their NEES is chi^2 with 3 n degrees of freedom.
  auto joint_p = [&](const SuiteModel& m) {
    double nees = 0.0;
    int dof = 0;
    for (const auto& ex : condition_on_groups(residuals(held_out, m))) {
      for (const RunResidual& r : ex) {
        const Eigen::LLT<Matrix3> llt(r.cov);
        nees += (r.error - r.mean).dot(llt.solve(r.error - r.mean));
        dof += 3;
      }
    }
    std::printf("held out: NEES per run %.3g (dof %d)\n", 3.0 * nees / dof, dof);
    return chi2_sf(nees, dof);
  };
  EXPECT_GT(joint_p(f.model), kAlpha);
  EXPECT_LT(joint_p(no_spread), kAlpha);
  EXPECT_STREQ(with.verdict.name(), "consistent");
  EXPECT_STREQ(without.verdict.name(), "inconsistent");
  // Each held-out run on its own: its covariance includes the spread (marginal).
  const auto res = residuals(held_out, f.model);
  const auto own = marginal(res);
  const Vector3 u = res[0][0].group_column, u2 = res[0][0].group_column2;
  EXPECT_GT(u.norm(), 0.0);
  EXPECT_LT((own[0][0].cov - res[0][0].cov - u * u.transpose() - u2 * u2.transpose()).norm(), 1e-15);
}

TEST(GroupLikelihood, TheGroupTermsAreTheDrawsMoments) {
  // Each run's group terms against the moments of its systematic mean f(Eb + sd z) over the draw
  // z ~ N(0, 1), by the trapezoid rule on z in [-8, 8] (step 0.05; spectrally accurate for this
  // smooth, Gaussian-weighted integrand): the mean's shift E[f] - f(Eb), the column E[f z] and
  // the second column E[f (z^2 - 1)] / sqrt(2). sd = 0.02 (five times the world's) makes the
  // curvature visible. Three points (Eb, Eb +- sqrt(3) sd) give the shift and the column to
  // O(sd^6 f^(6)) and O(sd^5 f^(5)), the second column to O(sd^4 f^(4)): relative errors of order
  // (sd / Eb)^2 = 4e-4 times the derivatives' growth, bounded here by 1e-3 and 2e-2.
  const WorldFile w = load_world(kWorld);
  const Suite suite = synth_suite(w, "odomcov_group_moments", {"day1"});
  const double eb = 1.01, sd = 0.02;
  SuiteModel model = world_model(w, {{"wheelbase_error", {eb}}, {kGroupVariation, {sd}, "wheelbase_error.Eb"}});
  SuiteModel flat = model;
  flat.effects[1].values[0] = 0.0;
  const auto res = residuals(suite, model), res0 = residuals(suite, flat);
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    std::vector<double> durations;
    const std::vector<ArcSegment> pieces = model_pieces(suite.experiments[e].path, w.robot.wheelbase_m, &durations);
    auto f = [&](double value) {
      return predict(pieces, durations, model.robot, {{"wheelbase_error", {value}}}).mean;
    };
    const Vector3 f0 = f(eb);
    Vector3 shift = Vector3::Zero(), column = Vector3::Zero(), column2 = Vector3::Zero();
    const double step = 0.05;
    for (int k = -160; k <= 160; ++k) {
      const double z = k * step, weight = step * std::exp(-0.5 * z * z) / std::sqrt(2.0 * M_PI);
      const Vector3 fz = f(eb + sd * z) - f0;
      shift += weight * fz;
      column += weight * z * fz;
      column2 += weight * (z * z - 1.0) / std::sqrt(2.0) * fz;
    }
    const RunResidual& r = res[e][0];
    std::printf("%s: shift %.3g, column %.3g, column2 %.3g (relative errors %.2g %.2g %.2g)\n",
                suite.experiments[e].name.c_str(), shift.norm(), column.norm(), column2.norm(),
                (r.mean - res0[e][0].mean - shift).norm() / shift.norm(),
                (r.group_column - column).norm() / column.norm(),
                (r.group_column2 - column2).norm() / column2.norm());
    EXPECT_LT((r.mean - res0[e][0].mean - shift).norm(), 1e-3 * shift.norm()) << suite.experiments[e].name;
    EXPECT_LT((r.group_column - column).norm(), 1e-3 * column.norm()) << suite.experiments[e].name;
    EXPECT_LT((r.group_column2 - column2).norm(), 2e-2 * column2.norm()) << suite.experiments[e].name;
    EXPECT_TRUE(res0[e][0].group_column.isZero(0.0) && res0[e][0].group_column2.isZero(0.0));
  }
}

TEST(GroupDiagnose, NamesTheGroupVariationAndOnlyWhenThereIsOne) {
  // The model knows the wheelbase error (refitted by diagnose); the candidates are the group
  // variations of Eb and Ed and the effects nearest to them. Family-wise alpha 0.01.
  WorldFile w = load_world(kWorld);
  const SuiteModel model = world_model(w, {{"wheelbase_error", {1.0}}});
  const std::vector<std::string> only = {kGroupVariation, "turn_dependent_wheelbase",
                                         "wheel_diameter_ratio", "per_run_radius"};
  const Diagnosis d = diagnose(synth_suite(w, "odomcov_group_diagnose"), model, kDiagnoseAlpha, only);
  ASSERT_TRUE(d.best);
  const Candidate& best = d.candidates[*d.best];
  std::printf("%s\n", explain(best).c_str());
  EXPECT_EQ(best.effect, "group_variation(wheelbase_error.Eb)");
  EXPECT_EQ(best.parameters, (std::vector<std::string>{"sd"}));
  EXPECT_TRUE(d.explained);
  EXPECT_EQ(candidate_yaml(best, model).rfind("- group_variation: {parameter: wheelbase_error.Eb, sd: ", 0), 0u);
  // The same world with no spread: no group candidate is significant.
  w.world.effects[1].values[0] = 0.0;
  const Diagnosis none = diagnose(synth_suite(w, "odomcov_group_diagnose_none"), model, kDiagnoseAlpha, only);
  for (const Candidate& c : none.candidates) {
    if (c.effect.rfind(kGroupVariation, 0) == 0) EXPECT_FALSE(c.significant) << c.effect << " p " << c.p_value;
  }
}

TEST(GroupLikelihood, LoggedRunsTheSameWhateverTheThreads) {
  // Logged runs are predicted in parallel, each with its group column; the grouped likelihood
  // is the same on one thread and on all.
  Suite suite = load_suite(ODOMCOV_SOURCE_DIR "/tests/data/suites/good_logs.yaml");
  suite.experiments[0].group = "day-1";
  SuiteModel model = suite_model(suite);
  model.effects = {{"wheelbase_error", {1.01}}, {kGroupVariation, {0.01}, "wheelbase_error.Eb"}};
  double one = 0.0;
  tbb::task_arena(1).execute([&] { one = log_likelihood(residuals(suite, model)); });
  const auto res = residuals(suite, model);
  EXPECT_EQ(log_likelihood(res), one);
  EXPECT_GT(res[0][0].group_column.norm(), 0.0);
  EXPECT_EQ(res[0][0].group, res[0][1].group);
}

TEST(GroupLikelihood, KeptPredictionsGiveTheSameBits) {
  // residuals' `predictions` (what calibrate's cache shares between models that differ only in
  // a reference offset, a group's sd or the measurement noise): a model predicted from another
  // model's kept predictions gets the bits of its own propagation. A group that varies the
  // reference offset itself, which the kept predictions leave out, too.
  Suite suite = load_suite(ODOMCOV_SOURCE_DIR "/tests/data/suites/good_logs.yaml");
  suite.experiments[0].group = "day-1";
  for (int order : {1, 2}) {  // order 2: the logged runs' coarse correction, kept in parts
    SuiteModel a = suite_model(suite);
    a.order = order;
    a.effects = {{"wheelbase_error", {1.01}},
                 {"reference_offset", {0.01, -0.02}},
                 {kGroupVariation, {0.003}, "reference_offset.dx"}};
    SuiteModel b = a;
    b.effects[1].values = {0.013, -0.015};
    b.effects[2].values = {0.002};
    b.measurement_noise.xy_m *= 2.0;
    RunPredictions kept;
    residuals(suite, a, nullptr, nullptr, &kept);
    ASSERT_TRUE(kept[0][0].has_value());
    const auto from_kept = residuals(suite, b, nullptr, nullptr, &kept);
    const auto fresh = residuals(suite, b);
    ASSERT_EQ(from_kept.size(), fresh.size());
    for (std::size_t e = 0; e < fresh.size(); ++e) {
      ASSERT_EQ(from_kept[e].size(), fresh[e].size());
      for (std::size_t r = 0; r < fresh[e].size(); ++r) {
        EXPECT_EQ(from_kept[e][r].error, fresh[e][r].error);
        EXPECT_EQ(from_kept[e][r].mean, fresh[e][r].mean);
        EXPECT_EQ(from_kept[e][r].cov, fresh[e][r].cov);
        EXPECT_EQ(from_kept[e][r].group_column, fresh[e][r].group_column);
        EXPECT_EQ(from_kept[e][r].group_column2, fresh[e][r].group_column2);
      }
    }
    // and the offset still acts: b's means are not a's
    EXPECT_NE(fresh[0][0].mean, residuals(suite, a)[0][0].mean);
    EXPECT_GT(fresh[0][0].group_column.norm(), 0.0);
  }
}

TEST(GroupSuite, BadTargetsAreBadInput) {
  const auto dir = std::filesystem::temp_directory_path() / "odomcov_group_bad";
  std::filesystem::create_directories(dir);
  auto load = [&](const std::string& effects) {
    std::ofstream(dir / "m.csv") << "run,x,y,theta\n1,1,0,0\n2,1,0,0\n";
    std::ofstream(dir / "suite.yaml")
        << "robot: {wheelbase: 0.4, k_left: 1.0e-3, k_right: 1.0e-3}\n"
           "model:\n  effects:\n"
        << effects
        << "experiments:\n  - {name: a, group: g, path: {sample_rate: 10, segments: [{line: 1}]},"
           " measurements: m.csv}\n";
    return load_suite((dir / "suite.yaml").string());
  };
  const Suite ok = load("    - wheelbase_error: {Eb: 1.0}\n"
                        "    - group_variation: {parameter: wheelbase_error.Eb, sd: 0.01}\n");
  EXPECT_EQ(ok.model_effects[1].target, "wheelbase_error.Eb");
  EXPECT_EQ(effect_yaml(ok.model_effects[1]),
            "- group_variation: {parameter: wheelbase_error.Eb, sd: 0.01}");
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"    - group_variation: {parameter: wheelbase_error.Eb, sd: 0.01}\n", "no effect wheelbase_error"},
      {"    - wheelbase_error: {Eb: 1.0}\n    - group_variation: {parameter: wheelbase_error.Ed, sd: 0.01}\n",
       "has no parameter Ed"},
      {"    - turn_slip: {k: 0.01}\n    - group_variation: {parameter: turn_slip.k, sd: 0.01}\n",
       "only adds randomness"},
      {"    - wheelbase_error: {Eb: 1.0}\n    - group_variation: {sd: 0.01}\n", "missing required key"},
      {"    - wheelbase_error: {Eb: 1.0}\n    - group_variation: {parameter: wheelbase_error.Eb, sd: -1}\n",
       "must be in [0, inf)"},
  };
  for (const auto& [effects, message] : bad) {
    try {
      load(effects);
      ADD_FAILURE() << "accepted: " << effects;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
      EXPECT_NE(e.key().find("group_variation"), std::string::npos) << e.key();
      EXPECT_GT(e.line(), 0);
    }
  }
  // The API checks the same.
  EXPECT_THROW(check_effects({{kGroupVariation, {0.01}, "scale_error.Es"}}), EffectError);
}

}  // namespace
}  // namespace odomcov
