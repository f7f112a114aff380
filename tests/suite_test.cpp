// Loading suites with per-run logs, and the optiodom importer on small fixtures.
#include "odomcov/measurement/suite.hpp"

#include <gtest/gtest.h>

#include "odomcov/measurement/likelihood.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include "odomcov/base/error.hpp"
#include "odomcov/io/optiodom.hpp"
#include "odomcov/io/suite_io.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

const std::string kSuites = ODOMCOV_SOURCE_DIR "/tests/data/suites/";

TEST(Suite, LogsIntegrateTheirOwnOdometryUpToTheLastReference) {
  const Suite s = load_suite(kSuites + "good_logs.yaml");
  ASSERT_EQ(s.experiments.size(), 1u);
  const SuiteExperiment& ex = s.experiments[0];
  ASSERT_TRUE(ex.logged);
  ASSERT_EQ(ex.runs.size(), 2u);
  // log_a's last reference is on its third row: two pieces, rows after it ignored.
  ASSERT_EQ(ex.runs[0].pieces.size(), 2u);
  Vector3 odo = drive(drive(Vector3::Zero(), {0.05, 0.05}, 0.4), {0.05, 0.07}, 0.4);
  EXPECT_LT((odometry_end_pose(ex, ex.runs[0], 0.4) - odo).norm(), 1e-15);
  EXPECT_EQ(ex.runs[0].measured, Vector3(0.109, 0.005, 0.05));
  EXPECT_EQ(ex.runs[0].id, "log_a");
  EXPECT_LT((run_error(ex, ex.runs[0], 0.4) - (Vector3(0.109, 0.005, 0.05) - odo)).norm(), 1e-15);
  // Residuals come from each run's own prediction.
  const auto res = residuals(s, suite_model(s));
  EXPECT_NE(res[0][0].cov, res[0][1].cov);
}

// Review defect 5 (stale odometry): a run's error must follow the wheelbase of the model it is
// set against, for logged runs and planned paths alike, since a fit may move the wheelbase.
TEST(Suite, ErrorsFollowTheModelsWheelbase) {
  const Suite s = load_suite(kSuites + "good_logs.yaml");
  SuiteModel model = suite_model(s);
  model.robot.wheelbase_m = 0.41;
  const auto res = residuals(s, model);
  const SuiteExperiment& ex = s.experiments[0];
  for (std::size_t r = 0; r < ex.runs.size(); ++r) {
    EXPECT_LT((res[0][r].error - run_error(ex, ex.runs[r], 0.41)).norm(), 1e-15);
  }
  // log_a turns, so its odometry does depend on the wheelbase.
  EXPECT_GT((run_error(ex, ex.runs[0], 0.41) - run_error(ex, ex.runs[0], 0.4)).norm(), 1e-6);
}

TEST(Suite, BadFilesNameFileLineAndColumn) {
  auto expect = [&](const std::string& suite, const std::string& fragment) {
    try {
      load_suite(kSuites + suite);
      ADD_FAILURE() << suite << ": no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect("missing_file.yaml", "missing.csv: cannot open file");
  expect("empty_csv.yaml", "empty.csv: empty file");
  expect("header_only.yaml", "header_only.csv:1: no data rows");
  expect("wrong_columns.yaml", "wrong_columns.csv:1: expected the header 'run,x,y,theta'");
  expect("nan.yaml", "nan.csv:3: column 'y': must be finite");
  expect("duplicate_ids.yaml", "duplicate.csv:4: column 'run': duplicate run id '1'");
  expect("log_no_reference.yaml", "log_no_reference.csv:4: column 'x,y,theta': the log has no reference pose");
}

TEST(OptiOdom, ImportsTicksAsMetresAndGroupsByDirection) {
  OptiOdomOptions o;
  o.sessions = {ODOMCOV_SOURCE_DIR "/tests/data/optiodom/square/20000101"};
  std::vector<ImportSummary> summary;
  const std::vector<ImportedFile> files = import_optiodom(o, &summary);
  ASSERT_EQ(files.size(), 3u);
  ASSERT_EQ(summary.size(), 2u);
  EXPECT_EQ(summary[0].experiment, "square-20000101-cw");
  EXPECT_EQ(summary[1].experiment, "square-20000101-straight");
  // 40 cycles x 100 ticks x pi 0.08/(10 x 100) m per tick.
  EXPECT_NEAR(summary[1].mean_travel_m, 40 * 100 * M_PI * 0.08 / 1000, 1e-12);
  EXPECT_NEAR(summary[0].mean_turn_rad, -20 * 100 * M_PI * 0.08 / 1000 / 0.2, 1e-12);
  EXPECT_NE(files.back().text.find("robot: {wheelbase: 0.2"), std::string::npos);
}

// Each experiment's group is its session by default (the session directory's name: the cw and
// ccw experiments of one session share it) or, with OptiOdomGroup::day, the recording day. Two
// real sessions of data/optiodom: 230620202042 (20:42 on 23 June 2020) and 231220200029 (00:29 on
// 23 December 2020, which counts to the evening of the 22nd).
TEST(OptiOdom, GroupIsTheSessionOrTheDay) {
  const std::string diff = ODOMCOV_SOURCE_DIR "/data/optiodom/data/diff/square/";
  auto groups = [&](OptiOdomGroup group) {
    OptiOdomOptions o;
    o.sessions = {diff + "230620202042", diff + "231220200029"};
    o.wheelbase_m = 0.2;
    o.diameters_m = {{0.084, 0.084}};
    o.group = group;
    const auto dir = test::scratch_dir("optiodom_group");
    for (const ImportedFile& f : import_optiodom(o)) {
      std::filesystem::create_directories((dir / f.path).parent_path());
      std::ofstream(dir / f.path) << f.text;
    }
    std::map<std::string, std::string> by_name;
    for (const SuiteExperiment& ex : load_suite((dir / "suite.yaml").string()).experiments) {
      by_name[ex.name] = ex.group;
    }
    return by_name;
  };
  const std::map<std::string, std::string> sessions = groups(OptiOdomGroup::session);
  EXPECT_EQ(sessions, groups(OptiOdomOptions{}.group));  // the session is the default
  const std::map<std::string, std::string> expected_sessions{
      {"square-230620202042-ccw", "230620202042"}, {"square-230620202042-cw", "230620202042"},
      {"square-231220200029-ccw", "231220200029"}, {"square-231220200029-cw", "231220200029"}};
  EXPECT_EQ(sessions, expected_sessions);
  const std::map<std::string, std::string> expected_days{
      {"square-230620202042-ccw", "2020-06-23"}, {"square-230620202042-cw", "2020-06-23"},
      {"square-231220200029-ccw", "2020-12-22"}, {"square-231220200029-cw", "2020-12-22"}};
  EXPECT_EQ(groups(OptiOdomGroup::day), expected_days);
}

// The metadata row "Di,D1,D2" gives the diameter of the wheel of the first encoder column (odoR,
// column 5 of a run file) first, then that of odoL (column 6) [Sousa22]. With D1 = 0.08 m and
// D2 = 0.06 m and equal ticks on both wheels, the right wheel travels 4/3 as far as the left: the
// robot turns left (counter-clockwise). Swapping the two diameters would make it turn right.
// The scatter log-likelihood of three runs with full covariances (two share one), plus an
// experiment of one run, which says nothing about the spread (0). The golden value comes from
// tests/data/golden/scatter_likelihood.py: exact rational arithmetic (cofactor inverse and
// determinant) and 40-digit logarithms, independent of Eigen and of the Cholesky factor used
// here. The tolerance is a few hundred ulps of the terms (about 50 in magnitude).
TEST(Likelihood, ScatterGoldenValue) {
  Matrix3 s1, s2;
  s1 << 1e-4, 2e-5, 1e-6, 2e-5, 4e-4, -3e-6, 1e-6, -3e-6, 1e-6;
  s2 << 2e-4, 0, 0, 0, 1e-4, 5e-6, 0, 5e-6, 4e-6;
  const std::vector<std::vector<RunResidual>> res{
      {{{0.01, 0.02, 0.003}, {0.001, 0, 0}, s1},
       {{-0.005, 0.01, 0.001}, {0.001, 0, 0}, s1},
       {{0.002, -0.004, -0.002}, {0.0005, 0.001, 0}, s2}},
      {{{0.5, 0.5, 0.5}, {0, 0, 0}, s2}}};
  EXPECT_NEAR(scatter_log_likelihood(res), 20.091428794250649618, 1e-12);
  const std::vector<double> terms = run_log_likelihoods(res, true);
  ASSERT_EQ(terms.size(), 4u);
  EXPECT_EQ(terms[3], 0.0);
}

TEST(OptiOdom, FirstDiameterIsTheRightWheel) {
  const auto session = test::scratch_dir("optiodom_order") / "square" / "20000104";
  std::filesystem::create_directories(session);
  std::ofstream(session / "20000104_metadata.csv")
      << "type,diff,,\nngear,10,,\nencRes,100,,\nLi,0.2,,\nDi,0.08,0.06\nN,1,,\n";
  std::ofstream run(session / "20000104_run-01.csv");
  run << "0,0,0,0,0,0\n";
  for (int i = 1; i <= 30; ++i) run << 0.05 * i << ",0,0,0,100,100\n";
  run.close();
  OptiOdomOptions o;
  o.sessions = {session.string()};
  std::vector<ImportSummary> summary;
  const std::vector<ImportedFile> files = import_optiodom(o, &summary);
  ASSERT_EQ(summary.size(), 1u);
  EXPECT_EQ(summary[0].experiment, "square-20000104-ccw");
  // 30 cycles x 100 ticks x pi D / (10 x 100) m per tick on each wheel.
  const double left = 30 * 100 * M_PI * 0.06 / 1000, right = 30 * 100 * M_PI * 0.08 / 1000;
  EXPECT_NEAR(summary[0].mean_turn_rad, (right - left) / 0.2, 1e-12);
  // The log's last row: t, left, right (metres), then the reference.
  const std::string& log = files.front().text;
  const std::string last = log.substr(log.rfind('\n', log.size() - 2) + 1);
  double t = 0, l = 0, r = 0;
  ASSERT_EQ(std::sscanf(last.c_str(), "%lf,%lf,%lf", &t, &l, &r), 3) << last;
  EXPECT_NEAR(l, left, 1e-12);
  EXPECT_NEAR(r, right, 1e-12);
}

TEST(OptiOdom, MalformedSessionsFailClearly) {
  OptiOdomOptions o;
  o.sessions = {ODOMCOV_SOURCE_DIR "/tests/data/optiodom/bad/20000102"};
  EXPECT_THROW(import_optiodom(o), InputError);  // no ngear row
  o.sessions = {ODOMCOV_SOURCE_DIR "/tests/data/optiodom/bad/20000103"};
  try {
    import_optiodom(o);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 5);
    EXPECT_EQ(e.key(), "column '4'");
  }
}

}  // namespace
}  // namespace odomcov
