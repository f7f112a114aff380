// The transcendental functions of one arc's heading change a, computed once per piece and shared
// by every per-piece formula (arc_transition, arc_displacement, arc_noise_covariance,
// arc_input_gain, the noise-induced mean): the engine's inner loop pays one evaluation per piece
// instead of one per formula.
//
// Small pieces (|a| < kArcPolynomialBelow: every per-sample piece of a logged run) take the same
// Taylor series as series.hpp, with their coefficients precomputed so that no division and no
// libm call is left (the coefficients differ from series.hpp's divisions by at most an ulp each,
// so the two agree to a few ulp); there cos a = 1 - (a^2/2) sinc^2(a/2) and sin a = a sinc a,
// which are exact identities and cancel nothing for small a. Larger pieces use series.hpp and
// libm as before.
#pragma once

#include <array>
#include <cmath>
#include <complex>

#include "odomcov/closed_form/closed_form.hpp"
#include "base/series.hpp"

namespace odomcov::detail {

/// Below this |a| the polynomials serve. All their arguments then lie inside the ranges where
/// series.hpp itself uses the same series (sinc(2a): |2a| < kSincLongSeriesBelow; u3(2a):
/// |2a| < 0.25; a4(a): |a| < 0.125) with the same number of terms.
inline constexpr double kArcPolynomialBelow = 0.5 * series::kSincLongSeriesBelow;

namespace arc_poly {

/// Coefficients c_k of sinc(x) = 1 - x^2 c_1 (1 - x^2 c_2 (... (1 - x^2 c_7))), c_k = 1/((2k)(2k+1)).
inline constexpr std::array<double, 8> kSinc = [] {
  std::array<double, 8> c{};
  for (int k = 1; k <= 7; ++k) c[k] = 1.0 / ((2.0 * k) * (2.0 * k + 1.0));
  return c;
}();
/// u3(y) = (1/6) (1 - y^2 c_0 (1 - y^2 c_1 (...))), c_k = 1/((2k+4)(2k+5)), 7 terms (series.hpp).
inline constexpr std::array<double, 6> kU3 = [] {
  std::array<double, 6> c{};
  for (int k = 0; k <= 5; ++k) c[k] = 1.0 / ((2.0 * k + 4.0) * (2.0 * k + 5.0));
  return c;
}();
/// a4(x) = sum_{n=2..8} t_n x^(2n-4), t_n = (-1)^n (2^(2n-1) - 2)/(2n+1)! (series.hpp, 7 terms).
inline constexpr std::array<double, 7> kA4 = [] {
  std::array<double, 7> t{};
  double factorial = 120.0, pow2 = 8.0;
  for (int i = 0; i < 7; ++i) {
    const int n = i + 2;
    t[i] = ((n % 2 == 0) ? 1.0 : -1.0) * (pow2 - 2.0) / factorial;
    factorial *= (2.0 * n + 2.0) * (2.0 * n + 3.0);
    pow2 *= 4.0;
  }
  return t;
}();

/// The series through x^(2 Terms) (sinc: Terms <= 7), u3 through y^(2 (Terms - 1)) (<= 7),
/// a4 through x^(2 (Terms - 1)) (<= 7).
template <int Terms = 7>
inline double sinc(double x2) {
  double sum = 1.0;
  for (int k = Terms; k >= 1; --k) sum = 1.0 - x2 * kSinc[k] * sum;
  return sum;
}
template <int Terms = 7>
inline double u3(double y2) {
  double sum = 1.0;
  for (int k = Terms - 2; k >= 0; --k) sum = 1.0 - y2 * kU3[k] * sum;
  return sum * (1.0 / 6.0);
}
template <int Terms = 7>
inline double a4(double x2) {
  double sum = kA4[Terms - 1];
  for (int i = Terms - 2; i >= 0; --i) sum = kA4[i] + x2 * sum;
  return sum;
}

/// Below this |a| (most per-sample pieces) shorter series serve: sinc through x^6 at arguments
/// up to 2|a| = 0.04 (first term left out 0.04^8/9! < 2e-17), u3 through y^6 (left out
/// 6 0.04^8/11! < 1e-18 of it) and a4 through x^6 at |a| (left out < 2e-19 of it).
inline constexpr double kShortSeriesBelow = 0.02;

}  // namespace arc_poly

/// What the displacement and the transition need: sinc a, sinc(a/2), cos a and sin a.
struct ArcStep {
  double angle = 0.0;
  double sinc1 = 1.0, sinc_half = 1.0;
  double cos1 = 1.0, sin1 = 0.0;

  ArcStep() = default;
  explicit ArcStep(double a) : angle(a) {
    if (std::abs(a) < arc_poly::kShortSeriesBelow) {
      const double a2 = a * a;
      sinc1 = arc_poly::sinc<3>(a2);
      sinc_half = arc_poly::sinc<3>(0.25 * a2);
      cos1 = 1.0 - 0.5 * a2 * sinc_half * sinc_half;
      sin1 = a * sinc1;
    } else if (std::abs(a) < kArcPolynomialBelow) {
      const double a2 = a * a;
      sinc1 = arc_poly::sinc(a2);
      sinc_half = arc_poly::sinc(0.25 * a2);
      cos1 = 1.0 - 0.5 * a2 * sinc_half * sinc_half;
      sin1 = a * sinc1;
    } else {
      sinc1 = series::sinc(a);
      sinc_half = series::sinc(0.5 * a);
      cos1 = std::cos(a);
      sin1 = std::sin(a);
    }
  }
  /// The piece's end pose in its start frame (arc_displacement).
  double chord_x(double d) const { return d * sinc1; }
  double chord_y(double d) const { return 0.5 * d * angle * sinc_half * sinc_half; }
  /// The same with a lateral slip l to the left, spread along the arc as the travel is: the
  /// displacement is (d + i l) U(a), U(a) = sinc a + i (a/2) sinc^2(a/2) (Systematic, effects).
  double chord_x(double d, double l) const { return chord_x(d) - chord_y(l); }
  double chord_y(double d, double l) const { return chord_y(d) + chord_x(l); }
};

/// Everything the noise covariance and the input gain need besides: sinc(2a), u3(a), u3(2a), a4(a).
struct ArcFunctions : ArcStep {
  double sinc2 = 1.0, u3_1 = 1.0 / 6.0, u3_2 = 1.0 / 6.0, a4_1 = 1.0 / 20.0;

  explicit ArcFunctions(double a) : ArcStep(a) {
    if (std::abs(a) < arc_poly::kShortSeriesBelow) {
      const double a2 = a * a;
      sinc2 = arc_poly::sinc<3>(4.0 * a2);
      u3_1 = arc_poly::u3<4>(a2);
      u3_2 = arc_poly::u3<4>(4.0 * a2);
      a4_1 = arc_poly::a4<4>(a2);
    } else if (std::abs(a) < kArcPolynomialBelow) {
      const double a2 = a * a;
      sinc2 = arc_poly::sinc(4.0 * a2);
      u3_1 = arc_poly::u3(a2);
      u3_2 = arc_poly::u3(4.0 * a2);
      a4_1 = arc_poly::a4(a2);
    } else {
      sinc2 = series::sinc(2.0 * a);
      u3_1 = series::u3(a);
      u3_2 = series::u3(2.0 * a);
      a4_1 = series::a4(a);
    }
  }
};

/// x y for complex numbers, without std::complex's recovery of NaN products (its check costs a
/// branch per product in the inner loops; finite inputs give the same value).
inline std::complex<double> times(std::complex<double> x, std::complex<double> y) {
  return {x.real() * y.real() - x.imag() * y.imag(), x.real() * y.imag() + x.imag() * y.real()};
}

/// e^{i x}; for |x| <= kUnitPolynomialBelow from the polynomials (sin x = x sinc x,
/// cos x = 1 - (x^2/2) sinc^2(x/2); the sinc series' first term left out is below 1e-24 there).
inline constexpr double kUnitPolynomialBelow = 0.25;
inline std::complex<double> unit_complex(double x) {
  if (std::abs(x) <= kUnitPolynomialBelow) {
    const double x2 = x * x;
    const double sinc_half = arc_poly::sinc(0.25 * x2);
    return {1.0 - 0.5 * x2 * sinc_half * sinc_half, x * arc_poly::sinc(x2)};
  }
  return {std::cos(x), std::sin(x)};
}

/// The closed-form kernels (closed_form.hpp) from precomputed functions of the angle.
Vector3 arc_displacement(double center_m, const ArcStep& f);
Matrix3 arc_transition(double center_m, const ArcStep& f);
Matrix3 arc_noise_covariance(double center_m, const ArcFunctions& f, const Matrix2& intensity);
Matrix32 arc_input_gain(double center_m, const ArcFunctions& f);

/// The same kernels for a piece that also slips l [m] to the left (effects' lateral slip): its
/// displacement in its start frame is (d + i l) U(a), so the heading noise at a point of the
/// piece rotates the rest of the lateral slip with the rest of the travel. With l = 0 each is
/// the kernel above, bit for bit.
///  * arc_transition: third column i e^{-ia} (d + i l) U(a) = (chord_y(d) - chord_x(l),
///    chord_x(d) + chord_y(l)) in the end frame.
///  * arc_noise_covariance: with w the fraction of the piece still to go, the end error per unit
///    heading noise is (a_d(w) - b_l(w), b_d(w) + a_l(w)) with a_x(w) = x (1 - cos aw)/a and
///    b_x(w) = x sin(aw)/a (Psi of [Kleeman95, eq. (40)] for x = d; for the slip, -i l e^{-ia}
///    int_v^1 e^{iau} du); the along-track column (cos aw, -sin aw) is unchanged.
///  * arc_input_gain: 3 x 3, columns (e_dtheta, e_d, e_lat) spread uniformly over the piece:
///    the first two as above, integrated, and the slip's (int sin, int cos, 0).
Vector3 arc_displacement(double center_m, double lateral_m, const ArcStep& f);
Matrix3 arc_transition(double center_m, double lateral_m, const ArcStep& f);
Matrix3 arc_noise_covariance(double center_m, double lateral_m, const ArcFunctions& f,
                             const Matrix2& intensity);
Matrix3 arc_input_gain(double center_m, double lateral_m, const ArcFunctions& f);

}  // namespace odomcov::detail
