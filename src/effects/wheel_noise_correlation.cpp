// wheel_noise_correlation {rho}: the two wheels' per-sample noise is correlated (a shared
// floor or drive cause), corr = rho. World: z_R <- rho z_L + sqrt(1 - rho^2) z_R on the
// standard normals. Model: cov(e_L, e_R) over a piece = rho kL kR sqrt(|L| |R|), the sum of
// rho kL kR sqrt(|dL| |dR|) over its samples (their ratio is constant within a piece).
#include <cmath>

#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class WheelNoiseCorrelation final : public Effect {
 public:
  explicit WheelNoiseCorrelation(double rho) : rho_(rho), orth_(std::sqrt(1.0 - rho * rho)) {}
  bool stochastic() const override { return true; }
  bool noise_mix(double& from_left, double& from_right) const override {
    from_left = rho_;  // z_R <- rho z_L + sqrt(1 - rho^2) z_R
    from_right = orth_;
    return true;
  }
  void model(PieceModel& piece) const override {
    const double c = rho_ * piece.noise.k_left * piece.noise.k_right *
                     std::sqrt(std::abs(piece.encoder.left_m * piece.encoder.right_m));
    piece.wheel_cov(0, 1) += c;
    piece.wheel_cov(1, 0) += c;
  }

 private:
  double rho_, orth_;
};

}  // namespace

EffectType wheel_noise_correlation_type() {
  return {{"wheel_noise_correlation",
           {{"rho", "", -1.0, 1.0, true, true, 0.0, 0.5}},
           "correlated left and right wheel errors",
           "no bias; rho > 0 inflates along-track variance and shrinks heading variance "
           "(rho < 0 the reverse), so the two cannot both fit an uncorrelated model",
           "correlation of the left and right per-sample noise",
           /*systematic=*/false},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<WheelNoiseCorrelation>(v[0]);
          }};
}

}  // namespace odomcov::effects
