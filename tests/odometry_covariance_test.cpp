// The per-step API of odomcov::closed_form (OdometryCovariance) and the Lie-group reading of the
// closed form's transition matrix.
#include "odomcov/closed_form/odometry_covariance.hpp"

#include <gtest/gtest.h>

#include <random>

#include "odomcov/engine/propagation.hpp"
#include "test_util.hpp"

namespace odomcov {
namespace {

using test::max_rel_diff;

/// SE(2) element (x, y, theta) as its 3x3 homogeneous matrix, and the adjoint of manif/Sophus
/// for the tangent ordering (v_x, v_y, omega), as manif's SE2::adj() computes it:
///   Ad(T) = [[R, [y; -x]], [0, 1]].
Matrix3 adjoint(const Vector3& T) {
  const double c = std::cos(T.z()), s = std::sin(T.z());
  Matrix3 ad;
  ad << c, -s, T.y(),  //
      s, c, -T.x(),    //
      0, 0, 1;
  return ad;
}
Vector3 inverse(const Vector3& T) {
  const double c = std::cos(T.z()), s = std::sin(T.z());
  return {-(c * T.x() + s * T.y()), -(-s * T.x() + c * T.y()), -T.z()};
}

/// Frame convention: the tangential error (s, p, theta) of [Kleeman95] is, to first order, the
/// right (body-frame) perturbation tau of the pose, true = odometry * Exp(tau). Driving the
/// displacement T of a segment then maps tau_start to tau_end = Ad(T^-1) tau_start, so the
/// transition matrix of eq. (36) must be the adjoint of the inverse displacement.
TEST(OdometryCovariance, TransitionIsAdjointOfInverseDisplacement) {
  std::mt19937_64 rng(20260101);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<std::pair<double, double>> cases = {
      {0.0, 0.0}, {1e-8, 1e-8}, {1.0, 0.0}, {-2.0, 0.0}, {0.0, 1e-8}, {0.0, M_PI}, {0.0, -4 * M_PI},
      {1e-5, M_PI}, {3.0, 1e-5}, {1.0, -M_PI}, {-0.7, 2.9}};
  for (int i = 0; i < 200; ++i) cases.push_back({5.0 * u(rng), 7.0 * u(rng)});
  for (const auto& [d, a] : cases) {
    const Vector3 T = arc_displacement(d, a);
    const Matrix3 expected = adjoint(inverse(T));
    EXPECT_LT((arc_transition(d, a) - expected).cwiseAbs().maxCoeff(), 1e-12 * (1.0 + std::abs(d)))
        << "d = " << d << ", a = " << a;
  }
}

/// J_out_in in the world frame is the familiar EKF Jacobian of the pose update.
TEST(OdometryCovariance, WorldJacobianIsTheEkfJacobian) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Vector3 start(3 * u(rng), 3 * u(rng), 10 * u(rng));
    OdometryCovariance odo(0.4, {1e-3, 2e-3}, start);
    const OdometryStep& s = odo.step({2 * u(rng), 2 * u(rng)});
    Matrix3 expected = Matrix3::Identity();
    expected(0, 2) = -(s.pose_world.y() - start.y());
    expected(1, 2) = s.pose_world.x() - start.x();
    EXPECT_LT((s.J_out_in - expected).cwiseAbs().maxCoeff(), 1e-12);
  }
}

/// Stepping interval by interval, or in 50 pieces per interval, gives path_covariance at every
/// keyframe [Chong97 §4.1] and the odometry pose.
TEST(OdometryCovariance, StepsComposeToTheClosedForm) {
  std::mt19937_64 rng(11);
  for (int c = 0; c < 50; ++c) {
    const test::RandomCase rc = test::random_case(rng);
    const PathCovariance expected = path_covariance(rc.path, rc.robot);
    OdometryCovariance coarse(rc.robot.wheelbase_m, rc.robot.noise);
    OdometryCovariance fine(rc.robot.wheelbase_m, rc.robot.noise);
    for (std::size_t i = 0; i < rc.path.interval_count(); ++i) {
      const ArcSegment seg = rc.path.interval(i);
      coarse.step(seg);
      for (int k = 0; k < 50; ++k) fine.step({seg.left_m / 50, seg.right_m / 50});
      const KeyframeCovariance& k = expected.keyframes[i + 1];
      EXPECT_LT(max_rel_diff(coarse.P_world(), k.P_world), 1e-12);
      EXPECT_LT(max_rel_diff(fine.P_world(), k.P_world), 1e-9);
      EXPECT_LT((fine.pose_world() - k.pose_world).cwiseAbs().maxCoeff(), 1e-9);
      EXPECT_EQ(coarse.P_world(), coarse.P_world().transpose());  // symmetric to the last bit
    }
  }
}

/// J_out_wheels by first-order perturbation: the residual of the linear prediction falls as
/// the square of the perturbation (100x for a 10x smaller step).
TEST(OdometryCovariance, WheelJacobianIsFirstOrderExact) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Vector3 start(u(rng), u(rng), 4 * u(rng));
    const ArcSegment seg{2 * u(rng), 2 * u(rng)};
    const double B = 0.3 + 0.2 * (1 + u(rng));
    OdometryCovariance odo(B, {0, 0}, start);
    const OdometryStep s = odo.step(seg);
    const Eigen::Vector2d w(u(rng), u(rng));
    double residual[2];
    for (int k = 0; k < 2; ++k) {
      const double h = k == 0 ? 1e-3 : 1e-4;
      OdometryCovariance p(B, {0, 0}, start);
      const Vector3 moved = p.step({seg.left_m + h * w(0), seg.right_m + h * w(1)}).pose_world;
      residual[k] = (moved - s.pose_world - s.J_out_wheels * (h * w)).norm();
    }
    EXPECT_GT(residual[0] / residual[1], 50.0) << residual[0] << " " << residual[1];
    EXPECT_LT(residual[1], 1e-7);
  }
}

/// World covariances are symmetric to the last bit, so reports never print P(0,1) != P(1,0).
TEST(OdometryCovariance, WorldCovarianceIsExactlySymmetric) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const Matrix3 q = arc_covariance({2 * u(rng), 2 * u(rng)}, 0.5, {1e-3, 3e-3});
    const Matrix3 w = tangential_to_world(q, 10 * u(rng));
    EXPECT_EQ(w, w.transpose());
  }
}

}  // namespace
}  // namespace odomcov
