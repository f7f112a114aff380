// backlash {b_left, b_right} [m]: play in each wheel's drive train. After each reversal of a
// wheel's encoder direction the first b of encoder travel does not move that wheel; a run starts
// with the play taken up forwards. World: per sample, the part of the increment still inside the
// play is lost (an offset on that wheel's true travel). Model: the same loss per piece, with the
// piece split where the play is taken up (split_at), so the lost travel sits where the world
// loses it: a systematic loss at each reversal of the planned or logged motion.
#include <algorithm>
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

/// The encoder travel of this increment still inside the play, signed like the increment.
double lost(double b, double d, double since) {
  const double in_play = std::clamp(b - since, 0.0, std::abs(d));
  return d > 0 ? in_play : -in_play;
}

/// Where within |d| the play ends (a fraction in (0, 1)), or 1 when it does not end inside.
double play_end(double b, double d, double since) {
  const double rest = b - since;
  return rest > 0 && rest < std::abs(d) ? rest / std::abs(d) : 1.0;
}

class Backlash final : public Effect {
 public:
  Backlash(double left, double right) : left_(left), right_(right) {}
  Dependence dependence() const override { return Dependence::history; }
  void systematic(const Motion& m, Systematic& f) const override {
    f.offset_left_m -= lost(left_, m.dL_m, m.since_reversal_left_m);
    f.offset_right_m -= lost(right_, m.dR_m, m.since_reversal_right_m);
  }
  double split_at(const Motion& m) const override {
    return std::min(play_end(left_, m.dL_m, m.since_reversal_left_m),
                    play_end(right_, m.dR_m, m.since_reversal_right_m));
  }

 private:
  double left_, right_;
};

}  // namespace

EffectType backlash_type() {
  return {{"backlash",
           {{"b_left", "m", 0.0, 1e300, false, false, 0.0, 0.001},
            {"b_right", "m", 0.0, 1e300, false, false, 0.0, 0.001}},
           "play (backlash) in the wheels' drive trains, lost at every reversal",
           "a fixed loss of travel at every reversal of a wheel: heading steps on turns on the "
           "spot and on forward-backward runs, growing with the number of reversals rather than "
           "with distance",
           "after each reversal of a wheel's encoder direction the first b of encoder travel does "
           "not move that wheel",
           /*systematic=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<Backlash>(v[0], v[1]);
          }};
}

}  // namespace odomcov::effects
