// scale_error {Es}: both wheels' true travel is Es times the encoder's (a wrong mean wheel
// diameter or encoder resolution). World: systematic scale. Model: the same scale.
#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class ScaleError final : public Effect {
 public:
  explicit ScaleError(double es) : es_(es) {}
  void systematic(const Motion&, Systematic& f) const override {
    f.scale_left *= es_;
    f.scale_right *= es_;
  }

 private:
  double es_;
};

}  // namespace

EffectType scale_error_type() {
  return {{"scale_error",
           {{"Es", "", 0.0, 1e300, true, false, 1.0, 1.005}},
           "a wrong distance scale (mean wheel diameter or encoder resolution)",
           "along-track error proportional to distance on straight lines, plus a heading error "
           "proportional to the angle turned",
           "both wheels' true travel x Es",
           /*systematic=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<ScaleError>(v[0]);
          }};
}

}  // namespace odomcov::effects
