// odomcov fit SUITE.yaml --params P1,P2,... [--json FILE]
// Maximum-likelihood fit of model parameters with standard errors ([Chong97] §5.2 done properly).
#include <cmath>
#include <iostream>
#include <sstream>

#include "calibrate_output.hpp"
#include "commands.hpp"
#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/design.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/io/suite_io.hpp"
#include "output.hpp"
#include "progress.hpp"

namespace odomcov::cli {
namespace {

struct FitOptions {
  std::string suite;
  std::vector<std::string> params;
  std::string json;
  int order = 2;
  bool exact = false;
};

/// Every --params name must be fittable in the suite (its custom effects' parameters
/// included) and given once.
void check_params(const std::vector<std::string>& params, const Suite& suite) {
  for (std::size_t i = 0; i < params.size(); ++i) {
    if (const std::string e = check_fit_parameter(params[i], suite.model_effects); !e.empty()) {
      throw UsageError("--params: " + e);
    }
    for (std::size_t j = 0; j < i; ++j) {
      if (params[j] == params[i]) throw UsageError("--params: " + params[i] + " given twice");
    }
  }
}

/// The report on stdout: each estimate with its (robust) standard error, the log-likelihood
/// before and after, the warnings and the fitted model's YAML.
std::string fit_report(const Suite& suite, const FitResult& r) {
  std::ostringstream out;
  out << "odomcov fit: " << suite.name << " (" << suite.experiments.size()
      << " experiments), maximum likelihood\n";
  for (std::size_t i = 0; i < r.names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double se = r.stderrs(k);
    char line[160];
    std::snprintf(line, sizeof line, "  %-32s %.6g", r.names[i].c_str(), r.values(k));
    const double rse = r.robust_stderrs(k);
    out << line
        << (std::isfinite(se) ? " +/- " + sci(se, 2) + " (robust +/- " + sci(rse, 2) + ")"
                              : std::string(" (no standard error)"))
        << "\n";
  }
  out << "log-likelihood: " << fixed(r.log_likelihood_before, 3) << " before, "
      << fixed(r.log_likelihood_after, 3) << " after (" << r.evaluations << " evaluations)\n";
  for (const std::string& w : r.warnings) out << "warning: " << w << "\n";
  out << "the fitted model, to paste over the suite's robot line and model block:\n"
      << model_yaml(r.model);
  return out.str();
}

int run_fit(const FitOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  if (opt.params.empty()) throw UsageError("--params needs at least one parameter");
  check_order(opt.order);
  const Suite suite = load_suite(opt.suite);
  check_second_order_size(suite, opt.order);
  // After loading: the suite's custom effects' parameters can be fitted too.
  check_params(opt.params, suite);
  SuiteModel model = suite_model(suite);
  model.order = opt.order;
  check_finite_start(suite, model, "fit");
  std::atomic<std::int64_t> evaluations{0};
  ProgressBar bar([&evaluations] { return evaluations.load(); },
                  std::function<std::int64_t()>([] { return std::int64_t{0}; }),
                  "likelihood evaluations");
  const FitResult r = fit(suite, model, opt.params, Likelihood::full, &evaluations,
                            opt.exact ? FitPath::exact : FitPath::fast);
  bar.finish();
  const std::vector<ConfoundedPair> confounded = confounded_pairs(r.names, estimate_covariance(suite, r));
  std::vector<UnpredictableExperiment> unpredictable;
  const std::vector<NextExperiment> next = next_experiments(suite, r, &unpredictable);
  std::cout << fit_report(suite, r) << design_report(confounded, next, unpredictable);
  if (!opt.json.empty()) {
    json doc = fit_json(r);
    doc.update(design_json(confounded, next, unpredictable));
    write_json_atomic(opt.json, doc);
  }
  return kExitOk;
}

}  // namespace

void setup_fit(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<FitOptions>();
  CLI::App* cmd = app.add_subcommand("fit", "Maximum-likelihood fit of model parameters");
  cmd->add_option("suite", opt->suite, "Measurement suite (YAML)")->required();
  cmd->add_option("--params", opt->params,
                  "Parameters: k_left, k_right, wheelbase, <effect>.<parameter>")
      ->required()
      ->delimiter(',');
  cmd->add_option("--order", opt->order,
                  "Model order: 2 (default) = exact Gaussian-heading moments, 1 = first order")
      ->capture_default_str();
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->add_flag("--exact", opt->exact,
                "Propagate every run at every likelihood evaluation (slow; the reference for the "
                "default linearised, re-anchored fit)");
  cmd->callback([opt, &exit_code] { exit_code = run_fit(*opt); });
}

}  // namespace odomcov::cli
