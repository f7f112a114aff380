// bumps {rate [1/m], sigma [m]}: Poisson impulses at `rate` per metre of mean wheel travel
// (|dL| + |dR|)/2; each adds N(0, sigma^2) to one wheel chosen at random (a floor joint, a
// cable, a wheel climbing an edge).
// World: the distance to the next bump is exponential; when a sample's travel reaches it, the
// bump lands on that sample (several may). Model: the Gaussian equivalent, variance
// rate sigma^2 m / 2 on each wheel over a piece of mean travel m. The tails are heavier than
// that Gaussian: the signature diagnose looks for.
#include <cmath>
#include <limits>

#include "effects/effect.hpp"
#include "odomcov/base/format.hpp"

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
  bool events() const override { return true; }
  void event(std::uint32_t sample, RunState& state, const Draws& draws, double& extra_left,
             double& extra_right) const override {
    double& to_next = state.value[0];  // the simulator has taken this sample's travel off
    for (std::uint32_t j = 0; to_next <= 0.0 && j < kMaxBumpsPerSample; ++j) {
      const std::uint32_t i = kDrawsPerBump * j;
      const double size = sigma_ * draws.normal(sample, i + 1);
      (draws.uniform(sample, i) < 0.5 ? extra_left : extra_right) += size;
      to_next += -std::log(1.0 - draws.uniform(sample, i + 2)) / rate_;
    }
  }
  std::string non_gaussian() const override { return heavy_tailed() ? "Poisson impulses (heavy tails)" : ""; }
  bool heavy_tailed() const override { return rate_ > 0 && sigma_ > 0; }
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

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// Sample excess kurtosis, bias-corrected (G2 of Joanes & Gill 1998).
double excess_kurtosis(const std::vector<double>& x) {
  const double n = static_cast<double>(x.size());
  double mean = 0;
  for (double v : x) mean += v / n;
  double m2 = 0, m4 = 0;
  for (double v : x) {
    const double d = v - mean;
    m2 += d * d / n;
    m4 += d * d * d * d / n;
  }
  const double g2 = m4 / (m2 * m2) - 3.0;
  return ((n + 1) * g2 + 6) * (n - 1) / ((n - 2) * (n - 3));
}

/// bumps' sigma by the method of moments on the straight-line experiments: along a line a bump
/// J on one wheel moves the along-track error by J/2, so with Lambda = rate d bumps per run the
/// fourth cumulant of the along-track error is 3 Lambda sigma^4/16 = (3/16) rate sigma^4 d,
/// while q = rate sigma^2 is what the likelihood fitted. Pooling the lines (each cumulant from
/// its sample excess kurtosis times its variance squared, weighted by travel) gives
/// rate sigma^4 = (16/3) sum kappa4 / sum d and sigma^2 = rate sigma^4 / q. Returns NaN when no
/// straight experiment of ten runs or more shows heavy tails.
double bumps_sigma(const std::vector<ObservedExperiment>& data, double q) {
  double cumulant = 0.0, travel = 0.0;
  for (const ObservedExperiment& ex : data) {
    if (ex.path == nullptr || ex.errors.size() < 10) continue;
    double d = 0;
    bool straight = true;
    for (std::size_t i = 0; i < ex.path->interval_count(); ++i) {
      const ArcSegment s = ex.path->interval(i);
      straight = straight && s.left_m == s.right_m;
      d += std::abs(s.center_m());
    }
    if (!straight || d <= 0) continue;
    std::vector<double> along;
    for (const Vector3& e : ex.errors) along.push_back(e.x());
    double mean = 0, var = 0;
    for (double v : along) mean += v / static_cast<double>(along.size());
    for (double v : along) var += (v - mean) * (v - mean) / static_cast<double>(along.size() - 1);
    cumulant += excess_kurtosis(along) * var * var;
    travel += d;
  }
  if (!(travel > 0 && cumulant > 0 && q > 0)) return kNaN;
  return std::sqrt(16.0 / 3.0 * cumulant / travel / q);
}

/// diagnose's completion (EffectInfo::complete): the likelihood fitted the rate with sigma held
/// at its start, i.e. q = rate sigma^2; sigma comes from the tails (bumps_sigma), the rate is
/// then q / sigma^2.
std::string complete_bumps(const std::vector<ObservedExperiment>& data, EffectSpec& spec,
                           std::vector<double>& stderrs) {
  const double sigma_fixed = spec.values[1];
  const double q = spec.values[0] * sigma_fixed * sigma_fixed;
  const double q_se = stderrs[0] * sigma_fixed * sigma_fixed;
  const double sigma = bumps_sigma(data, q);
  const double s = std::isfinite(sigma) ? sigma : sigma_fixed;
  spec.values = {q / (s * s), s};
  stderrs = {q_se / (s * s), std::numeric_limits<double>::quiet_NaN()};
  return "rate sigma^2 = " + format_number(q, "%.3g") +
         (std::isfinite(q_se) ? " +/- " + format_number(q_se, "%.1g") + " m (" : std::string(" m (no standard error; ")) +
         "what the means and covariances determine); " +
         (std::isfinite(sigma) ? "sigma from the excess kurtosis of the along-track errors on "
                                 "the straight lines (a moment estimate, no standard error)"
                               : "sigma undetermined (no straight line with heavy tails), "
                                 "kept at " + format_number(s, "%.3g") + " m");
}

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
           /*grouped=*/false,
           // diagnose fits the rate only (a Gaussian likelihood sees rate sigma^2) and completes
           // sigma from the tails.
           /*diagnose_fitted=*/{"rate"},
           /*complete=*/complete_bumps,
           /*rescale_tails=*/[](EffectSpec& spec, double factor) {
             spec.values[1] *= factor;
             spec.values[0] /= factor * factor;
           }},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<Bumps>(v[0], v[1]);
          }};
}

}  // namespace odomcov::effects
