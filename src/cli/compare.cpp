// odomcov compare SUITE.yaml [--alpha A] [--json FILE]
// The model against measured runs: each experiment, the whole suite, and where it fails.
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/io/suite_io.hpp"
#include "failures.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct CompareOptions {
  std::string suite;
  double alpha = kDefaultAlpha;
  std::string json;
  int order = 2;
};

std::string side_by_side(const std::string& left, const std::string& right) {
  std::istringstream l(left), r(right);
  std::string a, b, out;
  while (true) {
    const bool has_a = static_cast<bool>(std::getline(l, a));
    const bool has_b = static_cast<bool>(std::getline(r, b));
    if (!has_a && !has_b) break;
    if (!has_a) a.clear();
    if (!has_b) b.clear();
    a.resize(44, ' ');
    out += a + b + "\n";
  }
  return out;
}

}  // namespace

std::string comparison_text(const Suite& suite, const Comparison& c) {
  std::ostringstream out;
  out << "odomcov compare: " << suite.name << " (" << suite.experiments.size()
      << " experiments), family-wise alpha = " << c.alpha << " (" << sci(c.alpha_per_test, 2)
      << " per test)\n";
  for (const ExperimentComparison& e : c.experiments) {
    out << "\n== " << e.name << " (n = " << e.n << "): " << e.verdict << "\n"
        << side_by_side("  measured error (true - odometry)\n" +
                            moments_text(e.measured.mean, e.measured.cov),
                        "predicted\n" + moments_text(e.predicted_mean, e.predicted_cov))
        << "  mean (" << (e.n > 3 ? "Hotelling T^2" : "chi^2") << "): " << test_text(e.mean_test)
        << "\n  covariance ("
        << (e.cov_method == "nees" ? std::string("NEES sum, two-sided")
                                   : e.cov_method == "lrt" ? std::string("LRT") : e.cov_method)
        << "): " << test_text(e.cov_test) << "\n  NEES mean " << fixed(e.nees_mean, 3)
        << " (expected 3), outside the 95% bound: " << fixed(100 * e.outside_95, 1)
        << "%, log-likelihood " << fixed(e.log_likelihood, 2) << "\n";
    for (const std::string& x : e.extrapolation) out << "  outside the model's training domain: " << x << "\n";
  }
  out << "\nSuite: log-likelihood " << fixed(c.log_likelihood, 2) << "; Mardia kurtosis "
      << (c.kurtosis.valid ? fixed(c.mardia_b2, 2) + " (Gaussian " + fixed(c.mardia_expected, 2) +
                                 "), p = " + sci(c.kurtosis.p_value, 2)
                           : std::string("n/a (no experiment has 10 runs)"))
      << "\nverdict: " << c.verdict << "\n";
  std::size_t outside = 0;
  for (const ExperimentComparison& e : c.experiments) outside += e.extrapolation.empty() ? 0 : 1;
  if (outside > 0) {
    out << "The model extrapolates: " << outside << " of " << c.experiments.size()
        << " experiments lie outside the domain it was calibrated on (listed above).\n";
  }
  if (!c.failures.empty()) {
    out << "Where it fails (worst first):\n";
    for (const std::string& f : failure_texts(c)) out << "  - " << f << "\n";
  }
  return out.str();
}

json comparison_json(const Suite& suite, const Comparison& c) {
  json experiments = json::array();
  for (const ExperimentComparison& e : c.experiments) {
    json errors = json::array();
    for (const Vector3& error : e.errors) errors.push_back(to_json(error));
    json tests = {{"mean", test_json(e.mean_test)}, {"covariance", test_json(e.cov_test)}};
    tests["covariance"]["method"] = e.cov_method;
    experiments.push_back({{"name", e.name},
                           {"n", e.n},
                           {"measured", moments_json(e.measured.mean, e.measured.cov)},
                           {"predicted", moments_json(e.predicted_mean, e.predicted_cov)},
                           {"tests", tests},
                           {"nees_mean", e.nees_mean},
                           {"outside_95", e.outside_95},
                           {"log_likelihood", e.log_likelihood},
                           {"verdict", e.verdict.name()},
                           {"extrapolation", e.extrapolation},
                           {"errors", errors}});
  }
  json kurtosis = test_json(c.kurtosis);
  kurtosis["b2"] = c.mardia_b2;
  kurtosis["b2_gaussian"] = c.mardia_expected;
  kurtosis["lrt_scale"] = c.kurtosis_scale;
  return {{"suite", suite.name},
          {"alpha", c.alpha},
          {"alpha_per_test", c.alpha_per_test},
          {"experiments", experiments},
          {"kurtosis", kurtosis},
          {"log_likelihood", c.log_likelihood},
          {"verdict", c.verdict.name()},
          {"failures", failure_texts(c)}};
}

namespace {

int run_compare(const CompareOptions& opt) {
  check_alpha(opt.alpha);
  check_order(opt.order);
  if (!opt.json.empty()) check_output_path(opt.json);
  const Suite suite = load_suite(opt.suite);
  check_second_order_size(suite, opt.order);
  SuiteModel model = suite_model(suite);
  model.order = opt.order;
  const Comparison c = compare(suite, model, opt.alpha);
  std::cout << comparison_text(suite, c);
  if (!opt.json.empty()) write_json_atomic(opt.json, comparison_json(suite, c));
  return kExitOk;
}

}  // namespace

void setup_compare(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<CompareOptions>();
  CLI::App* cmd = app.add_subcommand("compare", "The model against measured runs, and where it fails");
  cmd->add_option("suite", opt->suite, "Measurement suite (YAML)")->required();
  cmd->add_option("--alpha", opt->alpha, "Family-wise significance level over the suite's tests")
      ->capture_default_str();
  cmd->add_option("--order", opt->order,
                  "Model order: 2 (default) = exact Gaussian-heading moments, 1 = first order")
      ->capture_default_str();
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->callback([opt, &exit_code] { exit_code = run_compare(*opt); });
}

}  // namespace odomcov::cli
