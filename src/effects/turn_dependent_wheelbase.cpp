// turn_dependent_wheelbase {Eb_arc, Eb_spin}: the effective contact points move with the kind of
// turn (tyre scrub), so the true wheelbase of each increment is B (Eb_arc + (Eb_spin - Eb_arc) r)
// with r the spin fraction |dR - dL|/(|dR| + |dL|) (0 on a line, B|kappa|/2 on a forward arc, 1
// on the spot). World and model: the same factor per sample / per piece, from its Motion.
#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class TurnDependentWheelbase final : public Effect {
 public:
  TurnDependentWheelbase(double arc, double spin) : arc_(arc), spin_(spin) {}
  Dependence dependence() const override { return Dependence::increment; }
  void systematic(const Motion& m, Systematic& f) const override {
    f.wheelbase_factor *= arc_ + (spin_ - arc_) * m.r;
  }

 private:
  double arc_, spin_;
};

EffectInfo info() {
  EffectInfo i{"turn_dependent_wheelbase",
               {{"Eb_arc", "", 0.0, 1e300, true, false, 1.0, 1.005},
                {"Eb_spin", "", 0.0, 1e300, true, false, 1.0, 1.01}},
               "a wheelbase that depends on the kind of turn (tyre scrub moves the contact points)",
               "heading error proportional to the angle turned, but at different rates on turns on "
               "the spot and on wide arcs, so one wheelbase correction cannot fit both",
               "true wheelbase per sample B (Eb_arc + (Eb_spin - Eb_arc) r)",
               /*systematic=*/true};
  i.contains = {"wheelbase_error"};  // Eb_arc = Eb_spin = Eb
  return i;
}

}  // namespace

EffectType turn_dependent_wheelbase_type() {
  return {info(), [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<TurnDependentWheelbase>(v[0], v[1]);
          }};
}

}  // namespace odomcov::effects
