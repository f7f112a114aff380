// bumps {rate [1/m], sigma [m]}: Poisson impulses at `rate` per metre of mean wheel travel
// (|dL| + |dR|)/2; each adds N(0, sigma^2) to one wheel chosen at random (a floor joint, a
// cable, a wheel climbing an edge).
// World: the distance to the next bump is exponential; when a sample's travel reaches it, the
// bump lands on that sample (several may). Model: the Gaussian equivalent, variance
// rate sigma^2 m / 2 on each wheel over a piece of mean travel m. The tails are heavier than
// that Gaussian: the signature diagnose looks for.
#include <cmath>

#include "effect.hpp"

namespace odomcov::effects {
namespace {

/// Draw indices per bump (wheel, size, next gap); 85 bumps fit the 8-bit index of one sample.
constexpr std::uint32_t kDrawsPerBump = 3;
constexpr std::uint32_t kMaxBumpsPerSample = 85;
/// The largest expected number of bumps per sample the simulator accepts: with a Poisson mean
/// of 30, P(N > 85) < 1e-13 (Chernoff bound exp(-lambda) (e lambda/85)^85 = 3e-14), so the cap
/// of 85 never binds in practice and the simulation is exact; beyond it the config is refused.
constexpr double kMaxMeanBumpsPerSample = 30.0;

class Bumps final : public Effect {
 public:
  Bumps(double rate, double sigma) : rate_(rate), sigma_(sigma) {}
  bool stochastic() const override { return true; }
  void begin_run(RunState& state, const Draws& draws) const override {
    state.value[0] = rate_ > 0.0 ? -std::log(1.0 - draws.run_uniform(0)) / rate_ : HUGE_VAL;
  }
  void perturb(WorldSample& s, RunState& state, const Draws& draws) const override {
    double& to_next = state.value[0];
    to_next -= 0.5 * (std::abs(s.encoder_left) + std::abs(s.encoder_right));
    for (std::uint32_t j = 0; to_next <= 0.0 && j < kMaxBumpsPerSample; ++j) {
      const std::uint32_t i = kDrawsPerBump * j;
      const double size = sigma_ * draws.normal(s.index, i + 1);
      (draws.uniform(s.index, i) < 0.5 ? s.extra_left : s.extra_right) += size;
      to_next += -std::log(1.0 - draws.uniform(s.index, i + 2)) / rate_;
    }
  }
  std::string check_samples(double max_mean_travel_m) const override {
    const double per_sample = rate_ * max_mean_travel_m;
    if (per_sample <= kMaxMeanBumpsPerSample) return "";
    return "rate " + std::to_string(rate_) + "/m gives up to " + std::to_string(per_sample) +
           " bumps per sample on this path; the simulator draws at most " +
           std::to_string(kMaxBumpsPerSample) + " per sample, exact up to a mean of " +
           std::to_string(static_cast<int>(kMaxMeanBumpsPerSample)) +
           ": raise the path's sample_rate";
  }
  void model(PieceModel& piece) const override {
    const double mean_travel =
        0.5 * (std::abs(piece.encoder.left_m) + std::abs(piece.encoder.right_m));
    const double var = 0.5 * rate_ * sigma_ * sigma_ * mean_travel;
    piece.wheel_cov(0, 0) += var;
    piece.wheel_cov(1, 1) += var;
  }

 private:
  double rate_, sigma_;
};

}  // namespace

EffectType bumps_type() {
  return {{"bumps",
           {{"rate", "1/m", 0.0, 1e300, false, false, 0.0, 0.5},
            {"sigma", "m", 0.0, 1e300, false, false, 0.0, 0.005}},
           "bumps and floor joints that jolt one wheel at a time",
           "heavy tails: a few runs far out (Mardia kurtosis above 15), with variance growing "
           "with distance like wheel noise",
           "Poisson impulses at rate per metre of mean wheel travel, each N(0, sigma^2) on one "
           "wheel",
           /*systematic=*/false,
           /*heavy_tails=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<Bumps>(v[0], v[1]);
          }};
}

}  // namespace odomcov::effects
