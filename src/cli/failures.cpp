#include "failures.hpp"

#include <cmath>

#include "odomcov/base/format.hpp"

namespace odomcov::cli {
namespace {

const char* const kComponent[3] = {"x", "y", "theta"};
const char* const kUnit[3] = {"m", "m", "rad"};

std::string tails_text(const Comparison& c) {
  const std::string p = ", p = " + format_number(c.kurtosis.p_value, "%.2g");
  const std::string b2 = "Mardia kurtosis " + format_number(c.mardia_b2, "%.1f") + " against ";
  if (c.calibration.method == CalibrationMethod::simulation) {
    return std::string(c.mardia_b2 > c.mardia_model ? "tails heavier" : "tails lighter") +
           " than the model's world: " + b2 + format_number(c.mardia_model, "%.1f") +
           " there (" + format_number(c.mardia_expected, "%.1f") + " if Gaussian)" + p;
  }
  return std::string(c.kurtosis.statistic > 0 ? "tails heavier" : "tails lighter") + " than Gaussian: " +
         b2 + format_number(c.mardia_expected, "%.1f") + p;
}

}  // namespace

std::string failure_text(const Comparison& c, const Failure& f) {
  if (f.kind == Failure::Kind::tails) return tails_text(c);
  const ExperimentComparison& e = c.experiments.at(static_cast<std::size_t>(f.experiment));
  const int k = f.component;
  const std::string head = e.name + ": ";
  switch (f.kind) {
    case Failure::Kind::mean:
      return head + kComponent[k] + " mean " + format_number(e.measured.mean(k), "%.4g") + " " +
             kUnit[k] + ", " + format_number(std::abs(e.mean_t(k)), "%.1f") +
             " standard errors from the predicted " + format_number(e.predicted_mean(k), "%.4g");
    case Failure::Kind::joint_mean: {
      const int b = f.other;
      auto part = [&e](int i) {
        return std::string(kComponent[i]) + " mean " + format_number(e.measured.mean(i), "%.4g") + " " + kUnit[i] +
               " against " + format_number(e.predicted_mean(i), "%.4g");
      };
      return head + kComponent[k] + " and " + kComponent[b] + " means together " +
             format_number(e.joint_mean_t(k, b), "%.1f") +
             " standard errors off the prediction, though " + format_number(std::abs(e.mean_t(k)), "%.1f") +
             " and " + format_number(std::abs(e.mean_t(b)), "%.1f") + " alone (their errors correlate at " +
             format_number(e.mean_correlation(k, b), "%.2f") + "): " + part(k) + ", " + part(b);
    }
    case Failure::Kind::variance:
      return head + kComponent[k] + " variance " + format_number(e.variance_ratio(k), "%.2g") +
             "x predicted";
    case Failure::Kind::correlation:
      return head + kComponent[k] + "-" + kComponent[f.other] + " correlation " +
             format_number(e.measured_correlation(k, f.other), "%.2f") + " measured against " +
             format_number(e.predicted_correlation(k, f.other), "%.2f") + " predicted";
    default:  // spread
      return head + "errors " + format_number(std::sqrt(e.nees_mean / 3.0), "%.2g") +
             "x the predicted spread (NEES " + format_number(e.nees_mean, "%.3g") + " per run against 3)";
  }
}

std::string no_kurtosis_reason(const Suite& suite) {
  for (const SuiteExperiment& e : suite.experiments) {
    if (static_cast<std::int64_t>(e.runs.size()) >= kMinRunsForLrt) {
      return "no experiment of " + std::to_string(kMinRunsForLrt) +
             " runs or more has whitened errors that spread in all three components";
    }
  }
  return "no experiment has " + std::to_string(kMinRunsForLrt) + " runs";
}

std::vector<std::string> failure_texts(const Comparison& c) {
  std::vector<std::string> out;
  for (const Failure& f : c.failures) out.push_back(failure_text(c, f));
  return out;
}

}  // namespace odomcov::cli
