// arc_skid {c}: on an arc the tyres carry the centripetal force and slip sideways in proportion
// to it, so the robot slides outwards. Per increment the centre slips to the left by
//   lateral = -c v_c omega   [m per metre of mean wheel travel],
// with v_c = (dL + dR)/(2 dt) the signed centre speed and omega = (dR - dL)/(B dt) the turn rate
// (v_c omega is the centripetal acceleration, left positive): outwards on every arc, nothing on
// straight lines and on turns on the spot. The custom-effect form of the same physics on forward
// arcs is `lateral: "-c * v * omega"`. World and model: the same lateral slip per sample / per
// piece (effects' Systematic, "lateral"), from its Motion.
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class ArcSkid final : public Effect {
 public:
  explicit ArcSkid(double c) : c_(c) {}
  Dependence dependence() const override { return Dependence::increment; }
  void systematic(const Motion& m, Systematic& f) const override {
    if (!std::isfinite(m.dt_s)) {
      throw EffectError("arc_skid", "needs each increment's duration (the speed); give the times");
    }
    const double centre_speed = 0.5 * (m.dL_m + m.dR_m) / m.dt_s;
    f.lateral -= c_ * centre_speed * m.omega_radps;
  }

 private:
  double c_;
};

}  // namespace

EffectType arc_skid_type() {
  return {{"arc_skid",
           {{"c", "s^2/m", 0.0, 1e300, false, false, 0.0, 0.01}},
           "a sideways skid on arcs: the tyres slip outwards under the centripetal force "
           "(fast arcs, worn or hard tyres, smooth floors)",
           "arcs end displaced outwards (to the right on left arcs, to the left on right arcs), "
           "growing with speed times turn rate; straight lines and turns on the spot are untouched",
           "the centre slips outwards by c v omega per metre of travel (v the centre speed, omega "
           "the turn rate)",
           /*systematic=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<ArcSkid>(v[0]);
          }};
}

}  // namespace odomcov::effects
