// odomcov run CONFIG [--runs N] [--seed S] [--threads T] [--alpha A] [--order 1|2] [--check]
//             [--json FILE]
// Monte-Carlo against theory, reported as in [Kleeman95] §7.
#include <cmath>
#include <iostream>
#include <optional>
#include <sstream>

#include "commands.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/validation.hpp"
#include "odomcov/io/config_io.hpp"
#include "output.hpp"
#include "progress.hpp"

namespace odomcov::cli {
namespace {

/// The NEES mean in words: "n/a" where the predicted covariance cannot whiten (untestable).
std::string nees_text(double nees) { return std::isfinite(nees) ? fixed(nees, 4) : std::string("n/a"); }

struct RunOptions {
  std::string config;
  std::optional<std::int64_t> runs;
  std::optional<std::uint64_t> seed;
  int threads = 0;
  double alpha = kDefaultAlpha;
  bool check = false;
  std::string json;
  std::int64_t samples = 0;
  int order = 1;
};

std::string cov_test_name(int order) {
  return order == 2 ? "covariance (ADF [Browne84]):              "
                    : "covariance (LRT, Bartlett-corrected):     ";
}

/// At most this many end-point errors go into the JSON (a scatter plot needs far fewer).
constexpr std::int64_t kMaxJsonSamples = 100'000;

std::string report(const Config& config, const Validation& v, int threads) {
  std::ostringstream out;
  out << "odomcov run: " << config.name << "\n";
  auto effects_text = [](const EffectList& list) {
    std::string text;
    for (const EffectSpec& e : list) text += "\n    " + effect_yaml(e);
    return text.empty() ? std::string(" none") : text;
  };
  if (!config.world.effects.empty() || !config.model_effects.empty() ||
      config.world.noise.k_left != config.robot.noise.k_left ||
      config.world.noise.k_right != config.robot.noise.k_right) {
    out << "world: kl=" << config.world.noise.k_left << ", kr=" << config.world.noise.k_right
        << ", effects:" << effects_text(config.world.effects) << "\n"
        << "model effects:" << effects_text(config.model_effects) << "\n";
  }
  out
      << "SampleRate=" << config.path.sample_rate_hz << ", B=" << config.robot.wheelbase_m
      << ", kl=" << config.robot.noise.k_left << ", kr=" << config.robot.noise.k_right
      << ", MonteCarloRuns=" << v.runs << ", seed=" << v.seed
      << ", threads=" << (threads > 0 ? std::to_string(threads) : std::string("all")) << "\n"
      << "time Leftdist Rightdist:\n";
  for (const Keyframe& k : config.path.keyframes) {
    out << "  " << fixed(k.t_s, 6) << " " << fixed(k.left_m, 6) << " " << fixed(k.right_m, 6)
        << "\n";
  }
  out << "\n====== simulation\n"
      << "  number of samples: " << v.simulation.n << "\n"
      << moments_text(v.simulation.mean, v.simulation.cov) << "\n====== theory ("
      << v.theory_source << ")\n"
      << moments_text(v.theory_mean, v.theory_cov) << "\n====== tests (alpha = " << v.alpha
      << ")\n"
      << "  mean (chi^2, theory covariance):          " << test_text(v.mean_test) << "\n"
      << "  " << cov_test_name(v.order) << test_text(v.cov_test) << "\n"
      << "  mean NEES:                                " << nees_text(v.nees_mean)
      << " (expected 3)\n"
      << "verdict: " << v.verdict << " (order " << v.order << ")\n\n";
  const OrderResult& o = v.other;
  out << "The other order (information, not part of the verdict): " << o.theory_source << "\n"
      << moments_text(o.theory_mean, o.theory_cov)
      << "  mean (chi^2, theory covariance):          " << test_text(o.mean_test) << "\n"
      << "  " << cov_test_name(o.order) << test_text(o.cov_test) << "\n";
  if (o.order == 2) {
    out << "  covariance (LRT, Gaussian, for reference): " << test_text(o.cov_lrt) << "\n";
  }
  out << "  mean NEES: " << nees_text(o.nees_mean) << "; verdict (order " << o.order
      << "): " << o.verdict << "\n\n"
      << "Beyond the continuous first-order theory (information, not part of the verdict):\n"
      << "  noise-induced mean (exact for the Gaussian heading error of white wheel noise):\n"
      << "    (" << sci(v.noise_induced_mean.x(), 4) << ", " << sci(v.noise_induced_mean.y(), 4)
      << ", 0); mean test against theory + it: " << test_text(v.noise_induced_mean_test) << "\n"
      << "  per-sample first-order covariance [Wang88] (noise lumped per sample):\n";
  if (v.sampled_cov_test.valid) {
    const Matrix3& closed = v.order == 1 ? v.theory_cov : v.other.theory_cov;
    out << "    std-dev ratio to the closed form ("
        << fixed(std::sqrt(v.sampled_cov(0, 0) / closed(0, 0)), 4) << ", "
        << fixed(std::sqrt(v.sampled_cov(1, 1) / closed(1, 1)), 4) << ", "
        << fixed(std::sqrt(v.sampled_cov(2, 2) / closed(2, 2)), 4)
        << "); covariance test against it: " << test_text(v.sampled_cov_test) << "\n";
  } else {
    out << "    not available with model effects\n";
  }
  return out.str();
}

int run_run(const RunOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  check_alpha(opt.alpha);
  check_threads(opt.threads);
  check_order(opt.order);
  if (opt.samples < 0 || opt.samples > kMaxJsonSamples) {
    throw UsageError("--samples must be in [0, " + std::to_string(kMaxJsonSamples) + "]");
  }
  if (opt.samples > 0 && opt.json.empty()) throw UsageError("--samples needs --json");
  Config config = load_config(opt.config);
  if (opt.runs) config.simulation.runs = *opt.runs;
  if (opt.seed) config.simulation.seed = *opt.seed;
  check_simulation_size(opt.config, 0, "--runs", config.simulation.runs,
                        sample_count(config.path));

  Progress progress;
  ProgressBar bar([&progress] { return progress.runs_done.load(); }, config.simulation.runs,
                  "runs");
  const Validation v = validate(config, opt.alpha, opt.threads, &progress, opt.samples, opt.order);
  bar.finish();

  std::cout << report(config, v, opt.threads);
  if (!opt.json.empty()) {
    json doc = validation_json(config.name, v);
    if (!v.samples.empty()) {
      json samples = json::array();
      for (const Vector3& e : v.samples) samples.push_back(to_json(e));
      doc["odometry_end_pose"] = to_json(v.odometry_end_pose);
      doc["samples"] = samples;
    }
    write_json_atomic(opt.json, doc);
  }
  // --check passes only on consistent: an untestable verdict is a failure too.
  return opt.check && !v.verdict.consistent() ? kExitInconsistent : kExitOk;
}

}  // namespace

json order_json(const OrderResult& o) {
  json tests = {{"mean", test_json(o.mean_test)}, {"covariance", test_json(o.cov_test)}};
  if (o.order == 2) tests["covariance_lrt"] = test_json(o.cov_lrt);
  return {{"theory", moments_json(o.theory_mean, o.theory_cov)},
          {"source", o.theory_source},
          {"tests", tests},
          {"nees_mean", o.nees_mean},
          {"verdict", o.verdict.name()}};
}

json validation_json(const std::string& name, const Validation& v) {
  json out = {{"name", name},
          {"order", v.order},
          {"order_" + std::to_string(v.other.order), order_json(v.other)},
          {"runs", v.runs},
          {"seed", v.seed},
          {"alpha", v.alpha},
          {"simulation", moments_json(v.simulation.mean, v.simulation.cov)},
          {"theory", moments_json(v.theory_mean, v.theory_cov)},
          {"tests", {{"mean", test_json(v.mean_test)}, {"covariance", test_json(v.cov_test)}}},
          {"noise_induced_mean",
           {{"mean", to_json(v.noise_induced_mean)},
            {"test", test_json(v.noise_induced_mean_test)}}},
          {"sampled_theory",
           {{"cov", to_json(v.sampled_cov)}, {"test", test_json(v.sampled_cov_test)}}},
          {"nees_mean", v.nees_mean},
          {"verdict", v.verdict.name()}};
  if (v.verdict.untestable()) out["verdict_reason"] = v.verdict.reason;
  return out;
}

void setup_run(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<RunOptions>();
  CLI::App* cmd = app.add_subcommand("run", "Monte-Carlo simulation against the closed form");
  cmd->add_option("config", opt->config, "Path config (YAML)")->required();
  cmd->add_option("--runs", opt->runs, "Number of Monte-Carlo runs (overrides the config)");
  cmd->add_option("--seed", opt->seed, "Random seed (overrides the config)")
      ->check(non_negative_integer);
  cmd->add_option("--threads", opt->threads, "Worker threads; 0 = all cores")
      ->capture_default_str();
  cmd->add_option("--alpha", opt->alpha, "Significance level of the tests")
      ->capture_default_str();
  cmd->add_option("--order", opt->order,
                  "Model order of the theory and verdict: 1 = first-order closed form, 2 = exact "
                  "Gaussian-heading moments with the ADF covariance test (docs/orders.md)")
      ->capture_default_str();
  cmd->add_flag("--check", opt->check, "Exit with code 1 unless the verdict is consistent (inconsistent or untestable)");
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->add_option("--samples", opt->samples,
                  "Also put the end-pose errors of the first N runs in the JSON (scatter plots)");
  cmd->callback([opt, &exit_code] { exit_code = run_run(*opt); });
}

}  // namespace odomcov::cli
