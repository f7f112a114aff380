// Paths: keyframes of cumulative wheel travel, the segment shorthand that expands to them, the
// exact constant-curvature pose update, and the sampling schedule the simulator follows.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "odomcov/closed_form/closed_form.hpp"

namespace odomcov {

/// The nominal robot: wheelbase B [m] and the wheel noise constants kL, kR [m^(1/2)].
struct Robot {
  double wheelbase_m = 0.0;
  WheelNoise noise;
};

/// One row of a keyframe path: time [s] and cumulative encoder travel of each wheel [m].
struct Keyframe {
  double t_s = 0.0;
  double left_m = 0.0;
  double right_m = 0.0;
};

/// A path as the simulator and the theory see it: wheel distances linear in time between
/// keyframes (so each interval is a constant-curvature segment), sampled at sample_rate_hz.
struct Path {
  double sample_rate_hz = 0.0;
  std::vector<Keyframe> keyframes;  // first row (0, 0, 0), time strictly increasing

  std::size_t interval_count() const { return keyframes.empty() ? 0 : keyframes.size() - 1; }
  /// Wheel travel of the interval between keyframes i and i + 1.
  ArcSegment interval(std::size_t i) const;
  double duration_s() const { return keyframes.empty() ? 0.0 : keyframes.back().t_s; }
};

/// The segment shorthand of the config (docs/formats.md, "Path config"): driven in order, each at constant
/// wheel speeds with the faster wheel at `speed`.
struct PathSegment {
  enum class Kind { line, turn, arc };
  Kind kind = Kind::line;
  double distance_m = 0.0;  // line: signed length (negative = backwards)
  double angle_rad = 0.0;   // turn, arc: CCW positive
  double radius_m = 0.0;    // arc: > 0 centre on the left
};

/// Wheel travel of one segment: line d -> (d, d); turn a -> (-aB/2, aB/2);
/// arc (R, a) -> (a(R - B/2), a(R + B/2)).
ArcSegment segment_travel(const PathSegment& segment, double wheelbase_m);

/// Expands segments into keyframes; each segment lasts max(|left|, |right|)/speed.
std::vector<Keyframe> keyframes_from_segments(const std::vector<PathSegment>& segments,
                                              double wheelbase_m, double speed_mps);

/// SE(2) composition of poses (x, y, theta): world_T_b = world_T_a * a_T_b. theta is not wrapped.
Vector3 compose(const Vector3& world_T_a, const Vector3& a_T_b);

/// Degrees to radians, for the configs' *_deg keys.
inline constexpr double kDegToRad = M_PI / 180.0;

/// Angle wrapped to (-pi, pi].
double wrap_angle(double angle_rad);

/// The error of a pose against the odometry's as docs/conventions.md defines it: true - odometry, with
/// theta wrapped to (-pi, pi].
Vector3 pose_error(const Vector3& true_pose, const Vector3& odometry);

/// Pose after driving `segment` from `start` on the exact constant-curvature arc.
Vector3 drive(const Vector3& start, const ArcSegment& segment, double wheelbase_m);

/// The nominal end pose of the path (odometry without noise), integrated interval by interval.
Vector3 path_end_pose(const Path& path, double wheelbase_m);

/// The samples of a path, grouped into runs of identical encoder increments. Sample i covers
/// [i/f, min((i + 1)/f, T)]; samples that straddle a keyframe get their own run, so the
/// increments are exactly those of the piecewise-linear wheel distances.
struct SampleRun {
  std::int64_t count = 0;
  ArcSegment increment;  // encoder travel of each sample in the run
  double duration_s = 0.0;  // duration of each sample in the run (1/f, or less at a straddle)
};
std::vector<SampleRun> sample_schedule(const Path& path);

/// The encoder travel of a path as constant-curvature pieces: each run of equal samples of
/// sample_schedule is one arc (count x increment), so odometry driven piece by piece equals the
/// sampled odometry.
std::vector<ArcSegment> sample_arcs(const Path& path);

/// Total number of samples of a path (ceil(T f), with a 1e-9-sample tolerance).
std::int64_t sample_count(const Path& path);

/// The pieces the propagation engine uses for a keyframe path: each interval cut so that no piece turns
/// more than kPieceMaxAngle or travels more than kPieceMaxTravel, which only refines the
/// piecewise-linear V(u) of the noise-induced mean (the covariance does not change).
inline constexpr double kPieceMaxAngle = 0.25;   // rad
inline constexpr double kPieceMaxTravel = 0.25;  // m
/// `durations_s`, when given, receives each piece's duration.
std::vector<ArcSegment> model_pieces(const Path& path, double wheelbase_m,
                                     std::vector<double>* durations_s = nullptr);
/// The pieces of the sampled path: each run of equal samples of sample_schedule becomes its
/// first sample alone, then the rest cut as model_pieces cuts an interval. A quantity that
/// changes only where the increment changes (the acceleration along the path, from one sample
/// to the next) is then constant on every piece, as it is on every sample.
std::vector<ArcSegment> sample_model_pieces(const Path& path, double wheelbase_m,
                                            std::vector<double>* durations_s = nullptr);

}  // namespace odomcov
