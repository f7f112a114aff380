#include "odomcov/closed_form/odometry_covariance.hpp"

#include <stdexcept>

#include "odomcov/closed_form/path.hpp"

namespace odomcov {

OdometryCovariance::OdometryCovariance(double wheelbase_m, const WheelNoise& k,
                                       const Vector3& pose_world, const Matrix3& P_world)
    : wheelbase_m_(wheelbase_m), k_(k) {
  if (!(wheelbase_m > 0.0)) throw std::invalid_argument("OdometryCovariance: wheelbase_m must be > 0");
  if (!(k.k_left >= 0.0) || !(k.k_right >= 0.0)) {
    throw std::invalid_argument("OdometryCovariance: k_left and k_right must be >= 0");
  }
  last_.pose_world = pose_world;
  last_.P_world = 0.5 * (P_world + P_world.transpose());
}

const OdometryStep& OdometryCovariance::step(const ArcSegment& wheels) {
  const double d = wheels.center_m();
  const double a = wheels.heading_change_rad(wheelbase_m_);
  const double heading_in = last_.pose_world.z();
  const Vector3 pose_out = compose(last_.pose_world, arc_displacement(d, a));
  const Matrix3 T_in = world_from_tangential(heading_in);
  const Matrix3 T_out = world_from_tangential(pose_out.z());

  OdometryStep s;
  s.pose_world = pose_out;
  s.J_out_in = T_out * arc_transition(d, a) * T_in.transpose();
  s.Q_world = tangential_to_world(arc_covariance(wheels, wheelbase_m_, k_), pose_out.z());  // symmetric
  // (angle, center) from (left, right): angle = (R - L)/B, center = (L + R)/2.
  Eigen::Matrix2d input_from_wheels;
  input_from_wheels << -1.0 / wheelbase_m_, 1.0 / wheelbase_m_, 0.5, 0.5;
  s.J_out_wheels = T_out * arc_increment_jacobian(d, a) * input_from_wheels;
  const Matrix3 P = s.J_out_in * last_.P_world * s.J_out_in.transpose() + s.Q_world;
  s.P_world = 0.5 * (P + P.transpose());
  last_ = s;
  return last_;
}

}  // namespace odomcov
