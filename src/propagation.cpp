#include "odomcov/propagation.hpp"

#include <type_traits>

#include <cmath>
#include <algorithm>
#include <complex>
#include <limits>
#include <stdexcept>

#include "effects/effect.hpp"
#include "odomcov/limits.hpp"
#include "noise_mean.hpp"

namespace odomcov {

PathCovariance path_covariance(const Path& path, const Robot& robot) {
  const double B = robot.wheelbase_m;
  PathCovariance out;
  KeyframeCovariance current;  // t = 0, zero pose and covariance
  out.keyframes.push_back(current);
  Matrix3 P_tangential = Matrix3::Zero();
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment seg = path.interval(i);
    const double d = seg.center_m();
    const double a = seg.heading_change_rad(B);
    const Matrix3 phi = arc_transition(d, a);
    const Matrix3 q = arc_covariance(seg, B, robot.noise);
    P_tangential = phi * P_tangential * phi.transpose() + q;
    current.t_s = path.keyframes[i + 1].t_s;
    current.pose_world = drive(current.pose_world, seg, B);
    current.P_world = tangential_to_world(P_tangential, current.pose_world.z());
    current.segment_P_world = tangential_to_world(q, current.pose_world.z());
    out.keyframes.push_back(current);
  }
  return out;
}

namespace {

using Complex = std::complex<double>;

}  // namespace

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

namespace effects {

ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces,
                     const std::vector<double>& durations_s, const Robot& robot,
                     const EffectList& effect_list) {
  auto active = instantiate(effect_list);
  ResolvedPath out;
  for (const auto& e : active) {
    out.run_constants += e->run_constants();
  }
  const double B = robot.wheelbase_m;
  MotionTracker tracker(B);
  out.pieces.reserve(encoder_pieces.size());
  auto add_piece = [&](const ArcSegment& encoder, double dt) {
    PieceModel m;
    m.encoder = encoder;
    m.wheelbase_m = B;
    m.noise = robot.noise;
    m.motion = tracker.next(encoder.left_m, encoder.right_m, dt);
    Systematic sys;
    for (const auto& e : active) e->systematic(m.motion, sys);
    m.scale_left = sys.scale_left;
    m.scale_right = sys.scale_right;
    m.wheelbase_factor = sys.wheelbase_factor;
    m.wheel_cov.diagonal() = wheel_variances(encoder, robot.noise);
    for (const auto& e : active) e->model(m);

    ResolvedPiece r;
    r.encoder = encoder;
    const ArcSegment travel = sys.travel(encoder.left_m, encoder.right_m);
    r.wheelbase_true_m = m.wheelbase_factor * B;
    r.center_m = travel.center_m();
    r.angle_rad = travel.heading_change_rad(r.wheelbase_true_m);
    Eigen::Matrix2d to_input;  // (e_L, e_R) -> (e_dtheta, e_d)
    to_input << -1.0 / r.wheelbase_true_m, 1.0 / r.wheelbase_true_m, 0.5, 0.5;
    r.intensity = to_input * m.wheel_cov * to_input.transpose();
    r.intensity(0, 0) += m.heading_var;
    r.input_columns.resize(2, out.run_constants);
    for (int c = 0; c < out.run_constants; ++c) {
      r.input_columns.col(c) = to_input * m.run_columns.at(static_cast<std::size_t>(c));
    }
    out.pieces.push_back(std::move(r));
  };
  for (std::size_t i = 0; i < encoder_pieces.size(); ++i) {
    ArcSegment rest = encoder_pieces[i];
    double dt = durations_s.empty() ? std::nan("") : durations_s[i];
    // A history effect may change its factors inside the piece (backlash taken up): split there.
    for (int cut = 0; cut < 4; ++cut) {
      MotionTracker probe = tracker;
      const Motion whole = probe.next(rest.left_m, rest.right_m, dt);
      double f = 1.0;
      for (const auto& e : active) f = std::min(f, e->split_at(whole));
      if (!(f > 1e-12 && f < 1.0 - 1e-12)) break;
      add_piece({f * rest.left_m, f * rest.right_m}, f * dt);
      rest = {(1.0 - f) * rest.left_m, (1.0 - f) * rest.right_m};
      dt *= 1.0 - f;
    }
    add_piece(rest, dt);
  }
  for (auto& e : active) {
    if (e->measures()) out.measurement_effects.push_back(std::shared_ptr<const Effect>(std::move(e)));
  }
  return out;
}

}  // namespace effects

namespace {

/// The engine's loop; `each` (when not nullptr) sees the prediction after every piece.
template <class Each>
Prediction propagate(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effect_list, Each&& each) {
  const effects::ResolvedPath path = effects::resolve(pieces, durations_s, robot, effect_list);
  const int constants = path.run_constants;
  const double B = robot.wheelbase_m;

  Prediction out;
  Matrix3 P = Matrix3::Zero();                          // tangential, along the true path
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(3, constants);  // cov(e, per-run constants)
  Vector3 true_pose = Vector3::Zero();
  Vector3 odometry = Vector3::Zero();
  Complex noise_mean = 0.0;
  for (const effects::ResolvedPiece& r : path.pieces) {
    const double d = r.center_m;
    const double a = r.angle_rad;
    const Matrix3 phi = arc_transition(d, a);
    const Matrix3 q = arc_noise_covariance(d, a, r.intensity);
    const double v0 = P(2, 2);
    if (constants == 0) {
      P = phi * P * phi.transpose() + q;
    } else {
      const Eigen::MatrixXd A = arc_input_gain(d, a) * r.input_columns;
      const Matrix3 cross = phi * C * A.transpose();
      P = phi * P * phi.transpose() + cross + cross.transpose() + A * A.transpose() + q;
      C = phi * C + A;
    }
    // One cosine and sine of the heading serve the noise-induced mean and the pose update
    // (compose's own arithmetic, inlined).
    const double cos_h = std::cos(true_pose.z()), sin_h = std::sin(true_pose.z());
    noise_mean +=
        detail::noise_mean_of_piece(Complex(cos_h, sin_h), d, a, v0, P(2, 2) - v0, r.intensity(0, 1));
    const Vector3 step = arc_displacement(d, a);
    true_pose = {true_pose.x() + cos_h * step.x() - sin_h * step.y(),
                 true_pose.y() + sin_h * step.x() + cos_h * step.y(), true_pose.z() + step.z()};
    odometry = drive(odometry, r.encoder, B);
    if constexpr (!std::is_same_v<std::decay_t<Each>, std::nullptr_t>) {
      each(Prediction{pose_error(true_pose, odometry), {noise_mean.real(), noise_mean.imag(), 0.0},
                      tangential_to_world(P, true_pose.z()), odometry, true_pose});
    }
  }
  out.odometry_end_pose = odometry;
  out.true_end_pose = true_pose;
  out.cov = tangential_to_world(P, true_pose.z());
  Vector3 measured = true_pose;
  path.measure(measured, out.cov);  // what the external reference sees (reference_offset)
  out.mean = pose_error(measured, odometry);
  out.noise_mean = {noise_mean.real(), noise_mean.imag(), 0.0};
  return out;
}

}  // namespace

Prediction predict(const std::vector<ArcSegment>& pieces, const Robot& robot,
                   const EffectList& effect_list) {
  return propagate(pieces, {}, robot, effect_list, nullptr);
}

Prediction predict(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                   const Robot& robot, const EffectList& effect_list) {
  return propagate(pieces, durations_s, robot, effect_list, nullptr);
}

std::vector<Prediction> predict_trajectory(const std::vector<ArcSegment>& pieces,
                                           const Robot& robot, const EffectList& effect_list) {
  std::vector<Prediction> out;
  out.reserve(pieces.size() + 1);
  out.emplace_back();  // the start: exactly known
  propagate(pieces, {}, robot, effect_list, [&out](const Prediction& p) { out.push_back(p); });
  return out;
}

}  // namespace odomcov
