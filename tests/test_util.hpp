// Helpers shared by the tests: matrix comparison and seeded random paths.
#pragma once

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "odomcov/path.hpp"

namespace odomcov::test {

/// max |a - b| / max(max |b|, floor): the norm-relative difference used for matrices whose
/// entries span several orders of magnitude (or contain exact zeros).
inline double max_rel_diff(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b,
                           double floor = 0.0) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(b.cwiseAbs().maxCoeff(), floor);
}

/// A random segment: lines (either direction), turns on the spot (either sense) and arcs with
/// radius of either sign driven forwards or backwards.
inline PathSegment random_segment(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::uniform_int_distribution<int> kind(0, 2);
  const double sign = u(rng) < 0.5 ? -1.0 : 1.0;
  PathSegment s;
  switch (kind(rng)) {
    case 0:
      s.kind = PathSegment::Kind::line;
      s.distance_m = sign * (0.1 + 4.9 * u(rng));
      break;
    case 1:
      s.kind = PathSegment::Kind::turn;
      s.angle_rad = sign * (0.05 + 2.0 * M_PI * u(rng));
      break;
    default:
      s.kind = PathSegment::Kind::arc;
      s.radius_m = (u(rng) < 0.5 ? -1.0 : 1.0) * (0.05 + 3.0 * u(rng));
      s.angle_rad = sign * (0.05 + 2.0 * M_PI * u(rng));
  }
  return s;
}

struct RandomCase {
  Robot robot;
  Path path;
};

/// A random robot (kL != kR) and a path of 1-6 random segments.
inline RandomCase random_case(std::mt19937_64& rng, double sample_rate_hz = 100.0) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  RandomCase c;
  c.robot.wheelbase_m = 0.2 + 0.8 * u(rng);
  c.robot.noise = {1e-4 + 1e-2 * u(rng), 1e-4 + 1e-2 * u(rng)};
  std::vector<PathSegment> segments(1 + static_cast<int>(6 * u(rng)));
  for (auto& s : segments) s = random_segment(rng);
  c.path.sample_rate_hz = sample_rate_hz;
  c.path.keyframes = keyframes_from_segments(segments, c.robot.wheelbase_m, 0.5);
  return c;
}

/// The same path with every interval cut into `pieces` equal parts (or, with pieces == 0,
/// into two at a random fraction).
inline Path split_path(const Path& path, int pieces, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.05, 0.95);
  Path out{path.sample_rate_hz, {path.keyframes.front()}};
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const Keyframe& a = path.keyframes[i];
    const Keyframe& b = path.keyframes[i + 1];
    std::vector<double> cuts;
    if (pieces == 0) {
      cuts = {u(rng), 1.0};
    } else {
      for (int p = 1; p <= pieces; ++p) cuts.push_back(static_cast<double>(p) / pieces);
    }
    for (double f : cuts) {
      out.keyframes.push_back({a.t_s + f * (b.t_s - a.t_s), a.left_m + f * (b.left_m - a.left_m),
                               a.right_m + f * (b.right_m - a.right_m)});
    }
    out.keyframes.back() = b;
  }
  return out;
}

}  // namespace odomcov::test
