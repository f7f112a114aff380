#include "odomcov/measurement/comparison.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>

#include "odomcov/measurement/domain.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;
/// The LRT's Bartlett-corrected chi^2 is accurate from about ten runs; below, the NEES test.
constexpr std::int64_t kMinRunsForLrt = 10;
/// chi^2_3 95% point (Abramowitz & Stegun 26.8): the NEES bound of "outside_95".
constexpr double kChi2_3_95 = 7.814727903251178;

double student_t_two_sided(double t, double dof) {
  if (!(dof > 0) || !std::isfinite(t)) return std::isfinite(t) ? 1.0 : 0.0;
  return 2.0 * boost::math::cdf(boost::math::complement(boost::math::students_t(dof), std::abs(t)));
}

double chi2_two_sided(double x, double dof) {
  if (!std::isfinite(x) || !(dof > 0)) return std::numeric_limits<double>::quiet_NaN();
  const boost::math::chi_squared d(dof);
  const double lower = boost::math::cdf(d, std::max(x, 0.0));
  return std::min(1.0, 2.0 * std::min(lower, 1.0 - lower));
}

/// The predicted mean and covariance of a run drawn from the experiment (a mixture over its
/// runs), each run on its own (`own`: the between-group spread included).
void predicted_block(const std::vector<RunResidual>& own, ExperimentComparison& c) {
  const double n = static_cast<double>(own.size());
  Matrix3 mean_cov = Matrix3::Zero();
  MomentAccumulator means;
  for (const RunResidual& r : own) {
    mean_cov += r.cov / n;
    means.add(r.mean);
  }
  c.predicted_mean = means.mean();
  c.predicted_cov = mean_cov + means.scatter() / n;
}

/// `res` are the runs' predictions given the earlier runs of their groups
/// (condition_on_groups), so whitening each run by its own covariance whitens the groups
/// jointly; `own` are the runs' predictions on their own (marginal), for the predicted block.
ExperimentComparison compare_experiment(const SuiteExperiment& ex,
                                        const std::vector<RunResidual>& res,
                                        const std::vector<RunResidual>& own, double alpha_test,
                                        std::vector<Vector3>& whitened) {
  ExperimentComparison c;
  c.name = ex.name;
  c.n = static_cast<std::int64_t>(res.size());
  const double n = static_cast<double>(c.n);
  std::vector<Vector3> errors, raw;
  whitened.clear();
  Matrix3 mean_cov = Matrix3::Zero();
  // A prediction that cannot whiten (singular or non-finite covariance, e.g. no wheel noise and
  // no measurement noise) leaves the experiment untestable, with no statistic computed from it.
  for (const RunResidual& r : res) {
    const Eigen::LLT<Matrix3> llt(r.cov);
    if (llt.info() != Eigen::Success || !r.cov.allFinite() || !r.error.allFinite() ||
        !r.mean.allFinite()) {
      for (const RunResidual& q : res) c.errors.push_back(q.error);
      c.measured = moments(c.errors);
      c.mean_test.valid = c.cov_test.valid = false;
      c.cov_method = "none";
      c.verdict = Verdict::untestable("the predicted covariance is singular or not finite "
                                      "(no wheel noise and no measurement noise?)");
      whitened.clear();
      return c;
    }
  }
  for (const RunResidual& r : res) {
    errors.push_back(r.error);
    raw.push_back(r.error - r.mean);
    const Eigen::LLT<Matrix3> llt(r.cov);
    const Vector3 z = llt.matrixL().solve(r.error - r.mean);
    whitened.push_back(z);
    const double nees = z.squaredNorm();
    c.nees_mean += nees / n;
    c.outside_95 += (nees > kChi2_3_95 ? 1.0 : 0.0) / n;
    c.log_likelihood += gaussian_log_density(r.error, r.mean, r.cov);
    mean_cov += r.cov / n;
  }
  c.measured = moments(errors);
  c.errors = std::move(errors);
  predicted_block(own, c);

  const SampleMoments z = moments(whitened);
  c.mean_test = c.n > kDim ? hotelling_test(z, Vector3::Zero())
                           : mean_test_known_covariance(z, Vector3::Zero(), Matrix3::Identity());
  if (c.n >= kMinRunsForLrt) {
    c.cov_test = covariance_test(z, Matrix3::Identity());
    c.cov_method = "lrt";
  } else {
    c.cov_test.statistic = c.nees_mean * n;
    c.cov_test.dof = kDim * static_cast<int>(c.n);
    c.cov_test.p_value = chi2_two_sided(c.cov_test.statistic, c.cov_test.dof);
    c.cov_method = "nees";
  }
  const SampleMoments r = moments(raw);
  for (int k = 0; k < kDim; ++k) {
    // Like the joint test: the sample's own standard error (Student t) when the experiment is
    // large enough for Hotelling, else the predicted one (normal).
    const double sd = std::sqrt(std::max(r.cov(k, k), 0.0));
    if (!(mean_cov(k, k) > 0) && !(c.n > kDim && sd > 0)) continue;
    if (c.n > kDim && sd > 0) {
      c.mean_t(k) = r.mean(k) / (sd / std::sqrt(n));
      c.mean_p(k) = student_t_two_sided(c.mean_t(k), n - 1);
    } else {
      c.mean_t(k) = r.mean(k) / std::sqrt(mean_cov(k, k) / n);
      c.mean_p(k) = 2.0 * boost::math::cdf(boost::math::complement(boost::math::normal(),
                                                                   std::abs(c.mean_t(k))));
    }
    if (c.n > 1 && mean_cov(k, k) > 0) {
      c.variance_ratio(k) = r.cov(k, k) / mean_cov(k, k);
      c.variance_p(k) = chi2_two_sided((n - 1) * c.variance_ratio(k), n - 1);
    }
  }
  c.verdict = verdict(c.mean_test, c.cov_test, alpha_test);
  return c;
}

/// The mean failures of an experiment whose mean test fails: its worst component, and every
/// other component significant on its own.
void add_mean_failures(const ExperimentComparison& c, int index, double alpha_test, std::vector<Failure>& out) {
  int worst = 0;
  for (int k = 1; k < kDim; ++k) worst = c.mean_p(k) < c.mean_p(worst) ? k : worst;
  for (int k = 0; k < kDim; ++k) {
    if (k != worst && !(c.mean_p(k) < alpha_test)) continue;
    out.push_back({Failure::Kind::mean, index, k, k});
  }
}

/// The correlation failure: the pair of components whose measured and predicted correlations
/// differ most.
Failure worst_correlation(const ExperimentComparison& c, int index) {
  double worst = -1;
  Failure f{Failure::Kind::correlation, index, 0, 1};
  for (int a = 0; a < kDim; ++a) {
    for (int b = a + 1; b < kDim; ++b) {
      const double d = std::abs(c.measured_correlation(a, b) - c.predicted_correlation(a, b));
      if (d > worst) worst = d, f.component = a, f.other = b;
    }
  }
  return f;
}

/// The covariance failures of an experiment whose covariance test fails: the components whose
/// variance is significantly off; else the spread as a whole (the NEES test); else the worst
/// correlation.
void add_covariance_failures(const ExperimentComparison& c, int index, double alpha_test,
                             std::vector<Failure>& out) {
  bool named = false;
  for (int k = 0; k < kDim; ++k) {
    if (!(c.variance_p(k) < alpha_test)) continue;
    out.push_back({Failure::Kind::variance, index, k, k});
    named = true;
  }
  if (named) return;
  if (c.cov_method == "nees") {
    out.push_back({Failure::Kind::spread, index, 0, 0});
    return;
  }
  out.push_back(worst_correlation(c, index));
}

/// Where one experiment fails, worst component first (the CLI words them: src/cli/failures.cpp).
void add_failures(const ExperimentComparison& c, int index, double alpha_test,
                  std::vector<Failure>& out) {
  if (c.mean_test.valid && c.mean_test.p_value < alpha_test) add_mean_failures(c, index, alpha_test, out);
  if (c.cov_test.valid && c.cov_test.p_value < alpha_test) add_covariance_failures(c, index, alpha_test, out);
}

/// Mardia's multivariate kurtosis b2 [Mardia70] of one experiment's whitened residuals z, each
/// standardised by the experiment's own mean and (maximum-likelihood) covariance.
double mardia_b2(const std::vector<Vector3>& z) {
  const double n = static_cast<double>(z.size());
  const SampleMoments m = moments(z);
  const Matrix3 S = m.cov * ((n - 1) / n);
  const Eigen::LLT<Matrix3> llt(S);
  double b2 = 0.0;
  for (const Vector3& v : z) {
    const double q = (v - m.mean).dot(llt.solve(v - m.mean));
    b2 += q * q / n;
  }
  return b2;
}

/// The experiments' kurtoses pooled with Mardia's exact moments [Mardia74], weighted by their
/// run counts n: E b2 = p(p+2)(n-1)/(n+1),
/// Var b2 = 8p(p+2)(n-3)(n-p-1)(n-p+1)/((n+1)^2 (n+3)(n+5)), z = sum n(b2 - E)/sqrt(sum n^2 Var).
struct KurtosisPool {
  double excess = 0.0, variance = 0.0, weight = 0.0, b2_sum = 0.0, expected_sum = 0.0;

  /// Adds an experiment's whitened residuals; returns its b2/E b2.
  double add(const std::vector<Vector3>& z) {
    const double n = static_cast<double>(z.size());
    const double b2 = mardia_b2(z);
    constexpr double p = kDim;
    const double expected = p * (p + 2) * (n - 1) / (n + 1);
    const double var = 8 * p * (p + 2) * (n - 3) * (n - p - 1) * (n - p + 1) /
                       ((n + 1) * (n + 1) * (n + 3) * (n + 5));
    excess += n * (b2 - expected);
    variance += n * n * var;
    weight += n;
    b2_sum += n * b2;
    expected_sum += n * expected;
    return b2 / expected;
  }
};

/// A model with a heavy-tailed effect (bumps) predicts tails: then the kurtosis is
/// information, not a failure, and a Gaussian LRT's null distribution is wider by the
/// kurtosis factor 1 + kappa = b2/E b2, so each experiment's statistic is divided by its own
/// factor `kurtosis_ratio` (the scaled test of [Browne84] for elliptical errors) before the
/// verdicts. Its own: a short experiment sees a bump or two per run and far heavier tails
/// than a long one.
void scale_by_kurtosis(Comparison& out, const std::vector<double>& kurtosis_ratio) {
  out.kurtosis_scale = out.mardia_b2 / out.mardia_expected;
  for (std::size_t i = 0; i < out.experiments.size(); ++i) {
    ExperimentComparison& e = out.experiments[i];
    if (e.cov_method != "lrt" || !e.cov_test.valid) continue;
    e.cov_test.statistic /= std::max(1.0, kurtosis_ratio[i]);
    e.cov_test.p_value = chi2_sf(e.cov_test.statistic, e.cov_test.dof);
    e.cov_method = "lrt, kurtosis-scaled";
    e.verdict = verdict(e.mean_test, e.cov_test, out.alpha_per_test);
  }
}

/// The pooled kurtosis test (two-sided normal), with the covariance LRTs scaled when the model
/// expects tails; not valid when no experiment is large enough to tell a shape.
void kurtosis_test(const KurtosisPool& pool, bool tails_expected,
                   const std::vector<double>& kurtosis_ratio, Comparison& out) {
  if (!(pool.weight > 0)) {
    out.kurtosis.valid = false;  // no experiment is large enough to tell a shape
    return;
  }
  out.mardia_b2 = pool.b2_sum / pool.weight;
  out.mardia_expected = pool.expected_sum / pool.weight;
  if (tails_expected && out.mardia_b2 > out.mardia_expected) scale_by_kurtosis(out, kurtosis_ratio);
  out.kurtosis.statistic = pool.excess / std::sqrt(pool.variance);
  out.kurtosis.dof = 0;
  out.kurtosis.p_value = 2.0 * boost::math::cdf(boost::math::complement(
                                   boost::math::normal(), std::abs(out.kurtosis.statistic)));
}

/// The overall verdict and the failures, worst experiment first (smallest p-value, ties of
/// p underflowing to 0 broken by the NEES per run), then the tails unless the model
/// expects them.
void verdict_and_failures(Comparison& out, bool tails_expected) {
  std::vector<const ExperimentComparison*> order;
  for (const auto& c : out.experiments) order.push_back(&c);
  auto worst_p = [](const ExperimentComparison* c) {
    return std::min(c->mean_test.valid ? c->mean_test.p_value : 1.0,
                    c->cov_test.valid ? c->cov_test.p_value : 1.0);
  };
  std::stable_sort(order.begin(), order.end(), [&](auto* a, auto* b) {
    return worst_p(a) != worst_p(b) ? worst_p(a) < worst_p(b) : a->nees_mean > b->nees_mean;
  });
  Verdict overall;
  for (const ExperimentComparison* c : order) {
    overall.combine(c->verdict);
    add_failures(*c, static_cast<int>(c - out.experiments.data()), out.alpha_per_test, out.failures);
  }
  if (out.kurtosis.valid && out.kurtosis.p_value < out.alpha_per_test && !tails_expected) {
    overall.combine({Verdict::Kind::inconsistent, ""});
    out.failures.push_back({Failure::Kind::tails, -1, 0, 0});
  }
  out.verdict = overall;
}

}  // namespace

double ExperimentComparison::measured_correlation(int a, int b) const {
  return measured.cov(a, b) / std::sqrt(measured.cov(a, a) * measured.cov(b, b));
}

double ExperimentComparison::predicted_correlation(int a, int b) const {
  return predicted_cov(a, b) / std::sqrt(predicted_cov(a, a) * predicted_cov(b, b));
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha) {
  return compare(suite, model, alpha, residuals(suite, model));
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::vector<RunResidual>>& grouped) {
  Comparison out;
  out.alpha = alpha;
  out.alpha_per_test = alpha / static_cast<double>(2 * suite.experiments.size() + 1);
  const auto res = condition_on_groups(grouped);
  const auto own = marginal(grouped);
  // Mardia's multivariate kurtosis [Mardia70] as a test of shape only: each experiment's
  // whitened residuals are standardised by that experiment's own mean and covariance (so scale
  // and mean misfits, which differ between experiments, do not read as tails), and the
  // experiments with at least kMinRunsForLrt runs are pooled (KurtosisPool).
  bool tails_expected = false;
  for (const EffectSpec& e : model.effects) tails_expected = tails_expected || info_of(e)->heavy_tails;
  KurtosisPool pool;
  std::vector<double> kurtosis_ratio(suite.experiments.size(), 1.0);  // b2/E b2 per experiment
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    std::vector<Vector3> z;
    out.experiments.push_back(
        compare_experiment(suite.experiments[e], res[e], own[e], out.alpha_per_test, z));
    out.log_likelihood += out.experiments.back().log_likelihood;
    if (z.size() < static_cast<std::size_t>(kMinRunsForLrt)) continue;
    kurtosis_ratio[e] = pool.add(z);
  }
  kurtosis_test(pool, tails_expected, kurtosis_ratio, out);
  verdict_and_failures(out, tails_expected);
  for (std::size_t e = 0; model.domain && e < suite.experiments.size(); ++e) {
    out.experiments[e].extrapolation = extrapolation(*model.domain, suite.experiments[e], model.robot.wheelbase_m);
  }
  return out;
}

}  // namespace odomcov
