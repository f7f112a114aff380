// Path-level theory: the [Kleeman95] tables (golden values), consistency under splitting
// [Chong97 §4.1], and the per-sample propagation of [Wang88] as an independent route.
#include "odomcov/engine/propagation.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "odomcov/measurement/config.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/io/config_io.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

using test::max_rel_diff;

/// The Fig. 7 path: the keyframes printed in [Kleeman95] §7.
Path fig7_path() {
  return {200.0,
          {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}, {5, 3.37445, 4.15985}}};
}

Matrix3 sym(double a, double b, double c, double d, double e, double f) {
  Matrix3 m;
  m << a, b, c, b, d, e, c, e, f;
  return m;
}

/// Printed values carry 4 decimals of the table's scale factor; half a unit in the last place
/// is the rounding, and the rounded keyframes (5 digits) move the theory by < 1e-6 relative.
void expect_table(const Matrix3& got, const Matrix3& printed, double scale, const char* what) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(got(i, j), printed(i, j) * scale, 0.5e-4 * scale + 1e-6 * std::abs(got(i, j)))
          << what << " entry (" << i << "," << j << ")";
    }
  }
}

TEST(Propagation, ReproducesTableI) {
  // [Kleeman95] Table I / RUN.M output, kL = kR = 1e-3, B = 0.5. x-theta and y-theta at C and E
  // (heading 90 deg) carry the sign correction of erratum 5 (T(+theta)).
  const PathCovariance t = path_covariance(fig7_path(), {0.5, {1e-3, 1e-3}});
  ASSERT_EQ(t.keyframes.size(), 5u);
  expect_table(t.keyframes[1].segment_P_world, sym(0.0100, 0, 0, 0.2133, 0.1600, 0.1600), 1e-4,
               "A to B");
  expect_table(t.keyframes[1].P_world, sym(0.0100, 0, 0, 0.2133, 0.1600, 0.1600), 1e-4, "B");
  expect_table(t.keyframes[2].segment_P_world, sym(0.0098, 0.0062, 0, 0.0098, 0, 0.3142), 1e-5,
               "B to C");
  expect_table(t.keyframes[2].P_world, sym(0.0110, 0.0006, 0, 0.2143, 0.1600, 0.1914), 1e-4, "C");
  expect_table(t.keyframes[3].segment_P_world,
               sym(0.0346, -0.0375, -0.0507, 0.0589, 0.0750, 0.1257), 1e-4, "C to D");
  expect_table(t.keyframes[3].P_world, sym(0.2370, -0.3883, -0.2421, 0.7846, 0.4264, 0.3171),
               1e-4, "D");
  expect_table(t.keyframes[4].segment_P_world, sym(0.0074, 0.0047, 0, 0.0123, 0.0393, 0.3142),
               1e-5, "D to E");
  expect_table(t.keyframes[4].P_world, sym(0.3032, -0.4763, -0.2817, 0.8974, 0.4700, 0.3485),
               1e-4, "E");
  // Key poses of Fig. 7.
  EXPECT_LT((t.keyframes[3].pose_world - Vector3(3.0, 1.0, 0.0)).norm(), 1e-4);
  EXPECT_LT((t.keyframes[4].pose_world - Vector3(3.125, 1.125, M_PI / 2)).norm(), 1e-4);
}

TEST(Propagation, ReproducesTableII) {
  // [Kleeman95] Table II / RUN.M output, kL = 1e-3, kR = 2e-3 (signs per erratum 5 at C, E).
  const PathCovariance t = path_covariance(fig7_path(), {0.5, {1e-3, 2e-3}});
  expect_table(t.keyframes[1].P_world, sym(0.0250, 0.0600, 0.0600, 0.5333, 0.4000, 0.4000), 1e-4,
               "B");
  expect_table(t.keyframes[2].segment_P_world,
               sym(0.0245, 0.0156, 0.0750, 0.0245, 0.0750, 0.7854), 1e-5, "B to C");
  expect_table(t.keyframes[2].P_world, sym(0.0275, 0.0616, 0.0675, 0.5358, 0.4075, 0.4785), 1e-4,
               "C");
  expect_table(t.keyframes[3].segment_P_world,
               sym(0.0614, -0.0797, -0.0795, 0.1694, 0.1875, 0.2670), 1e-4, "C to D");
  expect_table(t.keyframes[3].P_world, sym(0.0432, -0.0837, -0.0491, 0.1999, 0.1074, 0.0746),
               1e-3, "D");
  expect_table(t.keyframes[4].segment_P_world,
               sym(0.0013, 0.0015, 0.0056, 0.0043, 0.0184, 0.1021), 1e-4, "D to E");
  expect_table(t.keyframes[4].P_world, sym(0.0568, -0.1042, -0.0578, 0.2283, 0.1185, 0.0848),
               1e-3, "E");
}

/// Relative agreement to 4 significant figures: half a unit in the 4th digit.
void expect_4_significant(const Matrix3& got, const Matrix3& want, const char* what) {
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(got(i, j), want(i, j), 5e-4 * std::abs(want(i, j))) << what << " " << i << j;
    }
  }
}

TEST(Propagation, ReproducesLKTheoreticalOfTablesIIIandIV) {
  // "LK theoretical cov matrix" printed in [Kleeman95] §7 (7 digits) and Table IV; Table V's
  // theory is Table IV's times 100.
  const Matrix3 table3 = sym(3.031791e-05, -4.763405e-05, -2.817159e-05, 8.974219e-05,
                             4.699783e-05, 3.48496e-05);
  const Matrix3 table4 = sym(5.680e-5, -0.000104, -5.782e-5, 0.000228, 0.000119, 8.477e-5);
  expect_4_significant(path_covariance(fig7_path(), {0.5, {1e-3, 1e-3}}).end().P_world, table3,
                       "Table III");
  const Matrix3 p4 = path_covariance(fig7_path(), {0.5, {1e-3, 2e-3}}).end().P_world;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      // Table IV prints 3-4 significant figures; docs/conventions.md gives 5 (5.6797e-05, ...).
      EXPECT_NEAR(p4(i, j), table4(i, j), 0.5e-6 + 5e-4 * std::abs(table4(i, j)));
    }
  }
  expect_4_significant(p4,
                       sym(5.6797e-05, -1.0423e-04, -5.7815e-05, 2.2830e-04, 1.1851e-04,
                           8.4768e-05),
                       "seeds README, kR = 2e-3");
  expect_4_significant(path_covariance(fig7_path(), {0.5, {1e-2, 2e-2}}).end().P_world,
                       100.0 * sym(5.6797e-05, -1.0423e-04, -5.7815e-05, 2.2830e-04, 1.1851e-04,
                                   8.4768e-05),
                       "Table V");
}

TEST(Propagation, ShippedConfigsAreFigures7And9) {
  const Config fig7 = load_config(ODOMCOV_SOURCE_DIR "/configs/kleeman95/fig7.yaml");
  const Config fig9 = load_config(ODOMCOV_SOURCE_DIR "/configs/kleeman95/fig9.yaml");
  EXPECT_EQ(fig7.robot.noise.k_right, 1e-3);
  EXPECT_EQ(fig9.robot.noise.k_right, 2e-3);
  EXPECT_LT(max_rel_diff(path_covariance(fig7.path, fig7.robot).end().P_world,
                         path_covariance(fig7_path(), {0.5, {1e-3, 1e-3}}).end().P_world),
            1e-15);
}

TEST(Propagation, SplittingAPathDoesNotChangeP) {
  // [Chong97 §4.1]: propagating in parts must give the same result. Random paths (backwards
  // motion, both turn senses, negative radii, kL != kR), each interval cut in two at a random
  // point and into 1000 equal pieces. Required 1e-9 relative; the composition is exact in
  // exact arithmetic, so what remains is rounding (~1e-13 after 1000 pieces).
  std::mt19937_64 rng(2024);
  for (int trial = 0; trial < 200; ++trial) {
    const test::RandomCase c = test::random_case(rng);
    const Matrix3 whole = path_covariance(c.path, c.robot).end().P_world;
    const Matrix3 halves = path_covariance(test::split_path(c.path, 0, rng), c.robot).end().P_world;
    EXPECT_LT(max_rel_diff(halves, whole), 1e-12) << "trial " << trial;
    if (trial % 10 == 0) {
      const Matrix3 thousand =
          path_covariance(test::split_path(c.path, 1000, rng), c.robot).end().P_world;
      EXPECT_LT(max_rel_diff(thousand, whole), 1e-9) << "trial " << trial;
    }
  }
}

TEST(Propagation, SplittingMatchesEntryByEntry) {
  // The same property entry by entry (not only in norm) on the Fig. 7 path with kL != kR.
  std::mt19937_64 rng(7);
  const Robot robot{0.5, {1e-3, 2e-3}};
  const Matrix3 whole = path_covariance(fig7_path(), robot).end().P_world;
  const Matrix3 split = path_covariance(test::split_path(fig7_path(), 1000, rng), robot).end().P_world;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(split(i, j), whole(i, j), 1e-9 * std::abs(whole(i, j)));
  }
}

TEST(Propagation, SampledPropagationConvergesToClosedForm) {
  // [Wang88]-style per-sample propagation is an independent computation (exact discrete
  // Jacobians, no integrals). Its difference from the closed form is the midpoint-rule error of
  // the noise integral, O(1/f^2): doubling f must cut it ~4x. Keyframe times are put on the
  // 400 Hz grid: a sample that straddles a keyframe where a wheel reverses has noise
  // k^2 |net increment| (docs/conventions.md), an O(1/f) effect of sampling that is not under test here.
  std::mt19937_64 rng(88);
  for (int trial = 0; trial < 20; ++trial) {
    test::RandomCase c = test::random_case(rng);
    for (Keyframe& k : c.path.keyframes) k.t_s = std::ceil(k.t_s * 400.0) / 400.0;
    const Matrix3 closed = path_covariance(c.path, c.robot).end().P_world;
    double previous = 0.0;
    for (double f : {400.0, 800.0, 1600.0, 3200.0}) {
      c.path.sample_rate_hz = f;
      const double diff = max_rel_diff(sampled_covariance(c.path, c.robot), closed);
      // The rounding accumulated over ~1e5 sample steps is ~1e-11 (measured); above 1e-9 it
      // moves the ratio by < 0.05.
      if (previous > 0.0 && diff > 1e-9) EXPECT_NEAR(previous / diff, 4.0, 0.1) << "f = " << f;
      previous = diff;
    }
    EXPECT_LT(previous, 1e-6);
  }
}

TEST(Propagation, NoiseInducedMeanOnALine) {
  // Line of length d, heading variance growing as q s (q = (kL^2 + kR^2)/B^2 per metre):
  //   E[x] = int_0^d (exp(-q s/2) - 1) ds = d sum_{k>=1} (-x)^k/(k+1)!,  x = q d/2,
  //   E[y] = (N_td/2) int_0^1 exp(-x u) du = (N_td/2)(1 - exp(-x))/x,  N_td = d (kR^2-kL^2)/(2B),
  // summed here as series (no cancellation), so the comparison is at rounding level.
  const Robot robot{0.5, {1e-2, 3e-2}};
  const double d = 4.0;
  const double x = (1e-4 + 9e-4) / 0.25 * d / 2;
  // damp = (1 - exp(-x))/x = sum_{k>=0} (-x)^k/(k+1)!;  E[x]/d = damp - 1 = the k >= 1 terms.
  double tail = 0, term = -x / 2;
  for (int k = 1; k < 20; ++k) {
    tail += term;
    term *= -x / (k + 2);
  }
  const double damp = 1.0 + tail;
  const double ex = d * tail;
  const double ey = 0.5 * d * (9e-4 - 1e-4) / (2 * 0.5) * damp;
  const Path line{100.0, {{0, 0, 0}, {8, d, d}}};
  const Vector3 m = noise_induced_mean(line, robot);
  EXPECT_NEAR(m.x(), ex, 4e-15 * std::abs(ex));
  EXPECT_NEAR(m.y(), ey, 4e-15 * std::abs(ey));
  EXPECT_EQ(m.z(), 0.0);
}

TEST(Propagation, NoiseInducedMeanIsSplitInvariant) {
  std::mt19937_64 rng(31);
  for (int trial = 0; trial < 50; ++trial) {
    const test::RandomCase c = test::random_case(rng);
    const Vector3 whole = noise_induced_mean(c.path, c.robot);
    const Vector3 split = noise_induced_mean(test::split_path(c.path, 0, rng), c.robot);
    EXPECT_LT((split - whole).norm(), 1e-12 * whole.norm()) << "trial " << trial;
  }
}

TEST(Propagation, IncrementJacobianIsFirstOrderPerturbation) {
  std::mt19937_64 rng(89);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double d = 0.1 * u(rng), a = trial % 2 ? 1e-9 * u(rng) : 0.5 * u(rng);
    const Matrix32 j = arc_increment_jacobian(d, a);
    const Eigen::Vector2d dir(u(rng), u(rng));
    auto residual = [&](double h) {
      const Vector3 nominal = arc_displacement(d, a);
      const Vector3 moved = arc_displacement(d + h * dir(1), a + h * dir(0));
      Vector3 e;
      e.head<2>() = world_from_tangential(nominal.z()).topLeftCorner<2, 2>().transpose() *
                    (moved - nominal).head<2>();
      e.z() = moved.z() - nominal.z();
      return (e - j * (h * dir)).norm();
    };
    const double r1 = residual(1e-4), r2 = residual(1e-5);
    if (r1 > 1e-17) EXPECT_LT(r2, r1 / 50.0 + 1e-18);
  }
}

/// A logged run's pieces for the mean's bit-for-bit tests: 400 samples of 10 ms, forward, then
/// backward (both wheels reverse), then forward at half the travel, with a kink every 50.
void reversing_log(std::vector<ArcSegment>& pieces, std::vector<double>& durations) {
  for (int i = 0; i < 400; ++i) {
    const double s = i < 150 ? 1.0 : (i < 300 ? -1.0 : 0.5);
    pieces.push_back({s * (0.004 + 1e-5 * (i % 7)), s * 0.0043 - 0.002 * (i % 50 == 0)});
    durations.push_back(0.01);
  }
}

TEST(Propagation, PredictMeanIsPredictsMeanBitForBit) {
  // predict_mean (the mean alone, for group_variation's column) streams resolve's pieces through
  // the same arithmetic as predict: the same bits, with history effects (backlash cuts pieces),
  // motion-dependent ones and a measurement hook, on pieces with reversals.
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;
  reversing_log(pieces, durations);
  const Robot robot{0.3, {1e-3, 2e-3}};
  const std::vector<EffectList> models = {
      {},
      {{"wheelbase_error", {1.02}}, {"backlash", {0.001, 0.002}}},
      {{"turn_dependent_wheelbase", {1.01, 1.03}}, {"reference_offset", {0.01, -0.02}}},
  };
  for (const EffectList& effects : models) {
    const Prediction p = predict(pieces, durations, robot, effects);
    const Vector3 alone = predict_mean(pieces, durations, robot, effects);
    const Vector3 given = predict_mean(pieces, durations, robot, effects, &p.odometry_end_pose);
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(alone(k), p.mean(k)) << effects.size() << " " << k;
      EXPECT_EQ(given(k), p.mean(k)) << effects.size() << " " << k;
    }
  }
}

TEST(Propagation, AGivenOdometryIsTheWalkBitForBit) {
  // The odometry depends on the encoders alone: predict takes a logged run's odometry_walk,
  // computed once, instead of walking it again at every evaluation, and gives the same bits.
  // Where an effect cuts the pieces (backlash at the reversals) it walks the odometry itself,
  // so even a wrong pose given there changes nothing.
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;
  reversing_log(pieces, durations);
  const Robot robot{0.3, {1e-3, 2e-3}};
  const Vector3 walked = odometry_walk(pieces, robot.wheelbase_m);
  const Vector3 wrong = walked + Vector3(1.0, -2.0, 0.5);
  const std::vector<std::pair<EffectList, bool>> models = {
      {{}, true},
      {{{"turn_dependent_wheelbase", {1.01, 1.03}}, {"reference_offset", {0.01, -0.02}}}, true},
      {{{"scale_error", {0.99}}, {"arc_skid", {0.002}}, {"per_run_radius", {0.001}}, {"acceleration_slip", {0.01}}}, true},
      {{{"wheelbase_error", {1.02}}, {"backlash", {0.001, 0.002}}}, false},
  };
  for (const double heading0 : {0.0, 0.7}) {
    for (const auto& [effects, uncut] : models) {
      const Prediction own = predict(pieces, durations, robot, effects, heading0);
      const Prediction given = predict(pieces, durations, robot, effects, heading0, uncut ? &walked : &wrong);
      if (uncut) EXPECT_EQ(own.odometry_end_pose, walked) << effects.size();
      EXPECT_EQ(given.odometry_end_pose, own.odometry_end_pose) << effects.size();
      EXPECT_EQ(given.mean, own.mean) << effects.size();
      EXPECT_EQ(given.noise_mean, own.noise_mean) << effects.size();
      EXPECT_EQ(given.cov, own.cov) << effects.size();
      EXPECT_EQ(given.true_end_pose, own.true_end_pose) << effects.size();
    }
  }
  // The effects moved the true path, so the odometry's shortcut (reusing the true piece's
  // angle functions) was not what made the two walks agree.
  EXPECT_NE(predict(pieces, durations, robot, models[1].first).true_end_pose, walked);
}

TEST(Propagation, PredictMeansIsPredictMeanForEachList) {
  // predict_means (group_variation's terms: one parameter at several values) walks the pieces
  // once for every list when no effect cuts or refines them, and once per list otherwise: either
  // way each mean is predict_mean's for its list, bit for bit, with the odometry given or not.
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;
  reversing_log(pieces, durations);
  const Robot robot{0.3, {1e-3, 2e-3}};
  auto at = [](EffectList list, std::size_t effect, double value) {
    list[effect].values[0] = value;
    return list;
  };
  const EffectList shared = {{"turn_dependent_wheelbase", {1.01, 1.03}},
                             {"wheel_diameter_ratio", {0.999}},
                             {"reference_offset", {0.01, -0.02}}};
  const EffectList cut = {{"wheelbase_error", {1.02}}, {"backlash", {0.001, 0.002}}};
  const std::vector<std::vector<EffectList>> cases = {
      {at(shared, 0, 1.005), at(shared, 0, 1.015), at(shared, 0, 1.01)},
      {at(shared, 1, 0.998), at(shared, 1, 1.0)},
      {at(cut, 0, 1.01), at(cut, 0, 1.03)},
  };
  for (const double heading0 : {0.0, 0.7}) {
    for (const std::vector<EffectList>& lists : cases) {
      const Vector3 odometry = predict(pieces, durations, robot, lists[0], heading0).odometry_end_pose;
      const std::vector<Vector3> alone = predict_means(pieces, durations, robot, lists, nullptr, heading0);
      const std::vector<Vector3> given = predict_means(pieces, durations, robot, lists, &odometry, heading0);
      ASSERT_EQ(alone.size(), lists.size());
      ASSERT_EQ(given.size(), lists.size());
      for (std::size_t j = 0; j < lists.size(); ++j) {
        const Vector3 one = predict_mean(pieces, durations, robot, lists[j], nullptr, heading0);
        const Vector3 one_given = predict_mean(pieces, durations, robot, lists[j], &odometry, heading0);
        for (int k = 0; k < 3; ++k) {
          EXPECT_EQ(alone[j](k), one(k)) << lists[j][0].name << " list " << j << " component " << k;
          EXPECT_EQ(given[j](k), one_given(k)) << lists[j][0].name << " list " << j << " component " << k;
        }
      }
      // The lists differ, and so do their means: the test compares different numbers.
      EXPECT_NE(alone[0], alone[1]);
    }
  }
}

TEST(Propagation, TrajectoryTakesThePiecesDurations) {
  // predict_trajectory sees each piece's duration, as predict does: with a speed-dependent
  // custom effect (configs/effects/speed_scale.yaml's world) its last element is predict's
  // prediction bit for bit, and the effect moves the mean, which it cannot do without times
  // (the speed is unknown: the expression is not finite, an InputError naming it).
  const Config c = load_config(ODOMCOV_SOURCE_DIR "/configs/effects/speed_scale.yaml");
  std::vector<double> durations;
  const std::vector<ArcSegment> pieces = model_pieces(c.path, c.robot.wheelbase_m, &durations);
  const std::vector<Prediction> along = predict_trajectory(pieces, durations, c.robot, c.world.effects);
  const Prediction end = predict(pieces, durations, c.robot, c.world.effects);
  ASSERT_EQ(along.size(), pieces.size() + 1);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(along.back().mean(k), end.mean(k)) << k;
  EXPECT_EQ(along.back().cov, end.cov);
  EXPECT_GT(end.mean.head<2>().norm(), 1e-3);
  EXPECT_THROW(predict_trajectory(pieces, {}, c.robot, c.world.effects), InputError);
}

}  // namespace
}  // namespace odomcov
