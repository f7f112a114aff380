// The closed-form arc covariance against: the paper's own formulas (line, turn, eq. (41) with its
// errata), an independent numerical quadrature of eq. (40), and first-order perturbation checks
// of Phi and of the input gain. Consistency (splitting a path) is in propagation_test.cpp.
#include "odomcov/closed_form/closed_form.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>
#include <random>

#include "odomcov/closed_form/path.hpp"
#include "base/quadrature.hpp"
#include "closed_form/arc_functions.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

using test::max_rel_diff;

/// [Kleeman95, eq. (41)] as the MATLAB arc_cov listing writes it (erratum 2 in C(1,2), erratum 6
/// for the scaling and the sign), in terms of R and a. Loses digits as a -> 0, so the tests use
/// it only for |a| >= 0.3.
Matrix3 kleeman_arc_cov(double dl, double dr, const WheelNoise& k, double B) {
  const double R = B * (dr + dl) / 2.0 / (dr - dl);
  const double a = (dr - dl) / B;
  const double kRsr = std::abs(B * dr / (dr - dl) * k.k_right * k.k_right);
  const double kRsl = std::abs(B * dl / (dr - dl) * k.k_left * k.k_left);
  const double ksum = kRsr + kRsl;
  const double kdiff = kRsr - kRsl;
  Matrix3 C;
  C(0, 0) = ksum * R * R / B / B * (3 * a / 2 - 2 * std::sin(a) + std::sin(2 * a) / 4) +
            ksum / 4 * (a / 2 + std::sin(2 * a) / 4) +
            kdiff * R / B * (std::sin(a) - a / 2 - std::sin(2 * a) / 4);
  C(0, 1) = ksum * (R * R / B / B * (3 - 4 * std::cos(a) + std::cos(2 * a)) / 4 +
                    (std::cos(2 * a) - 1) / 16) +
            kdiff * R / 4 / B * (2 * std::cos(a) - std::cos(2 * a) - 1);
  C(0, 2) = ksum * R / B / B * (a - std::sin(a)) + kdiff * std::sin(a) / 2 / B;
  C(1, 1) = (a / 2 - std::sin(2 * a) / 4) * (ksum * (R * R / B / B + 0.25) - kdiff * R / B);
  C(1, 2) = (ksum * R / B / B - kdiff / 2 / B) * (1 - std::cos(a));
  C(2, 2) = ksum / B / B * a;
  C(1, 0) = C(0, 1);
  C(2, 0) = C(0, 2);
  C(2, 1) = C(1, 2);
  return a < 0 ? Matrix3(-C) : C;
}

/// int_0^1 Psi(v) N Psi(v)^T dv by composite Gauss-Legendre, with Psi built from std::sin/cos
/// directly as printed in eq. (36) (erratum 1) with R a = d.
Matrix3 quadrature_noise_covariance(double d, double a, const Matrix2& N) {
  static const auto rule = gauss_legendre_01<20>();
  const int panels = 64;
  Matrix3 sum = Matrix3::Zero();
  for (int p = 0; p < panels; ++p) {
    for (const auto& [x, w] : rule) {
      const double v = (p + x) / panels;
      const double av = a * v;
      // d (1 - cos av)/a and d sin(av)/a, taking the a -> 0 limit exactly when a == 0; the
      // pointwise 1 - cos = 2 sin^2(av/2) keeps the oracle itself accurate for tiny a.
      const double half_sin = std::sin(0.5 * av);
      const double first = a == 0.0 ? 0.0 : 2.0 * d * half_sin * half_sin / a;
      const double second = a == 0.0 ? d * v : d * std::sin(av) / a;
      Matrix32 psi;
      psi << first, std::cos(av), second, -std::sin(av), 1.0, 0.0;
      sum += (w / panels) * psi * N * psi.transpose();
    }
  }
  return sum;
}

TEST(ClosedForm, ArcMatchesKleemanEq41) {
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int trial = 0; trial < 2000; ++trial) {
    const double B = 0.2 + u(rng);
    const WheelNoise k{1e-3 * (0.1 + u(rng)), 1e-3 * (0.1 + u(rng))};
    const double R = (u(rng) < 0.5 ? -1 : 1) * (0.01 + 3 * u(rng));
    const double a = (u(rng) < 0.5 ? -1 : 1) * (0.3 + 6 * u(rng));
    const ArcSegment seg{a * (R - B / 2), a * (R + B / 2)};
    const Matrix3 oracle = kleeman_arc_cov(seg.left_m, seg.right_m, k, B);
    EXPECT_LT(max_rel_diff(arc_covariance(seg, B, k), oracle), 1e-11)
        << "R = " << R << ", a = " << a;
  }
}

TEST(ClosedForm, LineLimitMatchesLineFormula) {
  // |dr - dl| = 1e-12: an arc of radius ~1e12 m. The issue asks for 1e-9 relative, entry by
  // entry; the cancellation-free form gives close to machine precision.
  for (double d : {-7.0, -0.3, 1e-3, 0.5, 2.0, 40.0}) {
    for (double skew : {1e-12, -1e-12, 1e-15, 0.0}) {
      const double B = 0.5;
      const WheelNoise k{1e-3, 2.5e-3};
      const ArcSegment seg{d - skew / 2, d + skew / 2};
      const Matrix3 arc = arc_covariance(seg, B, k);
      const Matrix3 line = line_covariance(d, B, k);
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          EXPECT_NEAR(arc(i, j), line(i, j), 1e-9 * std::abs(line(i, j)))
              << "d = " << d << ", skew = " << skew << ", entry " << i << j;
        }
      }
      EXPECT_LT(max_rel_diff(arc_transition(seg.center_m(), seg.heading_change_rad(B)),
                             arc_transition(d, 0.0)),
                1e-11);
    }
  }
}

TEST(ClosedForm, LineTransitionIsPhiLine) {
  Matrix3 phi_line = Matrix3::Identity();
  phi_line(1, 2) = 2.5;
  EXPECT_EQ(arc_transition(2.5, 0.0), phi_line);
}

TEST(ClosedForm, TurnOnTheSpotMatchesSection4) {
  // R = 0 (d = 0) and a vanishing R must both give [Kleeman95] §4.
  for (double a : {-4 * M_PI, -2.0, -M_PI / 2, 1e-3, 0.7, M_PI / 2, 3.0, 9.0}) {
    for (double B : {0.3, 0.5}) {
      const WheelNoise k{1e-3, 2e-3};
      const Matrix3 turn = turn_covariance(a, B, k);
      const ArcSegment spin{-a * B / 2, a * B / 2};
      EXPECT_LT(max_rel_diff(arc_covariance(spin, B, k), turn), 4e-15) << "a = " << a;
      const ArcSegment near_spin{-a * B / 2 + 1e-13, a * B / 2 + 1e-13};
      EXPECT_LT(max_rel_diff(arc_covariance(near_spin, B, k), turn), 1e-9) << "a = " << a;
    }
  }
}

TEST(ClosedForm, NoiseIntegralMatchesQuadrature) {
  // Independent route: eq. (40) integrated numerically (composite 20-point Gauss-Legendre, exact
  // to rounding for these smooth integrands), for random d, a and noise intensities.
  std::mt19937_64 rng(40);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 300; ++trial) {
    const double d = 5 * u(rng);
    const double a = trial % 3 == 0 ? 1e-3 * u(rng) : 4 * M_PI * u(rng);
    Eigen::Matrix2d L;
    L << u(rng), 0, u(rng), u(rng);
    const Matrix2 N = L * L.transpose();
    EXPECT_LT(max_rel_diff(arc_noise_covariance(d, a, N), quadrature_noise_covariance(d, a, N)),
              1e-13)
        << "d = " << d << ", a = " << a;
  }
  EXPECT_LT(max_rel_diff(arc_noise_covariance(2.0, 0.0, Matrix2::Identity()),
                         quadrature_noise_covariance(2.0, 0.0, Matrix2::Identity())),
            1e-14);
}

TEST(ClosedForm, NoJumpAcrossSeriesSwitches) {
  // The kernels switch at a = 2 (u3(a), a4(a)) and a = 1 (u3(2a)). Crossing a switch by one ulp
  // of a must change Q by no more than the smooth change over that step (~1e-16) plus rounding.
  const double B = 0.5;
  const WheelNoise k{1e-3, 3e-3};
  for (double a : {1.0, 2.0, -1.0, -2.0}) {
    for (double d : {-3.0, 0.0, 0.4, 10.0}) {
      const Matrix2 N = wheel_noise_intensity({d - a * B / 2, d + a * B / 2}, B, k);
      const Matrix3 at = arc_noise_covariance(d, a, N);
      const Matrix3 before = arc_noise_covariance(d, std::nextafter(a, 0.0), N);
      EXPECT_LT(max_rel_diff(before, at), 1e-14) << "a = " << a << ", d = " << d;
    }
  }
}

/// Tangential error of `actual` relative to `nominal`: (R(theta_nominal)^T dp, dtheta).
Vector3 tangential_error(const Vector3& actual, const Vector3& nominal) {
  Vector3 e;
  e.head<2>() = world_from_tangential(nominal.z()).topLeftCorner<2, 2>().transpose() *
                (actual - nominal).head<2>();
  e.z() = actual.z() - nominal.z();
  return e;
}

/// A first-order model is right when its residual is O(h^2): shrinking the perturbation 10x
/// must shrink the residual ~100x. We require >= 50x (the next order term can only reduce the
/// ratio below 100 by a factor 1 + O(h)), unless the residual is already at rounding level.
/// The residual is a difference of two poses of magnitude `pose_scale` (here <= ~7 m), each
/// computed with a few ulp of error, so the rounding floor is absolute, not relative to h:
/// 32 eps pose_scale. (A floor proportional to h held on x86-64 only because its libm's
/// sin/cos round the two drives alike; aarch64's do not.)
void expect_second_order_residual(double residual_h, double residual_h_over_10,
                                  double pose_scale) {
  const double rounding = 32 * std::numeric_limits<double>::epsilon() * pose_scale;
  if (residual_h < rounding) return;
  EXPECT_LT(residual_h_over_10, residual_h / 50.0 + rounding)
      << "residual " << residual_h << " -> " << residual_h_over_10;
}

TEST(ClosedForm, TransitionIsFirstOrderPerturbation) {
  // manif-style: perturb the start by w (tangential), drive the same wheel travel exactly, and
  // compare the end error with Phi w; the residual must be O(|w|^2).
  std::mt19937_64 rng(36);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double B = 0.5;
    const ArcSegment seg{3 * u(rng), 3 * u(rng)};
    const Vector3 start{u(rng), u(rng), M_PI * u(rng)};
    const Vector3 direction(u(rng), u(rng), u(rng));
    const Matrix3 phi = arc_transition(seg.center_m(), seg.heading_change_rad(B));
    auto residual = [&](double h) {
      const Vector3 w = h * direction;
      Vector3 perturbed = start;
      perturbed.head<2>() += world_from_tangential(start.z()).topLeftCorner<2, 2>() * w.head<2>();
      perturbed.z() += w.z();
      return (tangential_error(drive(perturbed, seg, B), drive(start, seg, B)) - phi * w).norm();
    };
    expect_second_order_residual(residual(1e-4), residual(1e-5), 7.0);
  }
}

TEST(ClosedForm, InputGainIsFirstOrderPerturbation) {
  // A relative scale error (eL, eR) on the wheels gives (dtheta, d) = ((R eR - L eL)/B,
  // (L eL + R eR)/2) spread along the segment; the end error is arc_input_gain times that.
  std::mt19937_64 rng(37);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double B = 0.4;
    const ArcSegment seg{3 * u(rng), 3 * u(rng)};
    const double dir_l = u(rng), dir_r = u(rng);
    const Vector3 nominal = drive(Vector3::Zero(), seg, B);
    const Matrix32 gain = arc_input_gain(seg.center_m(), seg.heading_change_rad(B));
    auto residual = [&](double h) {
      const double eps_l = h * dir_l, eps_r = h * dir_r;
      const Vector3 scaled =
          drive(Vector3::Zero(), {seg.left_m * (1 + eps_l), seg.right_m * (1 + eps_r)}, B);
      const Eigen::Vector2d input{(seg.right_m * eps_r - seg.left_m * eps_l) / B,
                                  0.5 * (seg.left_m * eps_l + seg.right_m * eps_r)};
      return (tangential_error(scaled, nominal) - gain * input).norm();
    };
    expect_second_order_residual(residual(1e-4), residual(1e-5), 7.0);
  }
}

TEST(ClosedForm, QIsSymmetricPositiveSemidefinite) {
  std::mt19937_64 rng(38);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 500; ++trial) {
    const double B = 0.5;
    const ArcSegment seg{5 * u(rng), 5 * u(rng)};
    const Matrix3 q = arc_covariance(seg, B, {1e-3 * std::abs(u(rng)), 1e-3 * std::abs(u(rng))});
    EXPECT_EQ(q, q.transpose());
    const Eigen::Vector3d eig = Eigen::SelfAdjointEigenSolver<Matrix3>(q).eigenvalues();
    EXPECT_GE(eig.minCoeff(), -1e-14 * eig.maxCoeff());
  }
}

TEST(ClosedForm, WorldTransformUsesPlusTheta) {
  // Erratum 5: a pure p (left) error at heading +90 deg is a -x error in the world.
  Matrix3 p_only = Matrix3::Zero();
  p_only(1, 1) = 1.0;
  p_only(1, 2) = p_only(2, 1) = 0.5;
  p_only(2, 2) = 1.0;
  const Matrix3 world = tangential_to_world(p_only, M_PI / 2);
  EXPECT_NEAR(world(0, 0), 1.0, 1e-15);
  EXPECT_NEAR(world(0, 2), -0.5, 1e-15);  // x-theta = -p-theta
  EXPECT_NEAR(world(1, 2), 0.0, 1e-15);
}

TEST(ClosedForm, ErrorEllipse) {
  Matrix3 p = Matrix3::Zero();
  // Axes 3 and 1 at +30 deg.
  const double c = std::cos(M_PI / 6), s = std::sin(M_PI / 6);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  p.topLeftCorner<2, 2>() = r * Eigen::Vector2d(9.0, 1.0).asDiagonal() * r.transpose();
  const ErrorEllipse e = error_ellipse(p);
  EXPECT_NEAR(e.semi_major_m, 3.0, 1e-14);
  EXPECT_NEAR(e.semi_minor_m, 1.0, 1e-14);
  EXPECT_NEAR(e.angle_rad, M_PI / 6, 1e-14);
  p.topLeftCorner<2, 2>() = Eigen::Vector2d(1.0, 4.0).asDiagonal();
  EXPECT_NEAR(error_ellipse(p).angle_rad, M_PI / 2, 1e-15);  // (-pi/2, pi/2]
}

// ---- Lateral slip (effects' Systematic::lateral): a piece of centre travel d, heading change a
// and lateral slip l moves by (d + i l) U(a), U(a) = (e^{ia} - 1)/(ia), in its start frame.

/// The piece's end pose in its start frame, straight from the definition (std::sin/cos).
Vector3 lateral_displacement(double d, double l, double a) {
  if (a == 0.0) return {d, l, 0.0};
  const double s = std::sin(a), c1 = 1.0 - std::cos(a);
  return {(d * s - l * c1) / a, (d * c1 + l * s) / a, a};
}

/// Q of a piece with a lateral slip by composite Gauss-Legendre: with v the fraction still to go,
/// the end error per unit heading noise is (a_d(v) - b_l(v), b_d(v) + a_l(v)), a_x(v) =
/// x (1 - cos av)/a, b_x(v) = x sin(av)/a, and per unit along-track noise (cos av, -sin av).
Matrix3 quadrature_lateral_covariance(double d, double l, double a, const Matrix2& N) {
  static const auto rule = gauss_legendre_01<20>();
  const int panels = 64;
  Matrix3 sum = Matrix3::Zero();
  for (int p = 0; p < panels; ++p) {
    for (const auto& [x, w] : rule) {
      const double v = (p + x) / panels, av = a * v;
      const double one_minus_cos = a == 0.0 ? 0.0 : 2.0 * std::sin(0.5 * av) * std::sin(0.5 * av) / a;
      const double sine = a == 0.0 ? v : std::sin(av) / a;
      Matrix32 psi;
      psi << d * one_minus_cos - l * sine, std::cos(av), d * sine + l * one_minus_cos, -std::sin(av), 1.0, 0.0;
      sum += (w / panels) * psi * N * psi.transpose();
    }
  }
  return sum;
}

TEST(ClosedFormLateral, ZeroSlipIsTheKernelsBitForBit) {
  std::mt19937_64 rng(60);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 100; ++trial) {
    const double d = 3 * u(rng), a = trial % 2 ? 1e-3 * u(rng) : 3 * u(rng);
    const detail::ArcFunctions f(a);
    const Matrix2 N = Matrix2::Identity() * (1 + u(rng) * u(rng));
    EXPECT_EQ(detail::arc_noise_covariance(d, 0.0, f, N), detail::arc_noise_covariance(d, f, N));
    EXPECT_EQ(detail::arc_transition(d, 0.0, f), detail::arc_transition(d, f));
    EXPECT_EQ(detail::arc_displacement(d, 0.0, f), detail::arc_displacement(d, f));
    const Matrix3 g = detail::arc_input_gain(d, 0.0, f);
    EXPECT_EQ(Matrix32(g.leftCols<2>()), detail::arc_input_gain(d, f));
  }
}

TEST(ClosedFormLateral, DisplacementIsTheDefinitionAndSplitsExactly) {
  // (d + i l) U(a): the kernel against the definition, and n equal parts composed give the
  // whole piece (the slip accumulates along the arc as the travel does).
  std::mt19937_64 rng(61);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double d = 3 * u(rng), l = 0.5 * u(rng), a = 4 * u(rng);
    const Vector3 whole = detail::arc_displacement(d, l, detail::ArcStep(a));
    EXPECT_LT((whole - lateral_displacement(d, l, a)).norm(), 1e-14 * (1 + std::abs(d) + std::abs(l)));
    const int n = 2 + trial % 9;
    Vector3 parts = Vector3::Zero();
    for (int k = 0; k < n; ++k) parts = compose(parts, detail::arc_displacement(d / n, l / n, detail::ArcStep(a / n)));
    EXPECT_LT((parts - whole).norm(), 1e-13 * (1 + std::abs(d) + std::abs(l))) << "n = " << n;
  }
}

TEST(ClosedFormLateral, NoiseIntegralMatchesQuadrature) {
  std::mt19937_64 rng(62);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 300; ++trial) {
    const double d = 5 * u(rng), l = 2 * u(rng);
    const double a = trial % 3 == 0 ? 1e-3 * u(rng) : 4 * M_PI * u(rng);
    Eigen::Matrix2d L;
    L << u(rng), 0, u(rng), u(rng);
    const Matrix2 N = L * L.transpose();
    EXPECT_LT(max_rel_diff(detail::arc_noise_covariance(d, l, detail::ArcFunctions(a), N),
                           quadrature_lateral_covariance(d, l, a, N)),
              1e-12)
        << "d = " << d << ", l = " << l << ", a = " << a;
  }
}

TEST(ClosedFormLateral, TransitionAndInputGainAreFirstOrderPerturbations) {
  // Phi: perturb the start (tangential) and drive the same piece exactly. The gain: a heading
  // rate, a travel and a slip error spread uniformly over the piece are the piece with
  // (a + e_theta, d + e_d, l + e_l); the end error is the gain times (e_theta, e_d, e_l).
  std::mt19937_64 rng(63);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double d = 3 * u(rng), l = u(rng), a = 3 * u(rng);
    const Vector3 start{u(rng), u(rng), M_PI * u(rng)};
    const Vector3 direction(u(rng), u(rng), u(rng));
    const detail::ArcFunctions f(a);
    const Matrix3 phi = detail::arc_transition(d, l, f), gain = detail::arc_input_gain(d, l, f);
    const Vector3 nominal = compose(start, lateral_displacement(d, l, a));
    auto transition_residual = [&](double h) {
      const Vector3 w = h * direction;
      Vector3 perturbed = start;
      perturbed.head<2>() += world_from_tangential(start.z()).topLeftCorner<2, 2>() * w.head<2>();
      perturbed.z() += w.z();
      return (tangential_error(compose(perturbed, lateral_displacement(d, l, a)), nominal) - phi * w).norm();
    };
    auto gain_residual = [&](double h) {
      const Vector3 e = h * direction;
      const Vector3 moved = compose(start, lateral_displacement(d + e.y(), l + e.z(), a + e.x()));
      return (tangential_error(moved, nominal) - gain * e).norm();
    };
    expect_second_order_residual(transition_residual(1e-4), transition_residual(1e-5), 7.0);
    expect_second_order_residual(gain_residual(1e-4), gain_residual(1e-5), 7.0);
  }
}

}  // namespace
}  // namespace odomcov
