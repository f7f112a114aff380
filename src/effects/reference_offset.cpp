// reference_offset {dx, dy} [m]: the external reference tracks a point d = (dx, dy) in the robot
// frame instead of the wheel-axle centre, zeroed at the start, so it measures
//   xy = p + R(theta) d - d,   theta unchanged.
// It acts on the measurement, not the motion. World: the measurement hook on the true end pose.
// Model: the same map on the mean end pose, and the covariance through its Jacobian
//   J = I + [0 0 -s dx - c dy; 0 0 c dx - s dy; 0 0 0]   (c, s = cos, sin of the mean heading),
// first order in the heading error.
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class ReferenceOffset final : public Effect {
 public:
  ReferenceOffset(double dx, double dy) : dx_(dx), dy_(dy) {}
  bool measures() const override { return true; }
  void measure(Vector3& pose) const override {
    const double c = std::cos(pose.z()), s = std::sin(pose.z());
    pose.x() += c * dx_ - s * dy_ - dx_;
    pose.y() += s * dx_ + c * dy_ - dy_;
  }
  void measure_model(Vector3& pose, Matrix3& J_measured_true) const override {
    const double c = std::cos(pose.z()), s = std::sin(pose.z());
    Matrix3 J_hook = Matrix3::Identity();
    J_hook(0, 2) = -s * dx_ - c * dy_;
    J_hook(1, 2) = c * dx_ - s * dy_;
    measure(pose);
    J_measured_true = J_hook * J_measured_true;
  }

 private:
  double dx_, dy_;
};

}  // namespace

EffectType reference_offset_type() {
  EffectType type{
      {"reference_offset",
       {{"dx", "m", -1e300, 1e300, false, false, 0.0, 0.01},
        {"dy", "m", -1e300, 1e300, false, false, 0.0, 0.01}},
       "the external reference tracks a point off the wheel-axle centre",
       "a position error that depends only on the final heading (zero after a full turn, "
       "largest after a half turn), not on the distance driven",
       "measured xy = p + R(theta) d - d, d = (dx, dy) in the robot frame",
       /*systematic=*/true},
      [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
        return std::make_unique<ReferenceOffset>(v[0], v[1]);
      }};
  type.info.measurement_only = true;
  return type;
}

}  // namespace odomcov::effects
