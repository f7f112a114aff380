// wheel_diameter_ratio {Ed}: unequal wheel diameters, UMBmark's Ed = D_R/D_L [Borenstein96],
// with the mean diameter kept: true dL = dL 2/(Ed + 1), true dR = dR 2 Ed/(Ed + 1).
// World: a systematic scale of each wheel's travel. Model: the same scales, so the mean is the
// exact perturbed path and the covariance is propagated along it.
#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class WheelDiameterRatio final : public Effect {
 public:
  explicit WheelDiameterRatio(double ed) : left_(2.0 / (ed + 1.0)), right_(2.0 * ed / (ed + 1.0)) {}
  void systematic(const Motion&, Systematic& f) const override {
    f.scale_left *= left_;
    f.scale_right *= right_;
  }

 private:
  double left_, right_;
};

}  // namespace

EffectType wheel_diameter_ratio_type() {
  return {{"wheel_diameter_ratio",
           {{"Ed", "", 0.0, 1e300, true, false, 1.0, 1.004, /*varies_between_groups=*/true}},
           "unequal wheel diameters (Ed = D_R/D_L)",
           "heading drifts on straight lines in proportion to distance (lateral error grows as "
           "distance squared); turns in either sense drift the same way",
           "true dL = dL 2/(Ed+1), dR = dR 2 Ed/(Ed+1)",
           /*systematic=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<WheelDiameterRatio>(v[0]);
          }};
}

}  // namespace odomcov::effects
