// The per-sample linearised covariance of [Wang88] (propagation.hpp, sampled_covariance): an
// independent check of the closed form, not part of the engine.
#include <cstdint>

#include "odomcov/engine/propagation.hpp"

namespace odomcov {

Matrix3 sampled_covariance(const Path& path, const Robot& robot) {
  const double B = robot.wheelbase_m;
  Matrix3 P_tangential = Matrix3::Zero();
  double heading = 0.0;
  for (const SampleRun& run : sample_schedule(path)) {
    const double d = run.increment.center_m();
    const double a = run.increment.heading_change_rad(B);
    const Matrix3 phi = arc_transition(d, a);
    const Matrix32 j = arc_increment_jacobian(d, a);
    const Matrix3 q = j * wheel_noise_intensity(run.increment, B, robot.noise) * j.transpose();
    for (std::int64_t n = 0; n < run.count; ++n) {
      P_tangential = phi * P_tangential * phi.transpose() + q;
    }
    heading += static_cast<double>(run.count) * a;
  }
  return tangential_to_world(P_tangential, heading);
}

}  // namespace odomcov
