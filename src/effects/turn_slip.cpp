// turn_slip {k} [rad^(1/2)]: extra opposite-signed slip of the two wheels while turning,
// distance unchanged: each sample's heading changes by an extra eta ~ N(0, k^2 |dtheta|),
// dtheta = (dR - dL)/B the encoder heading change. World: eta moves the wheels by -/+ eta B'/2
// (B' the true wheelbase, so the heading changes by exactly eta). Model: white heading
// variance k^2 |R - L|/B over a piece.
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class TurnSlip final : public Effect {
 public:
  explicit TurnSlip(double k) : k_(k) {}
  bool stochastic() const override { return true; }
  void terms(const LegView& leg, std::vector<TravelTerm>& out) const override {
    const double turned = std::abs(leg.encoder_right - leg.encoder_left) / leg.wheelbase_nominal;
    if (turned == 0.0 || k_ == 0.0) return;
    // eta = k sqrt(turned) z moves the wheels by -/+ eta B'/2.
    const double sd = k_ * std::sqrt(turned);
    out.push_back({0, false, 0, sd, -0.5 * leg.wheelbase});
    out.push_back({1, false, 0, sd, 0.5 * leg.wheelbase});
  }
  void model(PieceModel& piece) const override {
    piece.heading_var +=
        k_ * k_ * std::abs(piece.encoder.right_m - piece.encoder.left_m) / piece.wheelbase_m;
  }

 private:
  double k_;
};

}  // namespace

EffectType turn_slip_type() {
  return {{"turn_slip",
           {{"k", "rad^(1/2)", 0.0, 1e300, false, false, 0.0, 0.01}},
           "wheels slipping sideways against each other while the robot turns",
           "extra heading variance in proportion to the angle turned; straight lines and the "
           "mean unaffected",
           "extra heading variance k^2 |dtheta| per sample",
           /*systematic=*/false},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<TurnSlip>(v[0]);
          }};
}

}  // namespace odomcov::effects
