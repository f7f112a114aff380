// Closed-form odometry error covariance of one constant-curvature segment.
//
// Frames and signs ([Kleeman95] §3-§5; errata in docs/conventions.md):
//   * tangential error e = (s, p, theta): s along the heading at the END of the segment,
//     p to its left, theta counter-clockwise; error = true pose - odometry pose.
//   * a segment is described by its wheel travels (left_m, right_m) and the wheelbase B, or
//     equivalently by its centre travel d = (left+right)/2 and heading change a = (right-left)/B.
//     The arc radius R = d/a is never formed, so lines (a -> 0, R -> infinity) and turns on the
//     spot (d = 0, R = 0) are ordinary points of the same formulas.
//   * P_end = Phi P_start Phi^T + Q, all tangential; P_world = T(theta) P_tan T(theta)^T with
//     theta the heading at the end of the segment [erratum 5: T(+theta), not T(-theta)].
#pragma once

#include <Eigen/Core>

namespace odomcov {

using Vector3 = Eigen::Vector3d;
using Matrix2 = Eigen::Matrix2d;
using Matrix3 = Eigen::Matrix3d;
using Matrix32 = Eigen::Matrix<double, 3, 2>;

/// Wheel travel of one constant-curvature segment (signed; negative means backwards).
struct ArcSegment {
  double left_m = 0.0;
  double right_m = 0.0;

  double center_m() const { return 0.5 * (left_m + right_m); }
  double heading_change_rad(double wheelbase_m) const { return (right_m - left_m) / wheelbase_m; }
};

/// Per-wheel noise constants of [Kleeman95, eq. (1)]: var = k^2 |travel|, k in m^(1/2).
struct WheelNoise {
  double k_left = 0.0;
  double k_right = 0.0;
};

/// End pose of a segment in its start frame: (d sinc a, d (1 - cos a)/a, a).
/// This is the exact arc (constant-curvature) update of [Chong97, eq. (13)].
Vector3 arc_displacement(double center_m, double angle_rad);

/// Phi of [Kleeman95, eq. (36)]: maps the start error (tangential at the start) to the end error
/// (tangential at the end):
///   [ cos a   sin a   R(1 - cos a) ]        R(1 - cos a) = d (1 - cos a)/a
///   [-sin a   cos a   R sin a      ]        R sin a      = d sinc a
///   [   0       0         1        ]
Matrix3 arc_transition(double center_m, double angle_rad);

/// The wheel-error variances (left, right) of one piece under the model of [Kleeman95]: each
/// wheel's error has variance k^2 |travel|. The one place this law is written (the closed form,
/// the engine and the simulator all use it).
Eigen::Vector2d wheel_variances(const ArcSegment& seg, const WheelNoise& k);

/// Noise intensity of [Kleeman95, eq. (38)] over the whole segment: the covariance of
/// (e_dtheta, e_d) = ((e_R - e_L)/B, (e_L + e_R)/2) accumulated over the segment, for
/// independent wheel errors of variance k^2 |travel|:
///   [ (kL^2|L| + kR^2|R|)/B^2        (kR^2|R| - kL^2|L|)/(2B) ]
///   [ (kR^2|R| - kL^2|L|)/(2B)       (kL^2|L| + kR^2|R|)/4    ]
Matrix2 wheel_noise_intensity(const ArcSegment& seg, double wheelbase_m, const WheelNoise& k);

/// The general integral  Q_tan = int_0^1 Psi(v) N Psi(v)^T dv  of [Kleeman95, eq. (40)], where N
/// is the segment's noise intensity (any symmetric 2x2, e.g. wheel_noise_intensity) spread
/// uniformly along the segment, v is the fraction of the segment still to go and
///   Psi(v) = [ d (1 - cos av)/a    cos av ]      [erratum 1: -sin in the second row]
///            [ d sin(av)/a        -sin av ]
///            [ 1                   0      ]
/// Written with d = R a instead of R this is [Kleeman95, eq. (41)] divided through by a (with
/// erratum 2 in rho_sp) and also [Chong97, eq. (17)]. Every entry is a product of sinc and the
/// two series kernels of series.hpp, so the result is accurate to a few ulp for all (d, a),
/// including the line limit a -> 0 and the turn on the spot d = 0.
Matrix3 arc_noise_covariance(double center_m, double angle_rad, const Matrix2& intensity);

/// int_0^1 Psi(v) dv: the end error caused by a (e_dtheta, e_d) spread uniformly over the segment.
/// Used for per-run constant errors (e.g. a wheel radius error), whose effect is first order.
Matrix32 arc_input_gain(double center_m, double angle_rad);

/// d(arc_displacement)/d(angle, center) of [Chong97, eq. (13)], rotated into the end frame of the
/// segment: columns (d/d angle [m/rad, m/rad, 1], d/d center [1, 1, 0]), rows (s, p, theta)
/// tangential at the end. The first-order input gain of the discrete (per-sample) update
/// [Wang88]; free of cancellation for all (d, a) through sinc and the u3 kernel.
Matrix32 arc_increment_jacobian(double center_m, double angle_rad);

/// Q of one segment with independent wheel noise: arc_noise_covariance(wheel_noise_intensity).
Matrix3 arc_covariance(const ArcSegment& seg, double wheelbase_m, const WheelNoise& k);

/// P_end = Phi P_start Phi^T + Q for one segment (tangential frames at start and end).
Matrix3 propagate_arc(const Matrix3& P_start_tangential, const ArcSegment& seg, double wheelbase_m,
                      const WheelNoise& k);

/// Q_line(d) of [Kleeman95, §6], a literal transcription (with errata 3 and 4 in eqs. (13), (15)):
///   |d| [ (kR^2+kL^2)/4        d(kR^2-kL^2)/(4B)      (kR^2-kL^2)/(2B)  ]
///       [ d(kR^2-kL^2)/(4B)    d^2(kR^2+kL^2)/(3B^2)  d(kR^2+kL^2)/(2B^2) ]
///       [ (kR^2-kL^2)/(2B)     d(kR^2+kL^2)/(2B^2)    (kR^2+kL^2)/B^2     ]
/// d < 0 is backwards motion. Phi_line(d) = arc_transition(d, 0).
Matrix3 line_covariance(double distance_m, double wheelbase_m, const WheelNoise& k);

/// Turn on the spot through `angle_rad` (CCW positive), [Kleeman95, §4], in the tangential frame
/// at the end heading. The paper's major/minor axes sit at -a/2 from the end heading:
///   var_M  = B (kL^2+kR^2) |a + sin a| / 16                    eq. (20)
///   var_m  = B (kL^2+kR^2) |a - sin a| / 16                    eq. (22) (see note)
///   var_a  = |a| (kL^2+kR^2) / (2B)                            eq. (17)
///   cov_aM = (kR^2-kL^2) sin(|a|/2) / 2,  cov_Mm = cov_am = 0  eqs. (24), (26), (27)
/// Note: eq. (22) as printed lacks the factor 1/4 of eq. (19); the value above is the one that
/// reproduces Table I ("B to C" eigenvalues 0.0357e-6 and 0.1607e-6).
Matrix3 turn_covariance(double angle_rad, double wheelbase_m, const WheelNoise& k);

/// T(theta) of [Kleeman95, eq. (42)]: rotates tangential (s, p, theta) into world (x, y, theta).
Matrix3 world_from_tangential(double heading_rad);

/// P_world = T(theta) P_tan T(theta)^T [Kleeman95, eq. (43) with erratum 5].
Matrix3 tangential_to_world(const Matrix3& P_tangential, double heading_rad);

/// One-sigma x-y error ellipse of a world covariance: semi-axes a >= b and the angle of the
/// a axis from +x, in (-pi/2, pi/2].
struct ErrorEllipse {
  double semi_major_m = 0.0;
  double semi_minor_m = 0.0;
  double angle_rad = 0.0;
};
ErrorEllipse error_ellipse(const Matrix3& P_world);

}  // namespace odomcov
