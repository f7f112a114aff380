// wheelbase_error {Eb}: the true wheelbase is Eb B [Borenstein96]. World: systematic factor on
// the wheelbase. Model: the same factor (exact mean, covariance along the true path).
#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class WheelbaseError final : public Effect {
 public:
  explicit WheelbaseError(double eb) : eb_(eb) {}
  void systematic(const Motion&, Systematic& f) const override { f.wheelbase_factor *= eb_; }

 private:
  double eb_;
};

}  // namespace

EffectType wheelbase_error_type() {
  return {{"wheelbase_error",
           {{"Eb", "", 0.0, 1e300, true, false, 1.0, 1.01, /*varies_between_groups=*/true}},
           "a wrong wheelbase (true wheelbase = Eb B)",
           "heading error proportional to the angle turned, changing sign with the turn "
           "direction; straight lines unaffected",
           "true wheelbase = Eb B",
           /*systematic=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<WheelbaseError>(v[0]);
          }};
}

}  // namespace odomcov::effects
