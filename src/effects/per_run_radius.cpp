// per_run_radius {sigma}: each wheel's effective radius is off by a relative N(0, sigma^2)
// error drawn once per run (tyre pressure, load, temperature) and constant for the run.
// World: true travel x (1 + eps) with eps_L, eps_R drawn per run. Model: two standard-normal
// per-run constants with columns (sigma L', 0) and (0, sigma R') on (e_L, e_R), L', R' the
// piece's systematic true travel; the engine carries them as augmented state.
#include "effects/effect.hpp"

namespace odomcov::effects {
namespace {

class PerRunRadius final : public Effect {
 public:
  explicit PerRunRadius(double sigma) : sigma_(sigma) {}
  bool stochastic() const override { return true; }
  void begin_run(RunState& state, const Draws& draws) const override {
    state.value[0] = sigma_ * draws.run_normal(0);
    state.value[1] = sigma_ * draws.run_normal(1);
  }
  void perturb(WorldSample& s, RunState& state, const Draws&) const override {
    s.extra_left += state.value[0] * s.travel_left;
    s.extra_right += state.value[1] * s.travel_right;
  }
  int run_constants() const override { return 2; }
  std::string non_gaussian() const override {
    return sigma_ > 0 ? "a radius drawn once per run (products of per-run and per-sample errors)" : "";
  }
  void model(PieceModel& piece) const override {
    piece.run_columns.emplace_back(sigma_ * piece.scale_left * piece.encoder.left_m, 0.0);
    piece.run_columns.emplace_back(0.0, sigma_ * piece.scale_right * piece.encoder.right_m);
  }

 private:
  double sigma_;
};

}  // namespace

EffectType per_run_radius_type() {
  return {{"per_run_radius",
           {{"sigma", "", 0.0, 1e300, false, false, 0.0, 0.002}},
           "wheel radii that change from run to run (tyre pressure, load, temperature)",
           "variance grows as distance squared instead of linearly; each run keeps its own "
           "drift throughout",
           "each wheel's radius off by a relative N(0, sigma^2), drawn once per run",
           /*systematic=*/false},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<PerRunRadius>(v[0]);
          }};
}

}  // namespace odomcov::effects
