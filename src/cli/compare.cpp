// odomcov compare SUITE.yaml [--alpha A] [--calibration M] [--replicates B] [--seed S] [--json FILE]
// The model against measured runs: each experiment, the whole suite, and where it fails, with
// the tests calibrated by the Gaussian references or by simulating the model's world.
#include <iostream>
#include <sstream>

#include "odomcov/base/format.hpp"

#include "commands.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/io/suite_io.hpp"
#include "failures.hpp"
#include "output.hpp"
#include "referee_options.hpp"

namespace odomcov::cli {
namespace {

struct CompareOptions {
  std::string suite;
  double alpha = kDefaultAlpha;
  std::string json;
  int order = 2;
  RefereeOptions referee;
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

/// A test's line: its statistic and p-value, and under the simulation the Gaussian reference's
/// p-value beside it.
std::string calibrated_test_text(const TestResult& t, const CalibratedTest& c, const Calibration& cal) {
  std::string text = test_text(t);
  if (t.valid && cal.method == CalibrationMethod::simulation) {
    text += " (Gaussian reference p = " + sci(c.p_gaussian, 2) + "; family-wise p = " +
            format_number(c.p_family, "%.3g") + ")";
  }
  return text;
}

json calibrated_test_json(const TestResult& t, const CalibratedTest& c) {
  json out = test_json(t);
  if (!t.valid) return out;
  out["p_value_gaussian"] = c.p_gaussian;
  out["p_value_mc_error"] = c.p_mc_error;
  out["p_family"] = c.p_family;
  out["p_family_mc_error"] = c.p_family_mc_error;
  return out;
}

}  // namespace

std::string comparison_text(const Suite& suite, const Comparison& c) {
  std::ostringstream out;
  out << "odomcov compare: " << suite.name << " (" << suite.experiments.size()
      << " experiments), family-wise alpha = " << c.alpha << " (" << sci(c.alpha_per_test, 2)
      << " per test)\n"
      << calibration_text(c.calibration) << "\n";
  for (const ExperimentComparison& e : c.experiments) {
    out << "\n== " << e.name << " (n = " << e.n << "): " << e.verdict << "\n"
        << side_by_side("  measured error (true - odometry)\n" +
                            moments_text(e.measured.mean, e.measured.cov),
                        "predicted\n" + moments_text(e.predicted_mean, e.predicted_cov))
        << "  mean (" << (e.n > 3 ? "Hotelling T^2" : "chi^2")
        << "): " << calibrated_test_text(e.mean_test, e.mean_calibration, c.calibration)
        << "\n  covariance ("
        << (e.cov_method == "nees" ? std::string("NEES sum, two-sided")
                                   : e.cov_method == "lrt" ? std::string("LRT") : e.cov_method)
        << "): " << calibrated_test_text(e.cov_test, e.cov_calibration, c.calibration) << "\n  NEES mean " << fixed(e.nees_mean, 3)
        << " (expected 3), outside the 95% bound: " << fixed(100 * e.outside_95, 1)
        << "%, log-likelihood " << fixed(e.log_likelihood, 2) << "\n";
    for (const std::string& x : e.extrapolation) out << "  outside the model's training domain: " << x << "\n";
  }
  out << "\nSuite: log-likelihood " << fixed(c.log_likelihood, 2) << "; Mardia kurtosis "
      << (c.kurtosis.valid ? fixed(c.mardia_b2, 2) + " (Gaussian " + fixed(c.mardia_expected, 2) +
                                 (c.calibration.method == CalibrationMethod::simulation
                                      ? ", the model's world " + fixed(c.mardia_model, 2)
                                      : std::string()) +
                                 "), p = " + sci(c.kurtosis.p_value, 2)
                           : "n/a (" + no_kurtosis_reason(suite) + ")")
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
    json tests = {{"mean", calibrated_test_json(e.mean_test, e.mean_calibration)},
                  {"covariance", calibrated_test_json(e.cov_test, e.cov_calibration)}};
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
  json kurtosis = calibrated_test_json(c.kurtosis, c.kurtosis_calibration);
  kurtosis["b2"] = c.mardia_b2;
  kurtosis["b2_gaussian"] = c.mardia_expected;
  kurtosis["b2_model"] = c.mardia_model;
  json out = {{"suite", suite.name},
              {"alpha", c.alpha},
              {"alpha_per_test", c.alpha_per_test},
              {"experiments", experiments},
              {"kurtosis", kurtosis},
              {"log_likelihood", c.log_likelihood},
              {"verdict", c.verdict.name()},
              {"failures", failure_texts(c)}};
  out.update(calibration_json(c.calibration));
  return out;
}

namespace {

int run_compare(const CompareOptions& opt) {
  check_alpha(opt.alpha);
  check_order(opt.order);
  if (!opt.json.empty()) check_output_path(opt.json);
  calibration_options(opt.referee, nullptr);  // usage errors before any work
  const Suite suite = load_suite(opt.suite);
  check_second_order_size(suite, opt.order);
  SuiteModel model = suite_model(suite);
  model.order = opt.order;
  RefereeProgress progress;
  const CalibrationOptions calibration = calibration_options(opt.referee, &progress);
  const auto bar = referee_bar(progress);
  const Comparison c = compare(suite, model, opt.alpha, calibration);
  bar->finish();
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
  add_referee_options(cmd, opt->referee);
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->callback([opt, &exit_code] { exit_code = run_compare(*opt); });
}

}  // namespace odomcov::cli
