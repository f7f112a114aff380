// An EKF prediction step with odomcov's odometry covariance: a robot with B = 0.5 m and
// kL = kR = 1e-3 m^(1/2) drives the path of [Kleeman95] Fig. 7 in 20 ms encoder samples. Each
// sample, the filter's state and covariance are predicted with
//   x <- f(x, u),   P <- J_out_in P J_out_in^T + Q_world,
// where Q_world is the closed-form covariance the sample's wheel noise adds [Kleeman95,
// eq. (40)]. Without measurement updates the filter's P must equal odomcov's own accumulated
// covariance, which the program checks against the report's Table I value at the end (point E,
// with the corrected signs of docs/conventions.md): it exits 1 when they disagree.
#include <odomcov/closed_form/odometry_covariance.hpp>
#include <odomcov/closed_form/path.hpp>

#include <cmath>
#include <cstdio>
#include <vector>

int main() {
  using odomcov::ArcSegment;
  const double wheelbase_m = 0.5;
  const odomcov::WheelNoise k{1e-3, 1e-3};
  // Fig. 7 keyframes: (t s, cumulative left m, cumulative right m).
  const std::vector<odomcov::Keyframe> keyframes = {
      {0, 0, 0}, {2, 2, 2}, {3, 1.6073, 2.3927}, {4, 3.5708, 3.5708}, {5, 3.37445, 4.15985}};

  // The filter's own state: pose and covariance in the world frame.
  Eigen::Vector3d x = Eigen::Vector3d::Zero();
  Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
  odomcov::OdometryCovariance odometry(wheelbase_m, k);
  constexpr int kSamplesPerSecond = 50;
  for (std::size_t i = 1; i < keyframes.size(); ++i) {
    const auto& a = keyframes[i - 1];
    const auto& b = keyframes[i];
    const int n = static_cast<int>(std::lround((b.t_s - a.t_s) * kSamplesPerSecond));
    const ArcSegment increment{(b.left_m - a.left_m) / n, (b.right_m - a.right_m) / n};
    for (int s = 0; s < n; ++s) {
      const odomcov::OdometryStep& step = odometry.step(increment);
      x = odomcov::drive(x, increment, wheelbase_m);                     // x <- f(x, u)
      P = step.J_out_in * P * step.J_out_in.transpose() + step.Q_world;  // P <- F P F^T + Q
    }
  }
  std::printf("pose  x = %.4f m, y = %.4f m, theta = %.4f rad\n", x.x(), x.y(), x.z());
  std::printf("P_world =\n");
  for (int r = 0; r < 3; ++r) std::printf("  % .4e % .4e % .4e\n", P(r, 0), P(r, 1), P(r, 2));
  // Table I, point E, kL = kR = 1e-3 (docs/conventions.md, "Reference values").
  Eigen::Matrix3d table1;
  table1 << 3.0318e-05, -4.7634e-05, -2.8172e-05,  //
      -4.7634e-05, 8.9742e-05, 4.6998e-05,         //
      -2.8172e-05, 4.6998e-05, 3.4850e-05;
  const double worst = ((P - table1).cwiseAbs().array() / table1.cwiseAbs().array()).maxCoeff();
  std::printf("largest relative difference to Table I: %.2e (printed to 5 digits)\n", worst);
  return worst < 5e-4 ? 0 : 1;
}
