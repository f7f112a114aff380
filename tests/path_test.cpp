#include "odomcov/closed_form/path.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "test_util.hpp"

namespace odomcov {
namespace {

TEST(Path, SegmentTravel) {
  const double B = 0.5;
  const ArcSegment line = segment_travel({PathSegment::Kind::line, -2.0, 0, 0}, B);
  EXPECT_EQ(line.left_m, -2.0);
  EXPECT_EQ(line.right_m, -2.0);
  const ArcSegment turn = segment_travel({PathSegment::Kind::turn, 0, M_PI / 2, 0}, B);
  EXPECT_DOUBLE_EQ(turn.left_m, -M_PI / 8);  // [Kleeman95] Fig. 7: 1.6073 = 2 - pi/8
  EXPECT_DOUBLE_EQ(turn.right_m, M_PI / 8);
  // Fig. 7's third segment: radius -2B through -90 deg; forwards since R a > 0.
  const ArcSegment arc = segment_travel({PathSegment::Kind::arc, 0, -M_PI / 2, -1.0}, B);
  EXPECT_NEAR(arc.left_m, 3.5708 - 1.6073, 1e-4);
  EXPECT_NEAR(arc.right_m, 3.5708 - 2.3927, 1e-4);
  EXPECT_GT(arc.center_m(), 0.0);
  EXPECT_DOUBLE_EQ(arc.heading_change_rad(B), -M_PI / 2);
}

TEST(Path, KeyframesFromSegmentsUseTheFasterWheelSpeed) {
  const std::vector<PathSegment> segments{{PathSegment::Kind::line, 2.0, 0, 0},
                                          {PathSegment::Kind::turn, 0, M_PI / 2, 0},
                                          {PathSegment::Kind::arc, 0, -M_PI / 2, -1.0}};
  const auto kf = keyframes_from_segments(segments, 0.5, 0.5);
  ASSERT_EQ(kf.size(), 4u);
  EXPECT_DOUBLE_EQ(kf[1].t_s, 4.0);
  EXPECT_DOUBLE_EQ(kf[2].t_s, 4.0 + (M_PI / 8) / 0.5);
  EXPECT_DOUBLE_EQ(kf[3].t_s - kf[2].t_s, (M_PI / 2 * 1.25) / 0.5);  // outer (left) wheel
  EXPECT_NEAR(kf[3].left_m, 3.5708, 1e-4);
}

TEST(Path, WrapAngle) {
  EXPECT_EQ(wrap_angle(M_PI), M_PI);
  EXPECT_EQ(wrap_angle(-M_PI), M_PI);
  EXPECT_NEAR(wrap_angle(3 * M_PI), M_PI, 1e-15);
  EXPECT_NEAR(wrap_angle(-0.5 - 4 * M_PI), -0.5, 1e-14);
  EXPECT_EQ(wrap_angle(1e-300), 1e-300);
}

TEST(Path, AlignedScheduleHasOneRunPerInterval) {
  const Path fig7{200.0,
                  {{0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708},
                   {5, 3.37445, 4.15985}}};
  const auto runs = sample_schedule(fig7);
  ASSERT_EQ(runs.size(), 4u);
  EXPECT_EQ(runs[0].count, 400);
  EXPECT_EQ(runs[1].count, 200);
  EXPECT_DOUBLE_EQ(runs[0].increment.left_m, 2.0 / 400);
  EXPECT_EQ(sample_count(fig7), 1000);
}

TEST(Path, ScheduleCoversStraddlesAndAShortLastSample) {
  // Keyframes at 0.013 s and 0.0301 s against a 100 Hz grid: samples straddle both keyframes
  // and the last sample is 0.1 ms long.
  const Path path{100.0, {{0, 0, 0}, {0.013, 0.02, 0.03}, {0.0301, -0.01, 0.05}}};
  const auto runs = sample_schedule(path);
  std::int64_t n = 0;
  double left = 0, right = 0;
  for (const auto& r : runs) {
    n += r.count;
    left += static_cast<double>(r.count) * r.increment.left_m;
    right += static_cast<double>(r.count) * r.increment.right_m;
  }
  EXPECT_EQ(n, 4);
  EXPECT_EQ(sample_count(path), 4);
  EXPECT_NEAR(left, -0.01, 1e-15);
  EXPECT_NEAR(right, 0.05, 1e-15);
  // Sample 1 covers [0.01, 0.02]: 0.003 s of interval 0 and 0.007 s of interval 1.
  ASSERT_GE(runs.size(), 2u);
  EXPECT_NEAR(runs[1].increment.left_m, 0.02 * 3 / 13 + (-0.03) * 7 / 17.1, 1e-15);
  // The last sample covers [0.03, 0.0301].
  EXPECT_NEAR(runs.back().increment.right_m, 0.02 * 0.1 / 17.1, 1e-15);
}

TEST(Path, SampledOdometryReachesTheArcEndPose) {
  // Integrating the samples with the exact arc update lands on the keyframe path's end pose
  // when keyframes fall on samples (arcs of one curvature compose exactly).
  std::mt19937_64 rng(5);
  for (int trial = 0; trial < 50; ++trial) {
    test::RandomCase c = test::random_case(rng, 100.0);
    for (Keyframe& k : c.path.keyframes) k.t_s = std::ceil(k.t_s * 100.0) / 100.0;
    Vector3 pose = Vector3::Zero();
    for (const SampleRun& r : sample_schedule(c.path)) {
      for (std::int64_t i = 0; i < r.count; ++i) pose = drive(pose, r.increment, c.robot.wheelbase_m);
    }
    const Vector3 end = path_end_pose(c.path, c.robot.wheelbase_m);
    EXPECT_LT((pose - end).norm(), 1e-10 * (1.0 + end.norm()));
  }
}

}  // namespace
}  // namespace odomcov
