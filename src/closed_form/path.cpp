#include "odomcov/closed_form/path.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "odomcov/closed_form/limits.hpp"

namespace odomcov {
namespace {

/// Sample boundaries closer than this many samples to a keyframe time count as on it, so that
/// keyframes at whole multiples of 1/f do not produce sliver samples from rounding.
constexpr double kSampleTolerance = 1e-9;

}  // namespace

ArcSegment Path::interval(std::size_t i) const {
  return {keyframes[i + 1].left_m - keyframes[i].left_m,
          keyframes[i + 1].right_m - keyframes[i].right_m};
}

ArcSegment segment_travel(const PathSegment& segment, double wheelbase_m) {
  const double half_b = 0.5 * wheelbase_m;
  switch (segment.kind) {
    case PathSegment::Kind::line:
      return {segment.distance_m, segment.distance_m};
    case PathSegment::Kind::turn:
      return {-segment.angle_rad * half_b, segment.angle_rad * half_b};
    case PathSegment::Kind::arc:
      return {segment.angle_rad * (segment.radius_m - half_b),
              segment.angle_rad * (segment.radius_m + half_b)};
  }
  return {};
}

std::vector<Keyframe> keyframes_from_segments(const std::vector<PathSegment>& segments,
                                              double wheelbase_m, double speed_mps) {
  std::vector<Keyframe> keyframes{{0.0, 0.0, 0.0}};
  for (const PathSegment& segment : segments) {
    const ArcSegment travel = segment_travel(segment, wheelbase_m);
    const Keyframe& last = keyframes.back();
    const double duration_s = std::max(std::abs(travel.left_m), std::abs(travel.right_m)) /
                              speed_mps;
    keyframes.push_back(
        {last.t_s + duration_s, last.left_m + travel.left_m, last.right_m + travel.right_m});
  }
  return keyframes;
}

Vector3 compose(const Vector3& world_T_a, const Vector3& a_T_b) {
  const double c = std::cos(world_T_a.z());
  const double s = std::sin(world_T_a.z());
  return {world_T_a.x() + c * a_T_b.x() - s * a_T_b.y(),
          world_T_a.y() + s * a_T_b.x() + c * a_T_b.y(), world_T_a.z() + a_T_b.z()};
}

double wrap_angle(double angle_rad) {
  double wrapped = std::remainder(angle_rad, 2.0 * M_PI);  // in [-pi, pi]
  if (wrapped <= -M_PI) wrapped += 2.0 * M_PI;
  return wrapped;
}

Vector3 pose_error(const Vector3& true_pose, const Vector3& odometry) {
  return {true_pose.x() - odometry.x(), true_pose.y() - odometry.y(),
          wrap_angle(true_pose.z() - odometry.z())};
}

Vector3 drive(const Vector3& start, const ArcSegment& segment, double wheelbase_m) {
  return compose(start,
                 arc_displacement(segment.center_m(), segment.heading_change_rad(wheelbase_m)));
}

Vector3 path_end_pose(const Path& path, double wheelbase_m) {
  Vector3 pose = Vector3::Zero();
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    pose = drive(pose, path.interval(i), wheelbase_m);
  }
  return pose;
}

namespace {

/// floor/ceil results as counts, saturated: a path outside the input limits (limits.hpp) must
/// not turn into undefined behaviour here; callers check the count against kMaxSamplesPerRun.
std::int64_t to_count(double value) {
  constexpr double kMax = 9.0e18;  // below INT64_MAX, exactly representable
  if (!(value > 0.0)) return 0;
  return value >= kMax ? static_cast<std::int64_t>(kMax) : static_cast<std::int64_t>(value);
}

}  // namespace

std::int64_t sample_count(const Path& path) {
  return to_count(std::ceil(path.duration_s() * path.sample_rate_hz - kSampleTolerance));
}

std::vector<ArcSegment> sample_arcs(const Path& path) {
  std::vector<ArcSegment> arcs;
  for (const SampleRun& s : sample_schedule(path)) {
    const double n = static_cast<double>(s.count);
    arcs.push_back({n * s.increment.left_m, n * s.increment.right_m});
  }
  return arcs;
}

std::vector<SampleRun> sample_schedule(const Path& path) {
  std::vector<SampleRun> runs;
  const double f = path.sample_rate_hz;
  const double T = path.duration_s();
  const std::int64_t n = sample_count(path);
  // Samples [0, n_full) have the full length 1/f; the last one may be shorter.
  if (n > kMaxSamplesPerRun) {
    throw std::length_error("sample_schedule: " + std::to_string(n) +
                            " samples, above kMaxSamplesPerRun (limits.hpp)");
  }
  const auto n_full = std::min(n, to_count(std::floor(T * f + kSampleTolerance)));
  const auto& kf = path.keyframes;

  // Encoder travel over [t0, t1], from the piecewise-linear wheel distances.
  auto travel = [&](double t0, double t1) {
    ArcSegment sum;
    for (std::size_t k = 0; k < path.interval_count(); ++k) {
      const double overlap = std::min(t1, kf[k + 1].t_s) - std::max(t0, kf[k].t_s);
      if (overlap <= 0.0) continue;
      const double span = kf[k + 1].t_s - kf[k].t_s;
      const ArcSegment seg = path.interval(k);
      sum.left_m += seg.left_m * (overlap / span);
      sum.right_m += seg.right_m * (overlap / span);
    }
    return sum;
  };

  std::size_t k = 0;
  std::int64_t i = 0;
  while (i < n) {
    const double t0 = static_cast<double>(i) / f;
    while (k + 1 < path.interval_count() && kf[k + 1].t_s * f <= static_cast<double>(i) + kSampleTolerance) {
      ++k;
    }
    // Full samples starting at i that end inside interval k share one increment.
    const auto end_in_k =
        std::min(n_full, to_count(std::floor(kf[k + 1].t_s * f + kSampleTolerance)));
    if (end_in_k > i) {
      const double span = kf[k + 1].t_s - kf[k].t_s;
      const ArcSegment seg = path.interval(k);
      runs.push_back({end_in_k - i, {seg.left_m / (span * f), seg.right_m / (span * f)}, 1.0 / f});
      i = end_in_k;
      continue;
    }
    // A sample that straddles a keyframe, or the final short sample.
    const double t1 = std::min(static_cast<double>(i + 1) / f, T);
    runs.push_back({1, travel(t0, t1), t1 - t0});
    ++i;
  }
  return runs;
}

std::vector<ArcSegment> model_pieces(const Path& path, double wheelbase_m,
                                     std::vector<double>* durations_s) {
  // The input checks (limits::check_path) keep paths far below this; a caller that skipped
  // them gets an exception here instead of an overflowing count or a huge allocation.
  const double total = limits::model_piece_count(path, wheelbase_m);
  if (!(total <= kMaxModelPieces)) {
    throw std::length_error("model_pieces: the path needs " + std::to_string(total) +
                            " pieces, above kMaxModelPieces (limits.hpp)");
  }
  std::vector<ArcSegment> pieces;
  pieces.reserve(static_cast<std::size_t>(total));
  if (durations_s) {
    durations_s->clear();
    durations_s->reserve(static_cast<std::size_t>(total));
  }
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment seg = path.interval(i);
    const double cuts = std::max({1.0, std::ceil(std::abs(seg.heading_change_rad(wheelbase_m)) / kPieceMaxAngle),
                                  std::ceil(std::abs(seg.center_m()) / kPieceMaxTravel)});
    const auto n = static_cast<std::int64_t>(cuts);
    const double nd = static_cast<double>(n);
    const double span = path.keyframes[i + 1].t_s - path.keyframes[i].t_s;
    for (std::int64_t k = 0; k < n; ++k) {
      pieces.push_back({seg.left_m / nd, seg.right_m / nd});
      if (durations_s) durations_s->push_back(span / nd);
    }
  }
  return pieces;
}

std::vector<ArcSegment> sample_model_pieces(const Path& path, double wheelbase_m,
                                            std::vector<double>* durations_s) {
  // As many pieces as model_pieces plus two per run of equal samples (checked as there).
  const double total = limits::model_piece_count(path, wheelbase_m);
  if (!(total <= kMaxModelPieces)) {
    throw std::length_error("sample_model_pieces: the path needs " + std::to_string(total) +
                            " pieces, above kMaxModelPieces (limits.hpp)");
  }
  std::vector<ArcSegment> pieces;
  if (durations_s) durations_s->clear();
  auto add = [&](const ArcSegment& piece, double duration) {
    pieces.push_back(piece);
    if (durations_s) durations_s->push_back(duration);
  };
  for (const SampleRun& run : sample_schedule(path)) {
    add(run.increment, run.duration_s);
    if (run.count < 2) continue;
    const double rest = static_cast<double>(run.count - 1);
    const ArcSegment seg{rest * run.increment.left_m, rest * run.increment.right_m};
    const double cuts = std::max({1.0, std::ceil(std::abs(seg.heading_change_rad(wheelbase_m)) / kPieceMaxAngle),
                                  std::ceil(std::abs(seg.center_m()) / kPieceMaxTravel)});
    const auto n = static_cast<std::int64_t>(cuts);
    const double nd = static_cast<double>(n);
    for (std::int64_t k = 0; k < n; ++k) add({seg.left_m / nd, seg.right_m / nd}, rest * run.duration_s / nd);
  }
  return pieces;
}

}  // namespace odomcov
