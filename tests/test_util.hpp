// Helpers shared by the tests: matrix comparison, seeded random paths, portable normal draws and
// per-build-tree scratch directories.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "odomcov/closed_form/path.hpp"

namespace odomcov::test {

/// A fresh, empty directory for one test's files, inside this build tree (ODOMCOV_TEST_DIR, set
/// by tests/CMakeLists.txt) and named with the process id: two build trees, or two tests run in
/// parallel by ctest, never share one.
inline std::filesystem::path scratch_dir(const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::path(ODOMCOV_TEST_DIR) / (name + "-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// Standard normal draws that are the same with every standard library: the Box-Muller transform
/// of the raw 64-bit outputs of std::mt19937_64 (a sequence the C++ standard fixes), where
/// std::normal_distribution's algorithm is left to the implementation (libstdc++ and libc++
/// differ), so fixed-seed tests would not be portable.
class PortableNormal {
 public:
  double operator()(std::mt19937_64& rng) {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    constexpr double kTwoPow53 = 9007199254740992.0;
    const double u1 = (static_cast<double>(rng() >> 11) + 1.0) / kTwoPow53;  // (0, 1]
    const double u2 = static_cast<double>(rng() >> 11) / kTwoPow53;          // [0, 1)
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * M_PI * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * M_PI * u2);
  }

 private:
  double spare_ = 0.0;
  bool has_spare_ = false;
};

/// Exponential(1) draws from the raw outputs of std::mt19937_64, for the same reason.
inline double portable_exponential(std::mt19937_64& rng) {
  return -std::log((static_cast<double>(rng() >> 11) + 1.0) / 9007199254740992.0);
}

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
