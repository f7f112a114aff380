#include "odomcov/engine/propagation.hpp"

#include <type_traits>

#include <cmath>
#include <algorithm>
#include <complex>
#include <limits>
#include <stdexcept>

#include "closed_form/arc_functions.hpp"
#include "effects/effect.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "engine/noise_mean.hpp"

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


namespace effects {
namespace {

/// Walks the encoder pieces as the effects see them: each piece cut where a history effect
/// changes its factors inside it (backlash taken up; split_at), and for every resulting piece
/// calls each(encoder, motion, systematic) with its motion and the effects' systematic factors
/// folded in. Without effects nothing reads the motion, and it is not computed.
template <class Each>
void for_each_piece(const std::vector<ArcSegment>& encoder_pieces,
                    const std::vector<double>& durations_s, double wheelbase_m,
                    const std::vector<std::unique_ptr<Effect>>& active, Each&& each) {
  bool splits = false;  // a history effect may cut pieces (split_at)
  for (const auto& e : active) splits = splits || e->dependence() == Dependence::history;
  MotionTracker tracker(wheelbase_m);
  Motion motion;
  auto one = [&](const ArcSegment& encoder, double dt) {
    Systematic sys;
    if (!active.empty()) {
      motion = tracker.next(encoder.left_m, encoder.right_m, dt);
      for (const auto& e : active) e->systematic(motion, sys);
    }
    each(encoder, motion, sys);
  };
  for (std::size_t i = 0; i < encoder_pieces.size(); ++i) {
    ArcSegment rest = encoder_pieces[i];
    double dt = durations_s.empty() ? std::nan("") : durations_s[i];
    for (int cut = 0; splits && cut < 4; ++cut) {
      MotionTracker probe = tracker;
      const Motion whole = probe.next(rest.left_m, rest.right_m, dt);
      double f = 1.0;
      for (const auto& e : active) f = std::min(f, e->split_at(whole));
      if (!(f > 1e-12 && f < 1.0 - 1e-12)) break;
      one({f * rest.left_m, f * rest.right_m}, f * dt);
      rest = {(1.0 - f) * rest.left_m, (1.0 - f) * rest.right_m};
      dt *= 1.0 - f;
    }
    one(rest, dt);
  }
}

/// The measurement hooks of the active effects (moved out of `active`).
std::vector<std::shared_ptr<const Effect>> measurement_effects(std::vector<std::unique_ptr<Effect>>& active) {
  std::vector<std::shared_ptr<const Effect>> out;
  for (auto& e : active) {
    if (e->measures()) out.push_back(std::shared_ptr<const Effect>(std::move(e)));
  }
  return out;
}

}  // namespace

ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces,
                     const std::vector<double>& durations_s, const Robot& robot,
                     const EffectList& effect_list) {
  auto active = instantiate(effect_list);
  ResolvedPath out;
  for (const auto& e : active) out.run_constants += e->run_constants();
  if (out.run_constants > kMaxRunConstants) {
    throw std::logic_error("resolve: more per-run constants than kMaxRunConstants");
  }
  const double B = robot.wheelbase_m;
  out.pieces.reserve(encoder_pieces.size());
  // One PieceModel serves every piece: its run columns keep their storage, so the loop does
  // not allocate.
  PieceModel m;
  double inverse_for = 0.0, inverse = 0.0;  // 1/b for the true wheelbase b = inverse_for
  m.wheelbase_m = B;
  m.noise = robot.noise;
  for_each_piece(encoder_pieces, durations_s, B, active,
                 [&](const ArcSegment& encoder, const Motion& motion, const Systematic& sys) {
    m.encoder = encoder;
    m.motion = motion;
    m.scale_left = sys.scale_left;
    m.scale_right = sys.scale_right;
    m.wheelbase_factor = sys.wheelbase_factor;
    m.wheel_cov.setZero();
    m.wheel_cov.diagonal() = wheel_variances(encoder, robot.noise);
    m.heading_var = 0.0;
    m.run_columns.clear();
    for (const auto& e : active) e->model(m);

    ResolvedPiece& r = out.pieces.emplace_back(encoder);
    const ArcSegment travel = sys.travel(encoder.left_m, encoder.right_m);
    r.wheelbase_true_m = m.wheelbase_factor * B;
    r.center_m = travel.center_m();
    r.angle_rad = travel.heading_change_rad(r.wheelbase_true_m);
    if (r.wheelbase_true_m != inverse_for) {  // 1/b changes only with the wheelbase factor
      inverse_for = r.wheelbase_true_m;
      inverse = 1.0 / inverse_for;
    }
    // (e_L, e_R) -> (e_dtheta, e_d) = ((e_R - e_L)/b, (e_L + e_R)/2), applied to the wheel
    // covariance W on both sides, written out.
    const double w11 = m.wheel_cov(0, 0), w22 = m.wheel_cov(1, 1);
    const double w12 = 0.5 * (m.wheel_cov(0, 1) + m.wheel_cov(1, 0));
    r.intensity(0, 0) = (w11 - 2.0 * w12 + w22) * inverse * inverse + m.heading_var;
    r.intensity(0, 1) = r.intensity(1, 0) = 0.5 * (w22 - w11) * inverse;
    r.intensity(1, 1) = 0.25 * (w11 + 2.0 * w12 + w22);
    r.input_columns.resize(2, out.run_constants);
    for (int c = 0; c < out.run_constants; ++c) {
      const Eigen::Vector2d& w = m.run_columns.at(static_cast<std::size_t>(c));
      r.input_columns.col(c) << (w.y() - w.x()) * inverse, 0.5 * (w.x() + w.y());
    }
  });
  out.measurement_effects = measurement_effects(active);
  return out;
}

}  // namespace effects

namespace {

/// A pose carried piece by piece, with the cosine and sine of its heading. They are updated by
/// multiplying with each piece's (cos a, sin a), which the piece's kernels have computed anyway,
/// and recomputed from the heading itself every kExactEvery pieces, so rounding in them stays
/// below ~kExactEvery ulps instead of growing with the path. The heading itself is summed
/// exactly as compose() does.
class PoseWalker {
 public:
  static constexpr int kExactEvery = 16;
  const Vector3& pose() const { return pose_; }
  Complex rotation() const { return rotation_; }
  /// Composes the piece of centre travel d whose angle functions are f.
  void step(double d, const detail::ArcStep& f) {
    const double x = f.chord_x(d), y = f.chord_y(d);
    const double c = rotation_.real(), s = rotation_.imag();
    pose_ = {pose_.x() + c * x - s * y, pose_.y() + s * x + c * y, pose_.z() + f.angle};
    if (++count_ == kExactEvery) {
      count_ = 0;
      rotation_ = Complex(std::cos(pose_.z()), std::sin(pose_.z()));
    } else {
      rotation_ *= Complex(f.cos1, f.sin1);
    }
  }

 private:
  Vector3 pose_ = Vector3::Zero();
  Complex rotation_ = 1.0;
  int count_ = 0;
};

/// phi P phi^T for the arc transition phi = [c s y; -s c x; 0 0 1] (arc_transition) and a
/// symmetric P, written out: the zeros and ones of phi cost nothing.
Matrix3 transition_congruence(const detail::ArcStep& f, double d, const Matrix3& P) {
  const double c = f.cos1, s = f.sin1, x = f.chord_x(d), y = f.chord_y(d);
  // M = phi P (rows 0 and 1; row 2 is P's)
  double m0[3], m1[3];
  for (int j = 0; j < 3; ++j) {
    m0[j] = c * P(0, j) + s * P(1, j) + y * P(2, j);
    m1[j] = -s * P(0, j) + c * P(1, j) + x * P(2, j);
  }
  Matrix3 out;
  out(0, 0) = c * m0[0] + s * m0[1] + y * m0[2];
  out(0, 1) = -s * m0[0] + c * m0[1] + x * m0[2];
  out(1, 1) = -s * m1[0] + c * m1[1] + x * m1[2];
  out(0, 2) = m0[2];
  out(1, 2) = m1[2];
  out(2, 2) = P(2, 2);
  out(1, 0) = out(0, 1);
  out(2, 0) = out(0, 2);
  out(2, 1) = out(1, 2);
  return out;
}

/// The engine's loop; `each` (when not nullptr) sees the prediction after every piece.
template <class Each>
Prediction propagate(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effect_list, Each&& each) {
  const effects::ResolvedPath path = effects::resolve(pieces, durations_s, robot, effect_list);
  const int constants = path.run_constants;
  const double B = robot.wheelbase_m;

  Prediction out;
  Matrix3 P = Matrix3::Zero();                          // tangential, along the true path
  // cov(e, per-run constants); fixed storage, so the loop does not allocate
  Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, effects::kMaxRunConstants> C =
      Eigen::MatrixXd::Zero(3, constants);
  PoseWalker true_pose, odometry;
  Complex noise_mean = 0.0;
  for (const effects::ResolvedPiece& r : path.pieces) {
    const double d = r.center_m;
    const double a = r.angle_rad;
    // One evaluation of the angle's functions serves every kernel below.
    const detail::ArcFunctions f(a);
    const Matrix3 q = detail::arc_noise_covariance(d, f, r.intensity);
    const double v0 = P(2, 2);
    if (constants == 0) {
      P = transition_congruence(f, d, P) + q;
    } else {
      const Matrix3 phi = detail::arc_transition(d, f);
      const Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, effects::kMaxRunConstants> A =
          detail::arc_input_gain(d, f) * r.input_columns;
      const Matrix3 cross = phi * C * A.transpose();
      P = phi * P * phi.transpose() + cross + cross.transpose() + A * A.transpose() + q;
      C = phi * C + A;
    }
    const Complex undamped(f.sinc1, 0.5 * a * f.sinc_half * f.sinc_half);  // int_0^1 e^{i a u} du
    noise_mean += detail::noise_mean_of_piece(true_pose.rotation(), d, a, undamped, v0, P(2, 2) - v0,
                                              r.intensity(0, 1));
    true_pose.step(d, f);
    // The odometry's piece: the same arc unless a systematic effect changed the true one.
    const double d_odometry = r.encoder.center_m(), a_odometry = r.encoder.heading_change_rad(B);
    if (d_odometry == d && a_odometry == a) {
      odometry.step(d, f);
    } else {
      odometry.step(d_odometry, detail::ArcStep(a_odometry));
    }
    if constexpr (!std::is_same_v<std::decay_t<Each>, std::nullptr_t>) {
      each(Prediction{pose_error(true_pose.pose(), odometry.pose()),
                      {noise_mean.real(), noise_mean.imag(), 0.0},
                      tangential_to_world(P, true_pose.pose().z()), odometry.pose(), true_pose.pose()});
    }
  }
  out.odometry_end_pose = odometry.pose();
  out.true_end_pose = true_pose.pose();
  out.cov = tangential_to_world(P, true_pose.pose().z());
  Vector3 measured = true_pose.pose();
  path.measure(measured, out.cov);  // what the external reference sees (reference_offset)
  out.mean = pose_error(measured, odometry.pose());
  out.noise_mean = {noise_mean.real(), noise_mean.imag(), 0.0};
  return out;
}

}  // namespace

Vector3 predict_mean(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effect_list,
                     const Vector3* odometry_end_pose) {
  // resolve's pieces, streamed: only their true arcs (the same arithmetic), nothing stored.
  auto active = effects::instantiate(effect_list);
  const double B = robot.wheelbase_m;
  const bool odometry_given = odometry_end_pose != nullptr;
  PoseWalker true_pose, odometry;
  effects::for_each_piece(pieces, durations_s, B, active,
                          [&](const ArcSegment& encoder, const effects::Motion&,
                              const effects::Systematic& sys) {
    const ArcSegment travel = sys.travel(encoder.left_m, encoder.right_m);
    const double center = travel.center_m(), angle = travel.heading_change_rad(sys.wheelbase_factor * B);
    const detail::ArcStep f(angle);
    true_pose.step(center, f);
    if (odometry_given) return;
    const double d_odometry = encoder.center_m(), a_odometry = encoder.heading_change_rad(B);
    if (d_odometry == center && a_odometry == angle) {
      odometry.step(center, f);
    } else {
      odometry.step(d_odometry, detail::ArcStep(a_odometry));
    }
  });
  effects::ResolvedPath hooks;
  hooks.measurement_effects = effects::measurement_effects(active);
  Vector3 measured = true_pose.pose();
  Matrix3 unused = Matrix3::Zero();
  hooks.measure(measured, unused);
  return pose_error(measured, odometry_given ? *odometry_end_pose : odometry.pose());
}

Prediction predict(const std::vector<ArcSegment>& pieces, const Robot& robot,
                   const EffectList& effect_list) {
  return propagate(pieces, {}, robot, effect_list, nullptr);
}

Prediction predict(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                   const Robot& robot, const EffectList& effect_list) {
  return propagate(pieces, durations_s, robot, effect_list, nullptr);
}

std::vector<Prediction> predict_trajectory(const std::vector<ArcSegment>& pieces,
                                           const std::vector<double>& durations_s,
                                           const Robot& robot, const EffectList& effect_list) {
  std::vector<Prediction> out;
  out.reserve(pieces.size() + 1);
  out.emplace_back();  // the start: exactly known
  propagate(pieces, durations_s, robot, effect_list, [&out](const Prediction& p) { out.push_back(p); });
  return out;
}

}  // namespace odomcov
