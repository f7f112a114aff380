// A stateful, per-step form of the closed form: what an EKF's prediction step needs. Part of
// odomcov::closed_form (depends on Eigen only).
//
// Frames and signs (docs/conventions.md):
//   * pose_world = (x [m], y [m], theta [rad]) of the robot in the world (start) frame, theta
//     counter-clockwise and not wrapped;
//   * the error e = true pose - odometry pose, in world coordinates (x, y, theta), first order;
//     P_world = E[e e^T] in m^2, m rad, rad^2;
//   * a step is one constant-curvature piece of encoder travel (left_m, right_m), e.g. one
//     odometry sample or one keyframe interval. Splitting a piece into several steps gives the
//     same covariance [Chong97, §4.1], so the step size is the caller's choice.
//
// The covariance update is [Kleeman95, eqs. (36)-(43)] with the errata of docs/conventions.md:
//   P_tan_end  = Phi P_tan_start Phi^T + Q_tan                  (tangential frames)
//   P_world    = T(theta) P_tan T(theta)^T                      (erratum 5: +theta)
// written in the world frame as
//   P_world_out = J_out_in P_world_in J_out_in^T + Q_world,
//   J_out_in = T(theta_out) Phi T(theta_in)^T = [[1, 0, -(y_out - y_in)],
//                                                [0, 1,  (x_out - x_in)],
//                                                [0, 0,  1           ]],
// the familiar EKF Jacobian of the pose update with respect to the previous pose.
#pragma once

#include "odomcov/closed_form/closed_form.hpp"

namespace odomcov {

/// The result of one step, all in the world (start) frame.
struct OdometryStep {
  Vector3 pose_world = Vector3::Zero();  // odometry pose after the step (exact arc update)
  Matrix3 P_world = Matrix3::Zero();     // accumulated covariance after the step (symmetric)
  Matrix3 Q_world = Matrix3::Zero();     // this step's own noise contribution [Kleeman95 eq. (40)]
  /// d pose_out / d pose_in (world-frame additive perturbations of the pose before the step).
  Matrix3 J_out_in = Matrix3::Identity();
  /// d pose_out / d (left_m, right_m): the first-order effect of errors in the step's wheel
  /// travel [m per m], e.g. for a Jacobian-based EKF that brings its own wheel noise.
  Matrix32 J_out_wheels = Matrix32::Zero();
};

/// Accumulates pose and covariance step by step.
///
///   OdometryCovariance odo(0.5, {1e-3, 1e-3});
///   for (auto [dl, dr] : encoder_increments) {
///     const OdometryStep& s = odo.step({dl, dr});
///     ekf.predict(s.J_out_in, s.Q_world);   // P <- F P F^T + Q
///   }
class OdometryCovariance {
 public:
  /// wheelbase_m > 0; k the wheel noise constants [m^(1/2)] of [Kleeman95, eq. (1)]. Starts at
  /// pose_world with covariance P_world (default: the origin, exactly known).
  OdometryCovariance(double wheelbase_m, const WheelNoise& k,
                     const Vector3& pose_world = Vector3::Zero(),
                     const Matrix3& P_world = Matrix3::Zero());

  /// Drives one constant-curvature piece of encoder travel and returns the new state together
  /// with the step's Jacobians and noise. The reference stays valid until the next call.
  const OdometryStep& step(const ArcSegment& wheels);

  const Vector3& pose_world() const { return last_.pose_world; }
  const Matrix3& P_world() const { return last_.P_world; }
  double wheelbase_m() const { return wheelbase_m_; }
  const WheelNoise& noise() const { return k_; }

 private:
  double wheelbase_m_;
  WheelNoise k_;
  OdometryStep last_;
};

}  // namespace odomcov
