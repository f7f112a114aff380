// Cross-validation: a model is judged by what it predicts on runs it was not fitted on. The
// suite's experiments are split into folds (their kinds, else their groups, else K folds over
// the experiments); a fit is repeated on each fold's complement and scored on the fold.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/measurement/calibration.hpp"

namespace odomcov {

/// At most this many folds: kinds or groups beyond it share folds (round robin), and K-fold
/// cross-validation over experiments uses it as K. Five folds keep each training set at 4/5 of
/// the runs while a round costs five fits per candidate.
inline constexpr std::size_t kMaxFolds = 5;

/// Leave-one-kind-out needs this many kinds: with two, each fit would see a single kind of
/// path, and an effect that only one kind shows (a wheelbase on spins, a scale on lines) could
/// not be tested at all; K folds over the experiments test it within its kind.
inline constexpr std::size_t kMinKindFolds = 3;

/// How a suite's experiments are split for cross-validation.
struct Folds {
  /// What the folds are: "kind" (leave one kind of path out), "group" (leave one group out),
  /// "experiments" (K folds over the experiments), or "" (no cross-validation: one experiment).
  std::string by;
  std::vector<std::string> names;   // each fold's label: its kind(s), group(s) or experiments
  std::vector<int> of_experiment;   // the fold of each experiment of the suite
  std::size_t size() const { return names.size(); }
  /// One flag per experiment: true for the experiments fold f is fitted on (every other fold).
  std::vector<bool> training(std::size_t fold) const;
};

/// The folds of a suite: its experiments' kinds (SuiteExperiment::kind) when there are
/// kMinKindFolds or more, else its groups when every experiment has one and there are two or
/// more, else K = min(kMaxFolds, experiments) folds with experiment i in fold i mod K; none for
/// a single experiment. More kinds or groups than kMaxFolds share folds in order of first
/// appearance (round robin).
Folds make_folds(const Suite& suite);
/// K = min(kMaxFolds, experiments) folds over the experiments, experiment i in fold i mod K (none
/// for a single experiment): make_folds' last resort, and diagnose's fallback for a candidate
/// that no kind of path can test (each fold then keeps every kind in its training runs).
Folds experiment_folds(const Suite& suite);

/// Two folds along a feature of the path: the experiments below the median of `values` (one
/// per experiment, experiment_feature_values) and those at or above it, so that a fit on one
/// side predicts the other (by = "feature"). When ties leave one side empty, the split is at
/// the median's other edge; none when every experiment has the same value. An experiment
/// without a value (no runs) joins the first fold.
Folds feature_folds(const std::vector<double>& values, const std::string& feature);

/// A fit repeated on each fold's complement.
struct FoldFits {
  std::vector<SuiteModel> models;  // per fold: fitted on every other fold's runs
  /// Per fold: the standard errors of every fitted parameter in that fold's fit (NaN where it
  /// has none), in the order of the names fitted.
  std::vector<std::vector<double>> stderrs;
};

/// For each fold f: fits `names` from `start` on the runs of every other fold, on a view of
/// `cache` (the round's fit path; on the fast path then refit_exactly over `own`, the nonlinear
/// parameters of a candidate, or over every name when `own` is empty: the base). No names:
/// `start` for every fold. `cache` belongs to the whole
/// suite, so each fold's model is propagated once for all its runs, the held-out ones
/// included. `path`: exact fits each fold on the exact path (diagnose --exact). `refit`
/// false: no exact refit after a fast fit (a screen, whose findings are then refitted).
FoldFits fit_folds(ResidualCache& cache, const Folds& folds, const SuiteModel& start,
                   const std::vector<std::string>& names, const std::vector<std::string>& own,
                   Likelihood kind, std::atomic<std::int64_t>* evaluations = nullptr,
                   FitPath path = FitPath::fast, bool refit = true);

/// The held-out log-likelihood of the runs outside `training` (one flag per experiment) given
/// the runs inside it: log L(all) - log L(training). For independent runs it is the held-out
/// runs' own log-density; with group_variation, their density given the training runs of their
/// groups (the chain rule). The scatter part is a sum over experiments, so there it is the
/// held-out experiments' own.
double held_out_log_likelihood(const std::vector<std::vector<RunResidual>>& all,
                               const std::vector<bool>& training, Likelihood kind);

/// held_out_log_likelihood in its parts, one per held-out run, which sum to it. Of the full
/// likelihood, a run's density given the training runs and the held-out runs before it (the
/// chain rule: under the model the parts are uncorrelated, even within a group); of the scatter
/// part, a run's deviation from its experiment's mean (n runs' deviations correlate by
/// -1/(n - 1), their squares by order 1/n^2).
std::vector<double> held_out_parts(const std::vector<std::vector<RunResidual>>& all,
                                   const std::vector<bool>& training, Likelihood kind);

/// The sampling standard deviation of a sum of n independent parts, estimated from their
/// scatter: sqrt(n s^2), s^2 their sample variance (the studentised log-likelihood ratio of
/// [Vuong89]). NaN for fewer than 2 parts or a non-finite part.
double spread_of_sum(const std::vector<double>& parts);

/// The log-likelihood of the kind asked for: the full one or its scatter part.
double log_likelihood_of(const std::vector<std::vector<RunResidual>>& residuals, Likelihood kind);

}  // namespace odomcov
