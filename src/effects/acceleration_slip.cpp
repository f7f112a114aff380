// acceleration_slip {c}: while the speed changes the wheels spin (speeding up) or skid (braking),
// so each wheel's true travel is its encoder travel times
//   1 - c a,
// with a the acceleration along the path (the change of the mean wheel speed from the previous
// increment over this increment's duration; 0 before the first). On a sampled path the speed
// jumps within one sample, so that sample carries the whole slip of the jump, c v dv of travel
// (c v^2 at a start from rest), whatever the sample rate. A stop on a planned path falls on a
// sample that does not move, and shows nothing; stops show where the speed ramps down over moving
// samples (logged runs). World: the factor per sample. Model: per piece, on pieces that set each
// stretch's first sample apart (EffectInfo::uses_acceleration, path_model_pieces), so the
// acceleration is constant on every piece as on every sample.
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class AccelerationSlip final : public Effect {
 public:
  explicit AccelerationSlip(double c) : c_(c) {}
  Dependence dependence() const override { return Dependence::history; }
  void systematic(const Motion& m, Systematic& f) const override {
    if (!std::isfinite(m.dt_s)) {
      throw EffectError("acceleration_slip", "needs each increment's duration (the acceleration); give the times");
    }
    const double factor = 1.0 - c_ * m.a_mps2;
    f.scale_left *= factor;
    f.scale_right *= factor;
  }

 private:
  double c_;
};

EffectInfo info() {
  EffectInfo i{"acceleration_slip",
               {{"c", "s^2/m", 0.0, 1e300, false, false, 0.0, 0.02}},
               "slip while the speed changes: the wheels spin when the robot speeds up and skid "
               "when it brakes (starts and stops, slippery floors, high acceleration)",
               "runs fall short by about c v^2 per start from rest (and overshoot where they brake "
               "while moving), whatever their length, so short runs with many starts suffer most",
               "each wheel's true travel x (1 - c a), a the acceleration along the path",
               /*systematic=*/true};
  i.uses_acceleration = true;
  return i;
}

}  // namespace

EffectType acceleration_slip_type() {
  return {info(), [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<AccelerationSlip>(v[0]);
          }};
}

}  // namespace odomcov::effects
