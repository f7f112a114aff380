#include "odomcov/closed_form/closed_form.hpp"

#include <algorithm>
#include <cmath>

#include "closed_form/arc_functions.hpp"
#include "base/series.hpp"

namespace odomcov {
namespace {

/// The integrals of Psi(v) entries over v in [0, 1] that build Q_tan, with
/// a(v) = d(1 - cos av)/a, b(v) = d sin(av)/a, c(v) = cos av, s(v) = sin av.
/// Each is written so that no entry cancels (see series.hpp):
///   int c   = sinc a                       int s   = (a/2) sinc^2(a/2)
///   int c^2 = (1 + sinc 2a)/2              int s^2 = 2 a^2 u3(2a)
///   int cs  = (a/2) sinc^2 a
///   int a   = d a u3(a)                    int b   = d sinc^2(a/2)/2
///   int a^2 = d^2 a^2 a4(a)                int b^2 = 2 d^2 u3(2a)
///   int ab  = d^2 (a/8) sinc^4(a/2)
///   int ac  = d a (2 u3(2a) - u3(a))       int as  = d (a^2/8) sinc^4(a/2)
///   int bc  = d sinc^2(a)/2                int bs  = 2 d a u3(2a)
/// (int ac = d (4 sin a - 2a - sin 2a)/(4a^2); 2 u3(2a) - u3(a) only cancels at its true zero.)
struct ArcIntegrals {
  double c, s, cc, ss, cs;        // independent of d
  double a, b, aa, bb, ab;        // per power of d already applied
  double ac, as, bc, bs;

  ArcIntegrals(double d, const detail::ArcFunctions& f) {
    const double x = f.angle;
    const double sinc1 = f.sinc1;
    const double sinc2 = f.sinc2;
    const double sinc_half2 = f.sinc_half * f.sinc_half;
    const double u3_1 = f.u3_1;
    const double u3_2 = f.u3_2;
    c = sinc1;
    s = 0.5 * x * sinc_half2;
    cc = 0.5 * (1.0 + sinc2);
    ss = 2.0 * x * x * u3_2;
    cs = 0.5 * x * sinc1 * sinc1;
    a = d * x * u3_1;
    b = 0.5 * d * sinc_half2;
    aa = d * d * x * x * f.a4_1;
    bb = 2.0 * d * d * u3_2;
    ab = d * d * 0.125 * x * sinc_half2 * sinc_half2;
    ac = d * x * (2.0 * u3_2 - u3_1);
    as = d * 0.125 * x * x * sinc_half2 * sinc_half2;
    bc = 0.5 * d * sinc1 * sinc1;
    bs = 2.0 * d * x * u3_2;
  }
};

}  // namespace

namespace detail {

Vector3 arc_displacement(double center_m, const ArcStep& f) {
  return {f.chord_x(center_m), f.chord_y(center_m), f.angle};
}

Matrix3 arc_transition(double center_m, const ArcStep& f) {
  const double c = f.cos1;
  const double s = f.sin1;
  // Third column: how far the end point moves, in the end frame, per unit start heading error:
  // (R(1 - cos a), R sin a) = (d a sinc^2(a/2)/2, d sinc a) = (chord y, chord x).
  Matrix3 phi;
  phi << c, s, f.chord_y(center_m),  //
      -s, c, f.chord_x(center_m),    //
      0.0, 0.0, 1.0;
  return phi;
}

Vector3 arc_displacement(double center_m, double lateral_m, const ArcStep& f) {
  if (lateral_m == 0.0) return arc_displacement(center_m, f);
  return {f.chord_x(center_m, lateral_m), f.chord_y(center_m, lateral_m), f.angle};
}

Matrix3 arc_transition(double center_m, double lateral_m, const ArcStep& f) {
  Matrix3 phi = arc_transition(center_m, f);
  if (lateral_m != 0.0) {
    phi(0, 2) -= f.chord_x(lateral_m);
    phi(1, 2) += f.chord_y(lateral_m);
  }
  return phi;
}

}  // namespace detail

Vector3 arc_displacement(double center_m, double angle_rad) {
  return detail::arc_displacement(center_m, detail::ArcStep(angle_rad));
}

Matrix3 arc_transition(double center_m, double angle_rad) {
  return detail::arc_transition(center_m, detail::ArcStep(angle_rad));
}

Eigen::Vector2d wheel_variances(const ArcSegment& seg, const WheelNoise& k) {
  return {k.k_left * k.k_left * std::abs(seg.left_m), k.k_right * k.k_right * std::abs(seg.right_m)};
}

Matrix2 wheel_noise_intensity(const ArcSegment& seg, double wheelbase_m, const WheelNoise& k) {
  const Eigen::Vector2d var = wheel_variances(seg, k);
  const double var_l = var.x();
  const double var_r = var.y();
  Matrix2 n;
  n(0, 0) = (var_l + var_r) / (wheelbase_m * wheelbase_m);
  n(0, 1) = n(1, 0) = (var_r - var_l) / (2.0 * wheelbase_m);
  n(1, 1) = 0.25 * (var_l + var_r);
  return n;
}

namespace detail {

Matrix3 arc_noise_covariance(double center_m, const ArcFunctions& f, const Matrix2& intensity) {
  const ArcIntegrals I(center_m, f);
  const double q11 = intensity(0, 0);
  const double q12 = 0.5 * (intensity(0, 1) + intensity(1, 0));
  const double q22 = intensity(1, 1);
  Matrix3 q;
  q(0, 0) = q11 * I.aa + 2.0 * q12 * I.ac + q22 * I.cc;
  q(0, 1) = q11 * I.ab + q12 * (I.bc - I.as) - q22 * I.cs;
  q(0, 2) = q11 * I.a + q12 * I.c;
  q(1, 1) = q11 * I.bb - 2.0 * q12 * I.bs + q22 * I.ss;
  q(1, 2) = q11 * I.b - q12 * I.s;
  q(2, 2) = q11;
  q(1, 0) = q(0, 1);
  q(2, 0) = q(0, 2);
  q(2, 1) = q(1, 2);
  return q;
}

Matrix32 arc_input_gain(double center_m, const ArcFunctions& f) {
  const ArcIntegrals I(center_m, f);
  Matrix32 g;
  g << I.a, I.c, I.b, -I.s, 1.0, 0.0;
  return g;
}

namespace {

/// The integrals of the heading column (A_x, A_y) = (a_d - b_l, b_d + a_l) of a piece with a
/// lateral slip l (arc_functions.hpp), from the unit integrals U (d = 1): a_x = x a_1 etc.
struct LateralIntegrals {
  double x, y;              // int A_x, int A_y
  double xx, yy, xy;        // int A_x^2, int A_y^2, int A_x A_y
  double xc, yc, xs, ys;    // int A_x cos, int A_y cos, int A_x sin, int A_y sin
  LateralIntegrals(double d, double l, const ArcIntegrals& U) {
    x = d * U.a - l * U.b;
    y = d * U.b + l * U.a;
    xx = d * d * U.aa - 2.0 * d * l * U.ab + l * l * U.bb;
    yy = d * d * U.bb + 2.0 * d * l * U.ab + l * l * U.aa;
    xy = (d * d - l * l) * U.ab + d * l * (U.aa - U.bb);
    xc = d * U.ac - l * U.bc;
    yc = d * U.bc + l * U.ac;
    xs = d * U.as - l * U.bs;
    ys = d * U.bs + l * U.as;
  }
};

}  // namespace

Matrix3 arc_noise_covariance(double center_m, double lateral_m, const ArcFunctions& f,
                             const Matrix2& intensity) {
  if (lateral_m == 0.0) return arc_noise_covariance(center_m, f, intensity);
  const ArcIntegrals U(1.0, f);
  const LateralIntegrals L(center_m, lateral_m, U);
  const double q11 = intensity(0, 0);
  const double q12 = 0.5 * (intensity(0, 1) + intensity(1, 0));
  const double q22 = intensity(1, 1);
  Matrix3 q;
  q(0, 0) = q11 * L.xx + 2.0 * q12 * L.xc + q22 * U.cc;
  q(0, 1) = q11 * L.xy + q12 * (L.yc - L.xs) - q22 * U.cs;
  q(0, 2) = q11 * L.x + q12 * U.c;
  q(1, 1) = q11 * L.yy - 2.0 * q12 * L.ys + q22 * U.ss;
  q(1, 2) = q11 * L.y - q12 * U.s;
  q(2, 2) = q11;
  q(1, 0) = q(0, 1);
  q(2, 0) = q(0, 2);
  q(2, 1) = q(1, 2);
  return q;
}

Matrix3 arc_input_gain(double center_m, double lateral_m, const ArcFunctions& f) {
  Matrix3 g;
  if (lateral_m == 0.0) {
    const ArcIntegrals I(center_m, f);
    g << I.a, I.c, I.s, I.b, -I.s, I.c, 1.0, 0.0, 0.0;
    return g;
  }
  const ArcIntegrals U(1.0, f);
  const LateralIntegrals L(center_m, lateral_m, U);
  g << L.x, U.c, U.s, L.y, -U.s, U.c, 1.0, 0.0, 0.0;
  return g;
}

}  // namespace detail

Matrix3 arc_noise_covariance(double center_m, double angle_rad, const Matrix2& intensity) {
  return detail::arc_noise_covariance(center_m, detail::ArcFunctions(angle_rad), intensity);
}

Matrix32 arc_input_gain(double center_m, double angle_rad) {
  return detail::arc_input_gain(center_m, detail::ArcFunctions(angle_rad));
}

Matrix3 arc_covariance(const ArcSegment& seg, double wheelbase_m, const WheelNoise& k) {
  return arc_noise_covariance(seg.center_m(), seg.heading_change_rad(wheelbase_m),
                              wheel_noise_intensity(seg, wheelbase_m, k));
}

Matrix3 propagate_arc(const Matrix3& P_start_tangential, const ArcSegment& seg,
                      double wheelbase_m, const WheelNoise& k) {
  const Matrix3 phi = arc_transition(seg.center_m(), seg.heading_change_rad(wheelbase_m));
  return phi * P_start_tangential * phi.transpose() + arc_covariance(seg, wheelbase_m, k);
}

Matrix3 line_covariance(double distance_m, double wheelbase_m, const WheelNoise& k) {
  const double d = distance_m;
  const double B = wheelbase_m;
  const double sum = k.k_right * k.k_right + k.k_left * k.k_left;
  const double diff = k.k_right * k.k_right - k.k_left * k.k_left;
  Matrix3 q;
  q << sum / 4.0, d * diff / (4.0 * B), diff / (2.0 * B),  //
      d * diff / (4.0 * B), d * d * sum / (3.0 * B * B), d * sum / (2.0 * B * B),  //
      diff / (2.0 * B), d * sum / (2.0 * B * B), sum / (B * B);
  return std::abs(d) * q;
}

Matrix3 turn_covariance(double angle_rad, double wheelbase_m, const WheelNoise& k) {
  const double a = std::abs(angle_rad);
  const double B = wheelbase_m;
  const double sum = k.k_left * k.k_left + k.k_right * k.k_right;
  const double diff = k.k_right * k.k_right - k.k_left * k.k_left;
  Matrix3 major_minor = Matrix3::Zero();
  major_minor(0, 0) = B * sum * std::abs(a + std::sin(a)) / 16.0;  // eq. (20)
  major_minor(1, 1) = B * sum * std::abs(a - std::sin(a)) / 16.0;  // eq. (22), see header
  major_minor(2, 2) = a * sum / (2.0 * B);                         // eq. (17)
  major_minor(0, 2) = major_minor(2, 0) = diff * std::sin(a / 2.0) / 2.0;  // eq. (26)
  // The major axis lies at start heading + angle/2 = end heading - angle/2.
  return tangential_to_world(major_minor, -0.5 * angle_rad);
}

Matrix3 world_from_tangential(double heading_rad) {
  const double c = std::cos(heading_rad);
  const double s = std::sin(heading_rad);
  Matrix3 t;
  t << c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0;
  return t;
}

Matrix3 tangential_to_world(const Matrix3& P_tangential, double heading_rad) {
  const Matrix3 t = world_from_tangential(heading_rad);
  const Matrix3 p = t * P_tangential * t.transpose();
  return 0.5 * (p + p.transpose());  // symmetric to the last bit, as a covariance must print
}

ErrorEllipse error_ellipse(const Matrix3& P_world) {
  const double p = P_world(0, 0);
  const double q = P_world(1, 1);
  const double r = 0.5 * (P_world(0, 1) + P_world(1, 0));
  const double mid = 0.5 * (p + q);
  const double radius = std::hypot(0.5 * (p - q), r);
  ErrorEllipse e;
  e.semi_major_m = std::sqrt(std::max(0.0, mid + radius));
  e.semi_minor_m = std::sqrt(std::max(0.0, mid - radius));
  double angle = 0.5 * std::atan2(2.0 * r, p - q);  // in (-pi/2, pi/2]
  if (angle <= -0.5 * M_PI) angle += M_PI;
  e.angle_rad = angle;
  return e;
}

Matrix32 arc_increment_jacobian(double center_m, double angle_rad) {
  // g(d, a) = (d sinc a, d (1 - cos a)/a, a) in the start frame of the sample.
  //   dg/dd = (sinc a, (1 - cos a)/a, 0) = (sinc a, (a/2) sinc^2(a/2), 0)
  //   dg/da = (d sinc'(a), d [(1 - cos a)/a]', 1) with, free of cancellation,
  //     sinc'(a)           = (cos a - sinc a)/a = a (u3(a) - sinc^2(a/2)/2)
  //     [(1 - cos a)/a]'   = sinc a - sinc^2(a/2)/2
  const double a = angle_rad;
  const double d = center_m;
  const double sinc_a = series::sinc(a);
  const double sinc_half = series::sinc(0.5 * a);
  const double half_sinc2 = 0.5 * sinc_half * sinc_half;
  Eigen::Matrix<double, 2, 2> j_start;  // columns: d/da, d/dd; rows: x, y in the start frame
  j_start << d * a * (series::u3(a) - half_sinc2), sinc_a,  //
      d * (sinc_a - half_sinc2), a * half_sinc2;
  const double c = std::cos(a);
  const double s = std::sin(a);
  Eigen::Matrix2d end_from_start;
  end_from_start << c, s, -s, c;
  Matrix32 j;
  j.topRows<2>() = end_from_start * j_start;
  j.row(2) << 1.0, 0.0;
  return j;
}

}  // namespace odomcov
