#include "odomcov/measurement/cross_validation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>

#include "odomcov/base/format.hpp"

namespace odomcov {
namespace {

/// Each experiment's label by `key` (kind or group), the distinct labels in order of first
/// appearance, and the experiments' indices into them.
struct Labels {
  std::vector<std::string> distinct;
  std::vector<int> of_experiment;
};
template <class Key>
Labels labels_of(const Suite& suite, Key key) {
  Labels out;
  std::map<std::string, int> index;
  for (const SuiteExperiment& ex : suite.experiments) {
    const std::string label = key(ex);
    const auto [it, added] = index.emplace(label, static_cast<int>(out.distinct.size()));
    if (added) out.distinct.push_back(label);
    out.of_experiment.push_back(it->second);
  }
  return out;
}

/// Folds from labels: one per label, or kMaxFolds shared round robin when there are more.
Folds folds_of(const std::string& by, const Labels& labels) {
  Folds f;
  f.by = by;
  const std::size_t count = std::min(labels.distinct.size(), kMaxFolds);
  f.names.assign(count, "");
  for (std::size_t l = 0; l < labels.distinct.size(); ++l) {
    std::string& name = f.names[l % count];
    name += (name.empty() ? "" : "+") + labels.distinct[l];
  }
  for (int l : labels.of_experiment) f.of_experiment.push_back(static_cast<int>(static_cast<std::size_t>(l) % count));
  return f;
}

/// The standard errors of `names` in a fit (NaN where it has none or lacks the name).
std::vector<double> stderrs_of(const FitResult& fit, const std::vector<std::string>& names) {
  std::vector<double> out;
  for (const std::string& name : names) {
    const auto at = std::find(fit.names.begin(), fit.names.end(), name);
    out.push_back(at == fit.names.end() ? std::numeric_limits<double>::quiet_NaN()
                                        : fit.stderrs(static_cast<Eigen::Index>(at - fit.names.begin())));
  }
  return out;
}

}  // namespace

std::vector<bool> Folds::training(std::size_t fold) const {
  std::vector<bool> keep;
  for (int f : of_experiment) keep.push_back(static_cast<std::size_t>(f) != fold);
  return keep;
}

Folds make_folds(const Suite& suite) {
  const Labels kinds = labels_of(suite, [](const SuiteExperiment& ex) { return experiment_kind(ex); });
  if (kinds.distinct.size() >= kMinKindFolds) return folds_of("kind", kinds);
  const Labels groups = labels_of(suite, [](const SuiteExperiment& ex) { return ex.group; });
  const bool grouped = std::none_of(suite.experiments.begin(), suite.experiments.end(),
                                    [](const SuiteExperiment& ex) { return ex.group.empty(); });
  if (grouped && groups.distinct.size() >= 2) return folds_of("group", groups);
  return experiment_folds(suite);
}

Folds experiment_folds(const Suite& suite) {
  if (suite.experiments.size() < 2) return {};
  const Labels each = labels_of(suite, [](const SuiteExperiment& ex) { return ex.name; });
  return folds_of("experiments", each);
}

Folds feature_folds(const std::vector<double>& values, const std::string& feature) {
  std::vector<double> known;
  for (double v : values) {
    if (std::isfinite(v)) known.push_back(v);
  }
  if (known.size() < 2) return {};
  std::sort(known.begin(), known.end());
  const double median = known[known.size() / 2];
  // Below the median, else at or below it when nothing lies below (ties at the bottom).
  const bool below = known.front() < median;
  const auto high = [&](double v) { return below ? v >= median : v > median; };
  if (!below && !(known.back() > median)) return {};
  Folds f;
  f.by = "feature";
  const std::string edge = format_number(median, "%.3g");
  f.names = {feature + (below ? " below " : " up to ") + edge, feature + (below ? " from " : " above ") + edge};
  for (double v : values) f.of_experiment.push_back(std::isfinite(v) && high(v) ? 1 : 0);
  return f;
}

double log_likelihood_of(const std::vector<std::vector<RunResidual>>& residuals, Likelihood kind) {
  return kind == Likelihood::full ? log_likelihood(residuals) : scatter_log_likelihood(residuals);
}

FoldFits fit_folds(ResidualCache& cache, const Folds& folds, const SuiteModel& start,
                   const std::vector<std::string>& names, const std::vector<std::string>& own,
                   Likelihood kind, std::atomic<std::int64_t>* evaluations, FitPath path, bool refit) {
  FoldFits out;
  for (std::size_t f = 0; f < folds.size(); ++f) {
    if (names.empty()) {
      out.models.push_back(start);
      out.stderrs.emplace_back();
      continue;
    }
    ResidualCache view(cache, folds.training(f));
    const FitResult first = fit(cache.suite(), start, names, kind, evaluations, path, &view);
    // The exact refit moves the candidate's own parameters; the base (no own ones) its whole
    // fit, so that neither side of a held-out comparison rests on the fast path alone.
    const FitResult r = refit ? refit_exactly(first, own.empty() ? names : own, kind, evaluations, view) : first;
    out.models.push_back(r.model);
    out.stderrs.push_back(stderrs_of(r, names));
  }
  return out;
}

double held_out_log_likelihood(const std::vector<std::vector<RunResidual>>& all,
                               const std::vector<bool>& training, Likelihood kind) {
  return log_likelihood_of(all, kind) - log_likelihood_of(select_experiments(all, training), kind);
}

std::vector<double> held_out_parts(const std::vector<std::vector<RunResidual>>& all,
                                   const std::vector<bool>& training, Likelihood kind) {
  // The training experiments first, then the held-out ones: each held-out run's density is then
  // the one given every training run and the held-out runs before it, and their sum is
  // log L(all) - log L(training) whatever the order of the held-out runs.
  std::vector<std::vector<RunResidual>> ordered;
  std::size_t held_runs = 0;
  for (const bool train : {true, false}) {
    for (std::size_t e = 0; e < all.size(); ++e) {
      if (training[e] != train) continue;
      ordered.push_back(all[e]);
      if (!train) held_runs += all[e].size();
    }
  }
  std::vector<double> values = run_log_likelihoods(ordered, kind == Likelihood::scatter);
  values.erase(values.begin(), values.end() - static_cast<std::ptrdiff_t>(held_runs));
  return values;
}

double spread_of_sum(const std::vector<double>& parts) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const std::size_t n = parts.size();
  if (n < 2) return kNaN;
  const double mean = std::accumulate(parts.begin(), parts.end(), 0.0) / static_cast<double>(n);
  double ss = 0.0;
  for (double d : parts) ss += (d - mean) * (d - mean);
  const double spread = std::sqrt(ss * static_cast<double>(n) / static_cast<double>(n - 1));
  return std::isfinite(spread) ? spread : kNaN;
}

}  // namespace odomcov
