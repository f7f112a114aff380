#include "odomcov/closed_form/limits.hpp"

#include <algorithm>
#include <cmath>

#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/path.hpp"

namespace odomcov::limits {
namespace {

std::string g(double v) { return format_number(v, "%.6g"); }

}  // namespace

std::string check_length(double value_m) {
  if (!std::isfinite(value_m) || std::abs(value_m) > kMaxLength_m) {
    return "magnitude " + g(value_m) + " m is beyond the limit of " + g(kMaxLength_m) + " m";
  }
  return "";
}

std::string check_angle(double value_rad) {
  if (!std::isfinite(value_rad) || std::abs(value_rad) > kMaxTurn_rad) {
    return "magnitude " + g(value_rad) + " rad is beyond the limit of " + g(kMaxTurn_rad) + " rad";
  }
  return "";
}

std::string check_wheelbase(double wheelbase_m) {
  if (!(wheelbase_m >= kMinWheelbase_m && wheelbase_m <= kMaxLength_m)) {
    return "must be in [" + g(kMinWheelbase_m) + ", " + g(kMaxLength_m) + "] m, got " +
           g(wheelbase_m);
  }
  return "";
}

std::string check_wheel_noise(const WheelNoise& noise) {
  for (double k : {noise.k_left, noise.k_right}) {
    if (!(k >= 0.0 && k <= kMaxWheelNoise)) {
      return "wheel noise k must be in [0, " + g(kMaxWheelNoise) + "] m^(1/2), got " + g(k);
    }
  }
  return "";
}

double model_piece_count(const Path& path, double wheelbase_m) {
  double pieces = 0.0;
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment seg = path.interval(i);
    pieces += std::max({1.0, std::ceil(std::abs(seg.heading_change_rad(wheelbase_m)) / kPieceMaxAngle),
                        std::ceil(std::abs(seg.center_m()) / kPieceMaxTravel)});
  }
  return pieces;  // NaN or inf when the path is out of range: callers check the travel first
}

std::string check_path(const Path& path, double wheelbase_m) {
  if (!(path.sample_rate_hz >= kMinSampleRate_hz) || !std::isfinite(path.sample_rate_hz)) {
    return "sample_rate " + g(path.sample_rate_hz) + " Hz is below the limit of " +
           g(kMinSampleRate_hz) + " Hz";
  }
  double turn = 0.0;
  for (const Keyframe& k : path.keyframes) {
    for (double travel : {k.left_m, k.right_m}) {
      if (const std::string e = check_length(travel); !e.empty()) {
        return "wheel travel at t = " + g(k.t_s) + " s: " + e;
      }
    }
  }
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    turn += std::abs(path.interval(i).heading_change_rad(wheelbase_m));
  }
  if (!(turn <= kMaxTurn_rad)) {
    return "the path turns " + g(turn) + " rad in all, more than the limit of " +
           g(kMaxTurn_rad) + " rad";
  }
  const double samples = std::ceil(path.duration_s() * path.sample_rate_hz);
  if (!(samples <= static_cast<double>(kMaxSamplesPerRun))) {
    return "the path needs " + g(samples) + " samples, more than the limit of " +
           std::to_string(kMaxSamplesPerRun);
  }
  const double pieces = model_piece_count(path, wheelbase_m);
  if (!(pieces <= kMaxModelPieces)) {
    return "the path needs " + g(pieces) + " model pieces (one per " + g(kPieceMaxTravel) +
           " m or " + g(kPieceMaxAngle) + " rad), more than the limit of " + g(kMaxModelPieces);
  }
  return "";
}

std::string check_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m) {
  if (static_cast<double>(pieces.size()) > kMaxModelPieces) {
    return "the run has " + std::to_string(pieces.size()) + " log rows, more than the limit of " +
           g(kMaxModelPieces);
  }
  double left = 0.0, right = 0.0, turn = 0.0;
  for (const ArcSegment& p : pieces) {
    left += p.left_m;
    right += p.right_m;
    turn += std::abs(p.heading_change_rad(wheelbase_m));
  }
  if (std::string e = check_length(left); !e.empty()) return "left wheel travel: " + e;
  if (std::string e = check_length(right); !e.empty()) return "right wheel travel: " + e;
  if (!(turn <= kMaxTurn_rad)) {
    return "the run turns " + g(turn) + " rad in all, more than the limit of " + g(kMaxTurn_rad) +
           " rad";
  }
  return "";
}

}  // namespace odomcov::limits
