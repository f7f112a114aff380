#include "odomcov/measurement/comparison.hpp"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>

#include "odomcov/base/format.hpp"
#include "odomcov/measurement/domain.hpp"
#include "odomcov/measurement/referee.hpp"
#include "odomcov/measurement/sequential_test.hpp"

namespace odomcov {
namespace {

constexpr int kDim = 3;
/// tails_test pools every experiment whose b2 varies: n >= p + 2 runs (with p + 1 the
/// standardised runs form a simplex and b2 is fixed).
constexpr std::size_t kMinRunsForTails = kDim + 2;
/// chi^2_3 95% point (Abramowitz & Stegun 26.8): the NEES bound of "outside_95".
constexpr double kChi2_3_95 = 7.814727903251178;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

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

// ---- Whitening: one code path for the data and for every replicate of the referee ---------

/// One run's prediction, ready to whiten any error: its runs' grouped likelihood in the
/// sequential form of condition_on_groups (likelihood.hpp), with everything that does not
/// depend on the error computed once. Run i of a group with posterior mean m of the group's
/// constants (z, q) is predicted as N(mean + U m, cov_c), cov_c = cov + U V U^T (V, the
/// posterior covariance, does not depend on the data), and then m += G r with r its residual
/// and G = (I + V A^T A)^-1 V U^T cov^-1 (the Woodbury step, A = L^-1 U).
struct RunWhitener {
  Vector3 mean = Vector3::Zero();
  Matrix3 L = Matrix3::Identity();  // lower Cholesky factor of cov_c
  Matrix3 cov = Matrix3::Zero();    // cov_c
  Eigen::Matrix<double, 3, 2> U = Eigen::Matrix<double, 3, 2>::Zero();
  Eigen::Matrix<double, 2, 3> G = Eigen::Matrix<double, 2, 3>::Zero();
  int group = -1;      // -1: no group columns
  bool whitens = true;  // cov_c is positive definite and finite, the mean finite
};

struct Prepared {
  std::vector<RunWhitener> runs;   // every run, experiment by experiment
  std::vector<std::size_t> first;  // experiment e's runs are [first[e], first[e + 1])
  int groups = 0;
  std::size_t experiments() const { return first.size() - 1; }
  std::size_t runs_of(std::size_t e) const { return first[e + 1] - first[e]; }
};

RunWhitener whitener(const RunResidual& r, Eigen::Matrix2d& V) {
  RunWhitener w;
  w.mean = r.mean;
  w.cov = r.cov;
  const bool grouped = !r.group_column.isZero(0.0) || !r.group_column2.isZero(0.0);
  if (grouped) {
    w.U << r.group_column, r.group_column2;
    w.group = r.group;
    w.cov += w.U * V * w.U.transpose();
    const Eigen::LLT<Matrix3> own(r.cov);
    if (own.info() == Eigen::Success && r.cov.allFinite() && w.U.allFinite()) {
      const Eigen::Matrix<double, 3, 2> A = own.matrixL().solve(w.U);
      const Eigen::Matrix2d gain =
          (Eigen::Matrix2d::Identity() + V * A.transpose() * A).partialPivLu().solve(V);
      w.G = gain * own.solve(w.U).transpose();
      V = 0.5 * (gain + gain.transpose());
    }
  }
  const Eigen::LLT<Matrix3> llt(w.cov);
  w.whitens = llt.info() == Eigen::Success && w.cov.allFinite() && w.mean.allFinite();
  if (w.whitens) w.L = llt.matrixL();
  return w;
}

Prepared prepare(const std::vector<std::vector<RunResidual>>& grouped) {
  Prepared p;
  std::vector<Eigen::Matrix2d> posterior;
  p.first.push_back(0);
  for (const auto& ex : grouped) {
    for (const RunResidual& r : ex) {
      if (r.group >= static_cast<int>(posterior.size())) {
        posterior.resize(static_cast<std::size_t>(r.group) + 1, Eigen::Matrix2d::Identity());
      }
      Eigen::Matrix2d none = Eigen::Matrix2d::Identity();
      p.runs.push_back(whitener(r, r.group >= 0 ? posterior[static_cast<std::size_t>(r.group)] : none));
    }
    p.first.push_back(p.runs.size());
  }
  p.groups = static_cast<int>(posterior.size());
  return p;
}

/// Whitens the errors of every run (suite order) into z; `m` is the groups' posterior means
/// (workspace, groups entries). A run whose error is not finite leaves its group unchanged.
void whiten(const Prepared& p, const Vector3* errors, std::vector<Eigen::Vector2d>& m, Vector3* z) {
  m.assign(static_cast<std::size_t>(p.groups), Eigen::Vector2d::Zero());
  for (std::size_t i = 0; i < p.runs.size(); ++i) {
    const RunWhitener& w = p.runs[i];
    Vector3 r = errors[i] - w.mean;
    if (w.group >= 0) {
      Eigen::Vector2d& g = m[static_cast<std::size_t>(w.group)];
      r -= w.U * g;
      if (r.allFinite()) g += w.G * r;
    }
    z[i] = w.L.triangularView<Eigen::Lower>().solve(r);
  }
}

// ---- The tests of one experiment and of the suite -----------------------------------------

struct ExperimentTests {
  TestResult mean, cov;
  bool lrt = false;  // the covariance test is the LRT (else the NEES sum, two-sided)
};

/// Hotelling's T^2 (chi^2 with the predicted covariance for n <= 3) and the covariance LRT of
/// cov = I (the two-sided NEES sum, sum |z|^2 ~ chi^2_3n, below kMinRunsForLrt runs) on an
/// experiment's whitened residuals.
ExperimentTests experiment_tests(const Vector3* z, std::size_t count) {
  MomentAccumulator acc;
  double nees = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    acc.add(z[i]);
    nees += z[i].squaredNorm();
  }
  const SampleMoments s = moments(acc);
  const auto n = static_cast<std::int64_t>(count);
  ExperimentTests t;
  t.mean = n > kDim ? hotelling_test(s, Vector3::Zero())
                    : mean_test_known_covariance(s, Vector3::Zero(), Matrix3::Identity());
  t.lrt = n >= kMinRunsForLrt;
  if (t.lrt) {
    t.cov = covariance_test(s, Matrix3::Identity());
  } else {
    t.cov.statistic = nees;
    t.cov.dof = kDim * static_cast<int>(n);
    t.cov.p_value = chi2_two_sided(nees, t.cov.dof);
  }
  return t;
}

/// Mardia's multivariate kurtosis b2 [Mardia70] of one experiment's whitened residuals z, each
/// standardised by the experiment's own mean and (maximum-likelihood) covariance. NaN when that
/// covariance is singular (runs all alike, or on a plane): such residuals have no shape to test.
double mardia_b2(const Vector3* z, std::size_t count) {
  const double n = static_cast<double>(count);
  MomentAccumulator acc;
  for (std::size_t i = 0; i < count; ++i) acc.add(z[i]);
  const Matrix3 S = acc.covariance() * ((n - 1) / n);
  const Eigen::LLT<Matrix3> llt(S);
  if (llt.info() != Eigen::Success || !S.allFinite()) return kNaN;
  double b2 = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const Vector3 d = z[i] - acc.mean();
    const double q = d.dot(llt.solve(d));
    b2 += q * q / n;
  }
  return b2;
}

/// The experiments' kurtoses pooled with Mardia's exact moments [Mardia74], weighted by their
/// run counts n: E b2 = p(p+2)(n-1)/(n+1),
/// Var b2 = 8p(p+2)(n-3)(n-p-1)(n-p+1)/((n+1)^2 (n+3)(n+5)), z = sum n(b2 - E)/sqrt(sum n^2 Var).
struct KurtosisPool {
  double excess = 0.0, variance = 0.0, weight = 0.0, b2_sum = 0.0, expected_sum = 0.0;

  /// Adds one experiment; false (and nothing added) when its kurtosis does not exist (mardia_b2).
  bool add(const Vector3* z, std::size_t count) {
    const double n = static_cast<double>(count);
    const double b2 = mardia_b2(z, count);
    if (!std::isfinite(b2)) return false;
    constexpr double p = kDim;
    const double expected = p * (p + 2) * (n - 1) / (n + 1);
    const double var = 8 * p * (p + 2) * (n - 3) * (n - p - 1) * (n - p + 1) /
                       ((n + 1) * (n + 1) * (n + 3) * (n + 5));
    excess += n * (b2 - expected);
    variance += n * n * var;
    weight += n;
    b2_sum += n * b2;
    expected_sum += n * expected;
    return true;
  }
  /// The pooled test (two-sided normal); not valid when no experiment is large enough.
  TestResult test() const {
    TestResult t;
    t.valid = weight > 0;
    if (!t.valid) return t;
    t.statistic = excess / std::sqrt(variance);
    t.dof = 0;
    t.p_value = 2.0 * boost::math::cdf(boost::math::complement(boost::math::normal(), std::abs(t.statistic)));
    return t;
  }
  double b2() const { return weight > 0 ? b2_sum / weight : 0.0; }
};

// ---- Scores: every test's statistic on one scale, for the calibration ---------------------

/// The largest normal score kept: Phi-bar(38.5) = 2e-324, the smallest double.
constexpr double kMaxScore = 38.5;

double clamp_score(double u) { return std::isnan(u) ? u : std::clamp(u, -kMaxScore, kMaxScore); }

/// The normal score of an upper-tail p-value, Phi-bar^-1(p): N(0, 1) under the Gaussian
/// reference.
double upper_score(double p) {
  if (std::isnan(p)) return kNaN;
  if (!(p > 0)) return kMaxScore;
  if (!(p < 1)) return -kMaxScore;
  return clamp_score(boost::math::quantile(boost::math::complement(boost::math::normal(), p)));
}

/// The signed normal score of a chi^2 statistic, Phi^-1(F(x)), for a two-sided test.
double signed_chi2_score(double x, double dof) {
  if (!std::isfinite(x) || !(dof > 0)) return kNaN;
  const boost::math::chi_squared d(dof);
  const double lower = boost::math::cdf(d, std::max(x, 0.0));
  return lower < 0.5 ? -upper_score(lower) : upper_score(boost::math::cdf(boost::math::complement(d, x)));
}

/// The tests of a comparison, in a fixed order: experiment e's mean test at 2e, its covariance
/// test at 2e + 1, the kurtosis last. `two_sided` says how a score's distance from its centre
/// counts; `valid` which tests exist for the data (an untestable experiment has none).
struct TestLayout {
  std::vector<bool> valid, two_sided;
  std::vector<std::uint8_t> testable;  // per experiment
  /// Per experiment: whether the kurtosis pools it (enough runs, and the data's residuals have
  /// a kurtosis: KurtosisPool::add), the same experiments in the data and every replicate.
  std::vector<std::uint8_t> pooled;
  std::size_t size() const { return valid.size(); }
  int count() const { return static_cast<int>(std::count(valid.begin(), valid.end(), true)); }
};

/// Per thread: the whitened residuals and the groups' posterior means.
struct Workspace {
  std::vector<Vector3> z;
  std::vector<Eigen::Vector2d> m;
};

/// The data's errors, run by run in suite order, and their whitened residuals in ws.z.
std::vector<Vector3> whiten_data(const Prepared& p, const std::vector<std::vector<RunResidual>>& grouped,
                                 Workspace& ws) {
  std::vector<Vector3> errors;
  for (const auto& ex : grouped) {
    for (const RunResidual& r : ex) errors.push_back(r.error);
  }
  ws.z.resize(errors.size());
  whiten(p, errors.data(), ws.m, ws.z.data());
  return errors;
}

/// The scores of every test for one set of errors (the data, or a replicate): the same
/// whitening, tests and kurtosis compare reports. NaN for a test that does not exist.
void scores(const Prepared& p, const TestLayout& layout, const Vector3* errors, Workspace& ws,
            double* out) {
  ws.z.resize(p.runs.size());
  whiten(p, errors, ws.m, ws.z.data());
  KurtosisPool pool;
  const std::size_t E = p.experiments();
  for (std::size_t e = 0; e < E; ++e) {
    out[2 * e] = out[2 * e + 1] = kNaN;
    if (!layout.testable[e]) continue;
    const Vector3* z = ws.z.data() + p.first[e];
    const std::size_t n = p.runs_of(e);
    const ExperimentTests t = experiment_tests(z, n);
    out[2 * e] = t.mean.valid ? upper_score(t.mean.p_value) : kNaN;
    out[2 * e + 1] = !t.cov.valid ? kNaN
                     : t.lrt      ? upper_score(t.cov.p_value)
                                  : signed_chi2_score(t.cov.statistic, t.cov.dof);
    if (layout.pooled[e]) pool.add(z, n);
  }
  const TestResult k = pool.test();
  out[2 * E] = k.valid ? clamp_score(k.statistic) : kNaN;
}

// ---- The data's comparison -----------------------------------------------------------------

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

/// Each component's mean and variance against the prediction, for wording the failures: the
/// sample's own standard error (Student t) when the experiment is large enough for Hotelling,
/// else the predicted one (normal); the variance ratio with its two-sided chi^2 p-value.
void component_tests(const SampleMoments& r, const Matrix3& mean_cov, ExperimentComparison& c) {
  const double n = static_cast<double>(c.n);
  c.mean_residual = r.mean;
  c.mean_residual_cov = (c.n > kDim && r.cov.diagonal().minCoeff() > 0 ? r.cov : mean_cov) / n;
  for (int k = 0; k < kDim; ++k) {
    const double sd = std::sqrt(std::max(r.cov(k, k), 0.0));
    const bool own_se = c.n > kDim && sd > 0;
    if (!(mean_cov(k, k) > 0) && !own_se) continue;
    if (own_se) {
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
}

/// Experiment e of the data: its moments, predicted block, NEES, log-likelihood, tests (on the
/// whitened residuals z) and per-component statistics. An experiment with a run that cannot be
/// whitened (singular or non-finite covariance, e.g. no wheel noise and no measurement noise)
/// or a non-finite error is untestable, with no statistic computed from it.
ExperimentComparison compare_experiment(const SuiteExperiment& ex, const Prepared& p, std::size_t e,
                                        const std::vector<RunResidual>& res,
                                        const std::vector<RunResidual>& own, const Vector3* z) {
  ExperimentComparison c;
  c.name = ex.name;
  c.n = static_cast<std::int64_t>(res.size());
  const double n = static_cast<double>(c.n);
  for (const RunResidual& r : res) c.errors.push_back(r.error);
  c.measured = moments(c.errors);
  bool testable = true;
  for (std::size_t i = 0; i < res.size(); ++i) {
    testable = testable && p.runs[p.first[e] + i].whitens && res[i].error.allFinite();
  }
  if (!testable) {
    c.mean_test.valid = c.cov_test.valid = false;
    c.cov_method = "none";
    c.verdict = Verdict::untestable("the predicted covariance is singular or not finite "
                                    "(no wheel noise and no measurement noise?)");
    return c;
  }
  predicted_block(own, c);
  Matrix3 mean_cov = Matrix3::Zero();
  std::vector<Vector3> raw;
  for (std::size_t i = 0; i < res.size(); ++i) {
    const RunWhitener& w = p.runs[p.first[e] + i];
    const double nees = z[i].squaredNorm();
    c.nees_mean += nees / n;
    c.outside_95 += (nees > kChi2_3_95 ? 1.0 : 0.0) / n;
    const Vector3 conditioned_mean = res[i].error - w.L * z[i];
    c.log_likelihood += gaussian_log_density(res[i].error, conditioned_mean, w.cov);
    raw.push_back(res[i].error - conditioned_mean);
    mean_cov += w.cov / n;
  }
  const ExperimentTests t = experiment_tests(z, res.size());
  c.mean_test = t.mean;
  c.cov_test = t.cov;
  c.cov_method = t.lrt ? "lrt" : "nees";
  component_tests(moments(raw), mean_cov, c);
  return c;
}

// ---- Where it fails --------------------------------------------------------------------------

/// The mean failures of an experiment whose mean test fails: every component significant on
/// its own (in order x, y, theta); when none is (the test failed on a combination: two means each
/// within their standard errors whose errors the covariance ties together), the pair of
/// components whose joint_mean_t is largest; with no such pair, the worst component alone.
void add_mean_failures(const ExperimentComparison& c, int index, double alpha_test, std::vector<Failure>& out) {
  int worst = 0;
  for (int k = 1; k < kDim; ++k) worst = c.mean_p(k) < c.mean_p(worst) ? k : worst;
  if (!(c.mean_p(worst) < alpha_test)) {
    Failure pair{Failure::Kind::joint_mean, index, 0, 0};
    double most = std::abs(c.mean_t(worst));
    for (int a = 0; a < kDim; ++a) {
      for (int b = a + 1; b < kDim; ++b) {
        const double t = c.joint_mean_t(a, b);
        if (t > most) most = t, pair.component = a, pair.other = b;
      }
    }
    out.push_back(pair.component != pair.other ? pair : Failure{Failure::Kind::mean, index, worst, worst});
    return;
  }
  for (int k = 0; k < kDim; ++k) {
    if (k == worst || c.mean_p(k) < alpha_test) out.push_back({Failure::Kind::mean, index, k, k});
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

/// The overall verdict and the failures, worst experiment first (smallest p-value, ties of
/// p underflowing to 0 broken by the NEES per run), then the tails.
void verdict_and_failures(Comparison& out) {
  for (ExperimentComparison& c : out.experiments) {
    if (c.cov_method != "none") c.verdict = verdict(c.mean_test, c.cov_test, out.alpha_per_test);
  }
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
  if (out.kurtosis.valid && out.kurtosis.p_value < out.alpha_per_test) {
    overall.combine({Verdict::Kind::inconsistent, ""});
    out.failures.push_back({Failure::Kind::tails, -1, 0, 0});
  }
  out.verdict = overall;
}

// ---- Choosing the calibration ----------------------------------------------------------------

/// The heading noise bends the error: the part of it quadratic in the heading error has a mean
/// (the noise-induced mean) and a spread of the same size; on a straight line, where the
/// along-track error gains -1/2 int theta^2 ds, the spread is 4/sqrt(12) = 1.15 times the mean.
constexpr double kSpreadPerNoiseMean = 1.1547005383792515;
/// The excess kurtosis of a standardised chi^2_1, the largest that a quadratic part can have.
constexpr double kQuadraticExcessKurtosis = 12.0;
/// The Gaussian reference is taken as exact when the worst run's departure from Gaussian moves
/// Mardia's kurtosis by at most this fraction of the kurtosis test's standard error with the
/// suite's runs.
constexpr double kUndetectableFraction = 0.1;

/// "" when the model's errors are Gaussian to within what the suite's runs could detect (see
/// docs/diagnose.md, "How compare decides"), else why not. `why_gaussian` gets the reason for
/// the Gaussian path.
std::string simulation_reason(const Suite& suite, const SuiteModel& model,
                              const std::vector<std::vector<RunResidual>>& res, std::string& why_gaussian) {
  if (const std::string e = non_gaussian_effect(model.effects); !e.empty()) {
    return "the model's world is not Gaussian (" + e + ")";
  }
  double worst = 0.0;
  std::string where;
  std::size_t runs = 0;
  for (std::size_t e = 0; e < res.size(); ++e) {
    for (const RunResidual& r : res[e]) {
      ++runs;
      const Eigen::LLT<Matrix3> llt(r.cov);
      if (llt.info() != Eigen::Success) continue;
      const double c = kSpreadPerNoiseMean * llt.matrixL().solve(r.noise_mean).norm();
      if (c > worst) worst = c, where = suite.experiments[e].name;
    }
  }
  const double shift = kQuadraticExcessKurtosis * std::pow(worst, 4);
  const double p = kDim;
  const double se = std::sqrt(8 * p * (p + 2) / static_cast<double>(std::max<std::size_t>(runs, 1)));
  const std::string figures = "the heading noise's non-Gaussian part, at most " +
                              format_number(worst, "%.2g") + " of a standard error" +
                              (where.empty() ? std::string() : " (" + where + ")") +
                              ", moves Mardia's kurtosis by up to " + format_number(shift, "%.2g") +
                              ", against the " + format_number(se, "%.2g") + " that " +
                              std::to_string(runs) + " runs resolve";
  if (shift > kUndetectableFraction * se) return "the errors are not Gaussian: " + figures;
  why_gaussian = "the model's errors are Gaussian to within what the runs could detect: its effects "
                 "add Gaussian noise or deterministic changes, and " + figures;
  return "";
}

// ---- The referee: calibration by simulating the model's world ------------------------------

/// The scores of the data (row 0) and of every replicate (rows 1 .. B), one row per set.
struct ScoreTable {
  std::size_t cols = 0;
  std::vector<double> values;
  std::size_t rows() const { return cols ? values.size() / cols : 0; }
  const double* row(std::size_t r) const { return values.data() + r * cols; }
};

/// A generalised Pareto tail fitted by probability-weighted moments [Hosking87] to the excesses
/// over `desc[count - 1]` of the `count - 1` scores above it (`desc` descending). Its shape xi
/// is kept in [0, kMaxShape] (an exponential tail at the lightest, so a p-value beyond the
/// scores errs large, never small, and is never 0; PWM needs a finite variance, xi < 1/2).
struct ParetoTail {
  double threshold = 0.0, xi = 0.0, beta = 1.0;
  bool ok = false;  // false: ties at the top, the empirical tail alone

  static constexpr double kMaxShape = 0.45;

  ParetoTail(const double* desc, std::size_t count) : threshold(desc[count - 1]) {
    // Probability-weighted moments of the excesses y (ascending): a0 = mean y,
    // a1 = mean (1 - p_i) y_(i), p_i = (i - 0.35)/N; xi = 2 - a0/(a0 - 2 a1), beta = 2 a0 a1/(a0 - 2 a1).
    const std::size_t exceedances = count - 1;
    const auto N = static_cast<double>(exceedances);
    double a0 = 0.0, a1 = 0.0;
    for (std::size_t i = 0; i < exceedances; ++i) {
      const double y = desc[exceedances - 1 - i] - threshold;  // ascending
      a0 += y / N;
      a1 += (1.0 - (static_cast<double>(i) + 0.65) / N) * y / N;
    }
    if (!(a0 > 0)) return;
    const double d = a0 - 2.0 * a1;
    const double raw = d > 0 ? 2.0 - a0 / d : kMaxShape;
    xi = std::clamp(raw, 0.0, kMaxShape);
    // Where xi is held at a bound, beta keeps the mean excess beta/(1 - xi) at a0.
    beta = xi == raw ? 2.0 * a0 * a1 / d : a0 * (1.0 - xi);
    ok = true;
  }
  /// P(score >= x | score > threshold).
  double survival(double x) const {
    const double y = (x - threshold) / beta;
    return xi > 1e-9 ? std::pow(1.0 + xi * y, -1.0 / xi) : std::exp(-y);
  }
};

/// One tail of a test's distribution in the model's world, from the n scores of the reference
/// replicates (kReferenceReplicates, simulated apart: neither the data nor any replicate the data
/// are ranked against is among them). The p-value of a score x is the share of the reference at
/// or above it, (1 + #{>= x})/(n + 1), and beyond the (N + 1)-th largest (N = max(10, n/10)) a
/// generalised Pareto tail fitted to the N above it (ParetoTail; for small permutation p-values,
/// [Knijnenburg09]). The reference is fixed before the data are ranked, so a p-value is the same
/// function of its score for the data and for every replicate, at every look: the min-P
/// statistic built on them is a fixed statistic, the condition of the sequential Monte-Carlo
/// test (SequentialMcTest). A far misfit does not widen its own reference. (Earlier versions
/// fitted each tail to the data and the replicates themselves: first the replicates alone, so
/// a replicate's largest score was in its own fit and the data's never, and correct worlds
/// were rejected 6 to 8% of the time at 1%; then every score left out of its own fit, exact at
/// one look but a reference that moved between looks, results/referee/README.md.)
struct Tail {
  std::vector<double> sorted;  // the reference's scores, descending
  std::size_t exceedances = 0;  // N
  std::optional<ParetoTail> pareto;

  explicit Tail(std::vector<double> scores) : sorted(std::move(scores)) {
    std::sort(sorted.begin(), sorted.end(), std::greater<>());
    const std::size_t n = sorted.size();
    exceedances = n < 4 ? 0 : std::min(n - 3, std::max<std::size_t>(kMinExceedances, n / 10));
    if (exceedances < 2) return;
    const ParetoTail t(sorted.data(), exceedances + 1);
    if (t.ok) pareto = t;
  }
  double n() const { return static_cast<double>(sorted.size()); }
  /// The share of the reference and x above the tail's threshold, x among them.
  double share_above_threshold() const { return static_cast<double>(exceedances + 1) / (n() + 1); }
  bool in_tail(double x) const { return pareto && x > pareto->threshold; }
  /// P(score >= x) in the model's world.
  double p(double x) const {
    if (in_tail(x)) return share_above_threshold() * pareto->survival(x);
    const auto k = std::upper_bound(sorted.begin(), sorted.end(), x, std::greater<>()) - sorted.begin();
    return (1.0 + static_cast<double>(k)) / (n() + 1);
  }
  /// Its Monte-Carlo standard error: binomial in the bulk; in the tail the delta method of an
  /// exponential tail, relative error sqrt((1 + ln^2(q/p))/N) with q the share above the
  /// threshold.
  double mc_error(double x) const {
    const double pv = p(x);
    if (!in_tail(x)) return std::sqrt(pv * (1 - pv) / n());
    const double log_ratio = std::log(share_above_threshold() / pv);
    return pv * std::sqrt((1.0 + log_ratio * log_ratio) / static_cast<double>(exceedances));
  }
  static constexpr std::size_t kMinExceedances = 10;
};

/// Each test's tails in the model's world (the lower one for two-sided tests only), and its
/// median (for the kurtosis the model's world expects).
struct Reference {
  std::vector<Tail> upper, lower;
  std::vector<double> median;
};

Reference reference(const ScoreTable& t, const TestLayout& layout) {
  Reference r;
  std::vector<double> v;
  for (std::size_t j = 0; j < t.cols; ++j) {
    v.clear();
    for (std::size_t row = 0; layout.valid[j] && row < t.rows(); ++row) {
      if (!std::isnan(t.row(row)[j])) v.push_back(t.row(row)[j]);
    }
    if (v.size() < 2) v.assign(2, 0.0);  // no such test: a placeholder, never asked
    r.upper.emplace_back(v);
    r.median.push_back(r.upper.back().sorted[v.size() / 2]);
    for (double& x : v) x = -x;
    r.lower.emplace_back(layout.two_sided[j] ? v : std::vector<double>{0.0, 0.0});
  }
  return r;
}

/// A test's p-value from its score, in the model's world: the upper tail, or for a two-sided
/// test twice the nearer tail.
double calibrated_p(double score, std::size_t j, const Reference& ref, const TestLayout& layout) {
  if (std::isnan(score)) return 1.0;
  if (!layout.two_sided[j]) return ref.upper[j].p(score);
  return std::min(1.0, 2.0 * std::min(ref.upper[j].p(score), ref.lower[j].p(-score)));
}

double calibrated_p_error(double score, std::size_t j, const Reference& ref, const TestLayout& layout) {
  if (!layout.two_sided[j]) return ref.upper[j].mc_error(score);
  const bool upper = ref.upper[j].p(score) <= ref.lower[j].p(-score);
  return 2.0 * (upper ? ref.upper[j].mc_error(score) : ref.lower[j].mc_error(-score));
}

/// The smallest calibrated p-value of each row from `first` on, appended to `out`.
void append_row_minima(const ScoreTable& t, std::size_t first, const Reference& ref, const TestLayout& layout,
                       std::vector<double>& out) {
  for (std::size_t r = first; r < t.rows(); ++r) {
    double m = 1.0;
    for (std::size_t j = 0; j < t.cols; ++j) {
      if (layout.valid[j]) m = std::min(m, calibrated_p(t.row(r)[j], j, ref, layout));
    }
    out.push_back(m);
  }
}

/// The risk per look of stopping to accept a verdict that more replicates would reverse: a look
/// accepts when the Clopper-Pearson interval of level 1 - kRiskPerLook lies above alpha.
constexpr double kRiskPerLook = 1e-3;
/// The share of alpha spent on the tail model: beyond every replicate the data are rejected when
/// the Bonferroni bound K m of their smallest p-value is at most kTailShare alpha; the ranks
/// spend the rest, (1 - kTailShare) alpha, over the looks.
constexpr double kTailShare = 0.1;

/// The family-wise test of the smallest p-value at the current look: the sequential Monte-Carlo
/// test of its rank among the replicates' smallest p-values, and beyond every replicate the tail
/// model, combined by weighted Bonferroni.
struct FamilyTest {
  SequentialMcTest ranks;  // at (1 - kTailShare) alpha
  int tests = 0;           // K
  double alpha = 0.0;
  std::size_t look = 0;
  std::vector<double> sorted;  // the replicates' smallest p-values at this look, ascending

  std::int64_t below(double m) const {
    return std::upper_bound(sorted.begin(), sorted.end(), m) - sorted.begin();
  }
  bool tail_rejects(double m) const { return below(m) == 0 && tests * m <= kTailShare * alpha; }
  /// The family-wise p-value of a smallest p-value m: at most alpha exactly when the look rejects.
  double p(double m) const {
    const std::int64_t k = below(m);
    double out = ranks.p_value(look, k) / (1 - kTailShare);
    if (k == 0) out = std::min(out, tests * m / kTailShare);
    return std::min(1.0, out);
  }
  /// The smallest p-values that the look rejects are those below this.
  double critical() const {
    const std::int64_t c = ranks.critical(look);
    if (c < 0) return std::min(kTailShare * alpha / tests, sorted.front());
    return c < static_cast<std::int64_t>(sorted.size()) ? sorted[static_cast<std::size_t>(c)] : 1.0;
  }
};

/// Look j after the replicates whose smallest p-values are minima[1..]: the data's (minima[0])
/// family-wise p-value, its interval; whether the verdict is decided (rejected, clearly
/// accepted, or the last look).
bool look(const std::vector<double>& minima, std::size_t j, FamilyTest& family, Calibration& cal) {
  family.look = j;
  family.sorted.assign(minima.begin() + 1, minima.end());
  std::sort(family.sorted.begin(), family.sorted.end());
  const auto B = static_cast<double>(family.sorted.size());
  const std::int64_t k = family.below(minima[0]);
  const auto kd = static_cast<double>(k);
  cal.replicates = static_cast<std::int64_t>(family.sorted.size());
  cal.resolution = 1.0 / (B + 1);
  cal.p_value = family.p(minima[0]);
  cal.beyond_replicates = k == 0;
  clopper_pearson(kd, B, kRiskPerLook, cal.p_interval);
  cal.p_mc_error = std::sqrt(kd / B * (1 - kd / B) / B);
  cal.looks = static_cast<int>(j) + 1;
  const bool tail = family.tail_rejects(minima[0]);
  const SequentialMcTest::Decision d = family.ranks.decide(j, k, kRiskPerLook, family.alpha);
  const bool last = j + 1 == family.ranks.looks().size();
  cal.close_call = last && !tail && cal.p_interval[0] <= family.alpha && family.alpha <= cal.p_interval[1];
  return tail || d != SequentialMcTest::Decision::go_on;
}

/// Simulates replicates [first, last) of the model's world and appends their scores.
void simulate_scores(const ModelWorld& world, const Prepared& p, const TestLayout& layout,
                     std::int64_t first, std::int64_t last, ScoreTable& table, RefereeProgress* progress) {
  // Replicates per batch: bounds the memory and paces the progress. The batches end at
  // multiples of kBatch, a multiple of every target's block of runs (32 lanes on AVX-512, 8 on
  // AVX2 and 128-bit vectors, 4 on the scalar fallback), so that a logged run's replicates fill
  // whole blocks. A replicate's numbers do not depend on its batch (the simulator's streams
  // are counter-based).
  constexpr std::int64_t kBatch = 64;
  std::vector<Vector3> errors;
  tbb::enumerable_thread_specific<Workspace> workspaces;
  for (std::int64_t b = first; b < last;) {
    const std::int64_t count = std::min((b / kBatch + 1) * kBatch, last) - b;
    world.errors(b, count, errors);
    const std::size_t base = table.values.size();
    table.values.resize(base + static_cast<std::size_t>(count) * table.cols);
    tbb::parallel_for(std::int64_t{0}, count, [&](std::int64_t i) {
      scores(p, layout, errors.data() + static_cast<std::size_t>(i) * world.runs(), workspaces.local(),
             table.values.data() + base + static_cast<std::size_t>(i) * table.cols);
    });
    if (progress) progress->done += count;
    b += count;
  }
}

/// Each test's calibrated p-value and family-wise p-value (as if its p-value were the data's
/// smallest), with their Monte-Carlo errors; the critical p-value per test.
void calibrate_tests(const ScoreTable& table, const Reference& ref, const TestLayout& layout,
                     const FamilyTest& family, Comparison& out) {
  const double B = static_cast<double>(family.sorted.size());
  auto fill = [&](std::size_t j, TestResult& t, CalibratedTest& c) {
    if (!layout.valid[j] || !t.valid) return;
    c.p_gaussian = t.p_value;
    t.p_value = calibrated_p(table.row(0)[j], j, ref, layout);
    c.p_mc_error = calibrated_p_error(table.row(0)[j], j, ref, layout);
    c.p_family = family.p(t.p_value);
    c.p_family_mc_error = std::sqrt(c.p_family * (1 - c.p_family) / B);
  };
  const std::size_t E = out.experiments.size();
  for (std::size_t e = 0; e < E; ++e) {
    fill(2 * e, out.experiments[e].mean_test, out.experiments[e].mean_calibration);
    fill(2 * e + 1, out.experiments[e].cov_test, out.experiments[e].cov_calibration);
  }
  fill(2 * E, out.kurtosis, out.kurtosis_calibration);
  // A test fails when its p_family <= alpha, i.e. when its p-value is below the critical one.
  out.alpha_per_test = family.critical();
}

/// The looks: after 99, 199, 399, ... replicates (B + 1 doubling), the last at the cap.
std::vector<std::int64_t> look_schedule(std::int64_t cap) {
  std::vector<std::int64_t> looks{std::min(kFirstLookReplicates, cap)};
  while (looks.back() < cap) looks.push_back(std::min(cap, 2 * (looks.back() + 1) - 1));
  return looks;
}

/// Calibrates `out`'s tests by the model's world (ModelWorld): each test's reference from
/// kReferenceReplicates replicates, then the data ranked against replicates drawn apart, with a
/// look after 99, 199, 399, ... of them until the sequential test decides or B reaches the cap.
/// Returns the kurtosis score's median in the model's world (0 for a Gaussian world).
double referee(const Suite& suite, const SuiteModel& model, const Prepared& p, const TestLayout& layout,
               const Vector3* data_errors, const CalibrationOptions& options, Comparison& out) {
  const ModelWorld world(suite, model, options.seed);
  const std::vector<std::int64_t> looks = look_schedule(std::max<std::int64_t>(1, options.max_replicates));
  if (options.progress) options.progress->target = kReferenceReplicates + looks.front();
  ScoreTable reference_scores;
  reference_scores.cols = layout.size();
  simulate_scores(world, p, layout, 0, kReferenceReplicates, reference_scores, options.progress);
  const Reference ref = reference(reference_scores, layout);
  ScoreTable table;
  table.cols = layout.size();
  table.values.resize(table.cols);
  Workspace ws;
  scores(p, layout, data_errors, ws, table.values.data());
  std::vector<double> minima;
  append_row_minima(table, 0, ref, layout, minima);
  Calibration& cal = out.calibration;
  cal.method = CalibrationMethod::simulation;
  cal.seed = options.seed;
  cal.tests = layout.count();
  cal.risk_per_look = kRiskPerLook;
  cal.reference_replicates = kReferenceReplicates;
  FamilyTest family{SequentialMcTest(looks, out.alpha * (1 - kTailShare)), cal.tests, out.alpha, 0, {}};
  for (std::size_t j = 0; j < looks.size(); ++j) {
    const std::int64_t B = j > 0 ? looks[j - 1] : 0;
    if (options.progress) options.progress->target = kReferenceReplicates + looks[j];
    simulate_scores(world, p, layout, kReferenceReplicates + B, kReferenceReplicates + looks[j], table,
                    options.progress);
    append_row_minima(table, minima.size(), ref, layout, minima);
    if (look(minima, j, family, cal)) break;
  }
  calibrate_tests(table, ref, layout, family, out);
  return ref.median[2 * out.experiments.size()];
}

/// The Gaussian references' p-values as they are, Bonferroni over 2 tests per experiment and
/// the kurtosis.
void gaussian_calibration(const TestLayout& layout, Comparison& out) {
  const std::size_t E = out.experiments.size();
  const double tests = static_cast<double>(2 * E + 1);
  out.alpha_per_test = out.alpha / tests;
  out.calibration.method = CalibrationMethod::gaussian;
  out.calibration.tests = layout.count();
  double smallest = 1.0;
  auto fill = [&](const TestResult& t, CalibratedTest& c) {
    c.p_gaussian = t.p_value;
    c.p_family = t.valid ? std::min(1.0, tests * t.p_value) : 1.0;
    if (t.valid) smallest = std::min(smallest, t.p_value);
  };
  for (ExperimentComparison& e : out.experiments) {
    fill(e.mean_test, e.mean_calibration);
    fill(e.cov_test, e.cov_calibration);
  }
  fill(out.kurtosis, out.kurtosis_calibration);
  out.calibration.p_value = std::min(1.0, tests * smallest);
  out.calibration.p_interval[0] = out.calibration.p_interval[1] = out.calibration.p_value;
}

/// Calibrates the tests as `options` asks: the referee when asked, or (automatic) when the
/// model's errors are not Gaussian to within what the runs could detect; else the Gaussian
/// references. Says why in out.calibration.reason.
void choose_and_calibrate(const Suite& suite, const SuiteModel& model,
                          const std::vector<std::vector<RunResidual>>& grouped, const Prepared& p,
                          const TestLayout& layout, const Vector3* errors, const KurtosisPool& pool,
                          const CalibrationOptions& options, Comparison& out) {
  std::string why_gaussian;
  const std::string not_gaussian = simulation_reason(suite, model, grouped, why_gaussian);
  const bool simulate = options.method == CalibrationMethod::simulation ||
                        (options.method == CalibrationMethod::automatic && !not_gaussian.empty());
  if (simulate && layout.count() > 0) {
    out.calibration.reason = options.method == CalibrationMethod::automatic ? not_gaussian
                             : not_gaussian.empty() ? "requested; " + why_gaussian
                                                    : "requested; " + not_gaussian;
    const double centre = referee(suite, model, p, layout, errors, options, out);
    // The pooled b2 is linear in the kurtosis score: b2 = E + z sqrt(sum n^2 Var)/sum n.
    if (out.kurtosis.valid) out.mardia_model = out.mardia_expected + centre * std::sqrt(pool.variance) / pool.weight;
    return;
  }
  gaussian_calibration(layout, out);
  out.calibration.reason = layout.count() == 0 ? "no test can be computed"
                           : options.method == CalibrationMethod::automatic ? why_gaussian
                           : not_gaussian.empty() ? "requested; " + why_gaussian
                                                  : "requested, though not exact here: " + not_gaussian;
}

/// The experiments a kurtosis pools: those whose every run whitens, with `min_runs` runs or more
/// (compare's test: kMinRunsForLrt).
std::vector<std::uint8_t> pooled_experiments(const Prepared& p,
                                             std::size_t min_runs = static_cast<std::size_t>(kMinRunsForLrt)) {
  std::vector<std::uint8_t> out;
  for (std::size_t e = 0; e < p.experiments(); ++e) {
    bool ok = p.runs_of(e) >= min_runs;
    for (std::size_t i = p.first[e]; ok && i < p.first[e + 1]; ++i) ok = p.runs[i].whitens;
    out.push_back(ok);
  }
  return out;
}

}  // namespace

namespace {

/// The pooled b2 of `replicates` replicates of the model's world (ModelWorld, seeded), over the
/// experiments `pooled` marks, each replicate whitened as the data are (p). Throws EffectError
/// when the model's effects cannot be simulated on some run.
std::vector<double> replicate_b2(const Suite& suite, const SuiteModel& model, const Prepared& p,
                                 const std::vector<std::uint8_t>& pooled, std::int64_t replicates,
                                 std::uint64_t seed) {
  const ModelWorld world(suite, model, seed);
  std::vector<Vector3> errors;
  world.errors(0, replicates, errors);
  std::vector<double> b2(static_cast<std::size_t>(replicates));
  tbb::enumerable_thread_specific<Workspace> workspaces;
  tbb::parallel_for(std::int64_t{0}, replicates, [&](std::int64_t b) {
    Workspace& ws = workspaces.local();
    ws.z.resize(p.runs.size());
    whiten(p, errors.data() + static_cast<std::size_t>(b) * world.runs(), ws.m, ws.z.data());
    KurtosisPool pool;
    for (std::size_t e = 0; e < p.experiments(); ++e) {
      if (pooled[e]) pool.add(ws.z.data() + p.first[e], p.runs_of(e));
    }
    b2[static_cast<std::size_t>(b)] = pool.b2();
  });
  return b2;
}

}  // namespace

TailsTest tails_test(const Suite& suite, const SuiteModel& model,
                     const std::vector<std::vector<RunResidual>>& residuals, int replicates, std::uint64_t seed) {
  TailsTest out;
  const Prepared p = prepare(residuals);
  std::vector<std::uint8_t> pooled = pooled_experiments(p, kMinRunsForTails);
  Workspace ws;
  whiten_data(p, residuals, ws);
  KurtosisPool data;
  for (std::size_t e = 0; e < p.experiments(); ++e) {
    // The replicates pool what the data pool: not an experiment whose residuals have no kurtosis.
    pooled[e] = pooled[e] && data.add(ws.z.data() + p.first[e], p.runs_of(e));
    out.experiments += pooled[e];
  }
  if (out.experiments == 0 || replicates < 1) return out;
  std::vector<double> b2;
  try {
    b2 = replicate_b2(suite, model, p, pooled, replicates, seed);
  } catch (const EffectError&) {
    return out;
  }
  out.b2 = data.b2();
  out.gaussian = data.expected_sum / data.weight;
  int above = 0, below = 0;
  for (double v : b2) {
    above += v >= out.b2, below += v <= out.b2;
    out.mean += v / static_cast<double>(replicates);
  }
  std::nth_element(b2.begin(), b2.begin() + replicates / 2, b2.end());
  out.model = b2[static_cast<std::size_t>(replicates / 2)];
  out.p_value = std::min(1.0, 2.0 * (1.0 + std::min(above, below)) / (1.0 + replicates));
  out.valid = true;
  return out;
}

const char* calibration_name(CalibrationMethod method) {
  switch (method) {
    case CalibrationMethod::gaussian: return "gaussian";
    case CalibrationMethod::simulation: return "simulation";
    default: return "automatic";
  }
}

double ExperimentComparison::measured_correlation(int a, int b) const {
  return measured.cov(a, b) / std::sqrt(measured.cov(a, a) * measured.cov(b, b));
}

double ExperimentComparison::predicted_correlation(int a, int b) const {
  return predicted_cov(a, b) / std::sqrt(predicted_cov(a, a) * predicted_cov(b, b));
}

double ExperimentComparison::joint_mean_t(int a, int b) const {
  const double caa = mean_residual_cov(a, a), cbb = mean_residual_cov(b, b), cab = mean_residual_cov(a, b);
  const double det = caa * cbb - cab * cab;
  if (!(caa > 0.0 && cbb > 0.0 && det > 1e-12 * caa * cbb)) return 0.0;
  const double da = mean_residual(a), db = mean_residual(b);
  const double d2 = (cbb * da * da - 2.0 * cab * da * db + caa * db * db) / det;
  return std::sqrt(std::max(d2, 0.0));
}

double ExperimentComparison::mean_correlation(int a, int b) const {
  return mean_residual_cov(a, b) / std::sqrt(mean_residual_cov(a, a) * mean_residual_cov(b, b));
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const CalibrationOptions& calibration) {
  return compare(suite, model, alpha, residuals(suite, model), calibration);
}

Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::vector<RunResidual>>& grouped,
                   const CalibrationOptions& options) {
  Comparison out;
  out.alpha = alpha;
  const Prepared p = prepare(grouped);
  const auto own = marginal(grouped);
  Workspace ws;
  const std::vector<Vector3> errors = whiten_data(p, grouped, ws);
  // Mardia's multivariate kurtosis [Mardia70] as a test of shape only: each experiment's
  // whitened residuals are standardised by that experiment's own mean and covariance (so scale
  // and mean misfits, which differ between experiments, do not read as tails), and the
  // experiments with at least kMinRunsForLrt runs are pooled (KurtosisPool).
  KurtosisPool pool;
  TestLayout layout;
  for (std::size_t e = 0; e < suite.experiments.size(); ++e) {
    const Vector3* z = ws.z.data() + p.first[e];
    out.experiments.push_back(compare_experiment(suite.experiments[e], p, e, grouped[e], own[e], z));
    const ExperimentComparison& c = out.experiments.back();
    out.log_likelihood += c.log_likelihood;
    layout.testable.push_back(c.cov_method != "none");
    layout.valid.push_back(c.mean_test.valid);
    layout.valid.push_back(c.cov_test.valid);
    layout.two_sided.push_back(false);
    layout.two_sided.push_back(c.cov_method == "nees");
    layout.pooled.push_back(c.cov_method != "none" && p.runs_of(e) >= static_cast<std::size_t>(kMinRunsForLrt) &&
                            pool.add(z, p.runs_of(e)));
  }
  out.kurtosis = pool.test();
  out.mardia_b2 = pool.b2();
  out.mardia_expected = pool.weight > 0 ? pool.expected_sum / pool.weight : 0.0;
  out.mardia_model = out.mardia_expected;
  layout.valid.push_back(out.kurtosis.valid);
  layout.two_sided.push_back(true);

  choose_and_calibrate(suite, model, grouped, p, layout, errors.data(), pool, options, out);
  verdict_and_failures(out);
  for (std::size_t e = 0; model.domain && e < suite.experiments.size(); ++e) {
    out.experiments[e].extrapolation = extrapolation(*model.domain, suite.experiments[e], model.robot.wheelbase_m);
  }
  return out;
}

}  // namespace odomcov
