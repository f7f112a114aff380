// Covariance along a whole path: the closed form composed segment by segment ([Kleeman95] §6,
// Tables I-II), and the per-sample linearised propagation of [Wang88] as an independent check.
#pragma once

#include <vector>

#include "odomcov/closed_form.hpp"
#include "odomcov/path.hpp"

namespace odomcov {

/// The theory at one keyframe (Tables I-II): accumulated covariance and the interval's own
/// contribution, both in the world frame at the keyframe's heading.
struct KeyframeCovariance {
  double t_s = 0.0;
  Vector3 pose_world = Vector3::Zero();
  Matrix3 P_world = Matrix3::Zero();
  Matrix3 segment_P_world = Matrix3::Zero();  // zero for the first keyframe
};

struct PathCovariance {
  std::vector<KeyframeCovariance> keyframes;  // one per keyframe, the first at t = 0
  const KeyframeCovariance& end() const { return keyframes.back(); }
};

/// Closed-form covariance at every keyframe of the path [Kleeman95, eqs. (40)-(43)].
PathCovariance path_covariance(const Path& path, const Robot& robot);

/// First-order covariance of the sampled odometry, propagated sample by sample with the exact
/// Jacobians of the discrete arc update (the approach of [Wang88]): for each sample,
///   P <- Phi P Phi^T + J N J^T,
/// with J the derivative of the sample's end pose (in its end frame) with respect to
/// (dtheta, d) and N the sample's noise intensity. It converges to path_covariance as the
/// sample rate grows, with an O(1/f^2) difference (midpoint-rule error of the noise integral)
/// when keyframes fall on sample boundaries. A sample that straddles a keyframe at which a
/// wheel reverses has noise k^2 |net increment| (SPEC noise model), an O(1/f) difference.
/// Returns the world-frame covariance at the end of the path.
Matrix3 sampled_covariance(const Path& path, const Robot& robot);

/// d(arc_displacement)/d(angle, center), rotated into the end frame of the sample.
Matrix32 arc_increment_jacobian(double center_m, double angle_rad);

}  // namespace odomcov
