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
  void terms(const LegView& leg, std::vector<TravelTerm>& out) const override {
    out.push_back({0, true, 0, leg.travel_left, 1.0});   // eps_L x travel_left
    out.push_back({1, true, 1, leg.travel_right, 1.0});  // eps_R x travel_right
  }
  int run_constants() const override { return 2; }
  std::string non_gaussian() const override {
    return sigma_ > 0 ? "a radius drawn once per run (products of per-run and per-sample errors)" : "";
  }
  void model(PieceModel& piece) const override {
    piece.run_columns.emplace_back(sigma_ * piece.scale_left * piece.encoder.left_m, 0.0, 0.0);
    piece.run_columns.emplace_back(0.0, sigma_ * piece.scale_right * piece.encoder.right_m, 0.0);
  }

 private:
  double sigma_;
};

}  // namespace

EffectType per_run_radius_type() {
  EffectInfo info{"per_run_radius",
                  {{"sigma", "", 0.0, 1e300, false, false, 0.0, 0.002}},
                  "wheel radii that change from run to run (tyre pressure, load, temperature)",
                  "variance grows as distance squared instead of linearly; each run keeps its own "
                  "drift throughout",
                  "each wheel's radius off by a relative N(0, sigma^2), drawn once per run",
                  /*systematic=*/false};
  info.run_constants = 2;
  return {info, [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<PerRunRadius>(v[0]);
          }};
}

}  // namespace odomcov::effects
