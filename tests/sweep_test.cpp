#include "odomcov/io/sweep.hpp"

#include <gtest/gtest.h>

#include <set>

#include "odomcov/base/error.hpp"
#include "odomcov/engine/propagation.hpp"

namespace odomcov {
namespace {

const std::string kSmall = ODOMCOV_SOURCE_DIR "/tests/data/sweep/small.yaml";

TEST(Sweep, GridIsRowMajorInTheOrderWritten) {
  const SweepPlan plan = load_sweep(kSmall);
  ASSERT_EQ(plan.point_count(), 12u);
  EXPECT_EQ(plan.point_values(0), (std::vector<double>{1, 20, 0.5}));
  EXPECT_EQ(plan.point_values(1), (std::vector<double>{1, 20, 1}));
  EXPECT_EQ(plan.point_values(2), (std::vector<double>{1, 50, 0.5}));
  EXPECT_EQ(plan.point_values(11), (std::vector<double>{20, 200, 1}));
}

TEST(Sweep, PointsGetTheirValuesAndDistinctSeeds) {
  const SweepPlan plan = load_sweep(kSmall);
  std::set<std::uint64_t> seeds;
  for (std::size_t i = 0; i < plan.point_count(); ++i) {
    const Config c = plan.point_config(i);
    const std::vector<double> v = plan.point_values(i);
    EXPECT_DOUBLE_EQ(c.robot.noise.k_left, 1e-3 * v[0]);
    EXPECT_DOUBLE_EQ(c.robot.noise.k_right, 2e-3 * v[0]);
    // noise_scale scales the wheel noise itself: the simulated world's as well as the model's.
    EXPECT_DOUBLE_EQ(c.world.noise.k_left, 1e-3 * v[0]);
    EXPECT_DOUBLE_EQ(c.world.noise.k_right, 2e-3 * v[0]);
    EXPECT_EQ(c.path.sample_rate_hz, v[1]);
    EXPECT_EQ(c.simulation.runs, 400);
    EXPECT_EQ(c.simulation.seed, plan.point_seed(i));
    seeds.insert(c.simulation.seed);
  }
  EXPECT_EQ(seeds.size(), plan.point_count());
}

TEST(Sweep, PathScaleScalesLinesAndRadiiNotSpins) {
  // The Fig. 7 path scaled by 2: the 2 m line becomes 4 m, the spin is still 90 deg, arc radii
  // double with their angles kept; the faster wheel keeps its speed.
  const Path fig7{200.0,
                  {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708},
                   {5, 3.37445, 4.15985}}};
  const double B = 0.5;
  const Path scaled = scale_path(fig7, 2.0);
  for (std::size_t i = 0; i < fig7.interval_count(); ++i) {
    EXPECT_NEAR(scaled.interval(i).center_m(), 2 * fig7.interval(i).center_m(), 1e-12);
    EXPECT_NEAR(scaled.interval(i).heading_change_rad(B), fig7.interval(i).heading_change_rad(B),
                1e-12);
  }
  EXPECT_DOUBLE_EQ(scaled.keyframes[1].t_s, 4.0);                           // line: twice as long
  EXPECT_DOUBLE_EQ(scaled.keyframes[2].t_s - scaled.keyframes[1].t_s, 1.0);  // spin: unchanged
  // Straight-line end points scale exactly; the whole path's geometry is similar.
  const Vector3 end = path_end_pose(fig7, B), end2 = path_end_pose(scaled, B);
  EXPECT_NEAR(end2.z(), end.z(), 1e-12);
  EXPECT_NEAR(end2.x(), 2 * end.x(), 1e-9);
  EXPECT_NEAR(end2.y(), 2 * end.y(), 1e-9);
}

TEST(Sweep, MetricsFollowTheirDefinitions) {
  Validation v;
  v.simulation = {10000, Vector3(1e-4, 0, -2e-4), Vector3(4e-6, 1e-6, 9e-6).asDiagonal()};
  v.theory_cov = Vector3(1e-6, 1e-6, 1e-6).asDiagonal();
  v.simulation.cov(0, 1) = v.simulation.cov(1, 0) = 1e-6;  // corr 0.5 vs 0
  const SweepMetrics m = sweep_metrics(v);
  EXPECT_NEAR(m.std_rel_err.x(), 1.0, 1e-12);
  EXPECT_NEAR(m.std_rel_err.z(), 2.0, 1e-12);
  EXPECT_NEAR(m.bias_se.x(), 1e-4 / (2e-3 / 100), 1e-9);
  EXPECT_NEAR(m.max_corr_diff, 0.5, 1e-12);
}

TEST(Sweep, AxesReachIntoEffectLists) {
  // By the effect's name in a list, or by index; the model keeps its own list.
  const SweepPlan plan = load_sweep(ODOMCOV_SOURCE_DIR "/tests/data/sweep/effect_axis.yaml");
  const Config c = plan.point_config(1);
  ASSERT_EQ(c.world.effects.size(), 1u);
  EXPECT_EQ(c.world.effects[0].values[0], 1.01);
  ASSERT_EQ(c.model_effects.size(), 1u);
  EXPECT_EQ(c.model_effects[0].values[0], 1.0);
}

TEST(Sweep, BadGridValuesNameTheSweepFile) {
  try {
    load_sweep(ODOMCOV_SOURCE_DIR "/tests/data/sweep/bad_value.yaml");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(e.line(), 3);
    EXPECT_EQ(e.key(), "grid.robot.wheelbase");
  }
}

}  // namespace
}  // namespace odomcov
