// compare: a model set against every experiment of a measurement suite, with the statistical
// tests of each experiment, the suite's kurtosis test and the verdict, calibrated by the
// Gaussian references where they are exact and by simulating the model's own world elsewhere.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

#include "odomcov/measurement/likelihood.hpp"
#include "odomcov/engine/statistics.hpp"

namespace odomcov {

/// What one test's p-values are under the calibration in use.
struct CalibratedTest {
  double p_gaussian = 1.0;  // against the Gaussian reference (the fast path's p-value)
  /// Family-wise: with the simulation, the family-wise p-value the data would have were this
  /// test's p-value their smallest (Calibration::p_value, from the k replicates whose smallest
  /// p-value is at or below it, and the tail model when k = 0); with the Gaussian reference,
  /// Bonferroni. The test fails when it is at or below alpha.
  double p_family = 1.0;
  double p_mc_error = 0.0;         // Monte-Carlo standard error of the test's p_value
  double p_family_mc_error = 0.0;  // and of p_family (binomial)
};

/// compare for one experiment (docs/json.md, "compare").
struct ExperimentComparison {
  std::string name;
  std::int64_t n = 0;
  SampleMoments measured;                 // of the errors
  Vector3 predicted_mean = Vector3::Zero();  // for a run drawn from the experiment
  Matrix3 predicted_cov = Matrix3::Zero();   // (mixture over runs for logged experiments)
  TestResult mean_test;   // Hotelling's T^2 on whitened residuals (chi^2 when n <= 3)
  TestResult cov_test;    // LRT of cov = I on whitened residuals (NEES test when n < 10)
  CalibratedTest mean_calibration, cov_calibration;  // their p_value's calibration
  std::string cov_method;  // "lrt" or "nees"
  double nees_mean = 0.0;
  double outside_95 = 0.0;  // fraction of runs with NEES above the chi^2_3 95% point
  double log_likelihood = 0.0;
  Verdict verdict;
  std::vector<Vector3> errors;  // each run's error (measured - odometry), in order
  // Per component (x, y, theta), for the failures:
  Vector3 mean_t = Vector3::Zero();        // (measured - predicted mean)/standard error
  Vector3 mean_p = Vector3::Ones();        // Student-t p-values
  /// The mean residual (measured - predicted, each run conditioned on its group's earlier runs)
  /// and its covariance: the sample's own over n when the experiment is large enough for
  /// Hotelling and every component spreads, else the predicted one over n (as mean_t's standard
  /// errors are taken).
  Vector3 mean_residual = Vector3::Zero();
  Matrix3 mean_residual_cov = Matrix3::Zero();
  Vector3 variance_ratio = Vector3::Ones();  // measured / predicted variance
  Vector3 variance_p = Vector3::Ones();    // chi^2 p-values (two-sided)
  /// With a model that records its training domain (SuiteModel::domain): where this
  /// experiment's runs lie outside it, in words (extrapolation()); empty inside.
  std::vector<std::string> extrapolation;

  /// Correlation of components a and b (0 x, 1 y, 2 theta), measured and predicted.
  double measured_correlation(int a, int b) const;
  double predicted_correlation(int a, int b) const;
  /// Components a and b's means taken together: how many standard errors the worst linear
  /// combination of the two is off the prediction, sqrt(d' C^-1 d) with d their mean residuals
  /// and C their block of mean_residual_cov; 0 when C is singular. At least the larger |mean_t|
  /// of the two, and far more when the two means' errors are correlated and the residuals go
  /// against it.
  double joint_mean_t(int a, int b) const;
  /// The correlation of components a and b's mean errors (in mean_residual_cov).
  double mean_correlation(int a, int b) const;
};

/// One way the model fails the data, as data; the command line and the Python module put it
/// in words (src/cli/failures.cpp). Components: 0 x, 1 y, 2 theta.
struct Failure {
  enum class Kind {
    mean,         // experiment's mean of `component` off the prediction (mean_t, mean_p)
    joint_mean,   // the mean test fails with no component off on its own: the means of
                  // (component, other) together, the pair whose joint_mean_t is largest
    variance,     // its variance off (variance_ratio, variance_p)
    correlation,  // the covariance test fails with no variance off: the correlation of
                  // (component, other) differs most
    spread,       // the NEES test fails (fewer than 10 runs): the errors' overall spread
    tails         // the suite's Mardia kurtosis (experiment = -1)
  };
  Kind kind = Kind::mean;
  int experiment = -1;  // index into Comparison::experiments
  int component = 0;
  int other = 0;
};

/// How compare calibrates its tests (docs/diagnose.md, "How compare decides").
///  * gaussian: each test against its Gaussian reference (Hotelling's F, the Bartlett-corrected
///    LRT's chi^2, the NEES sum's chi^2, Mardia's normal), Bonferroni over the tests. Exact when
///    the model's errors are Gaussian.
///  * simulation: the referee. Each test's statistic is set against its distribution in the
///    model's own world (ModelWorld, referee.hpp), and the family-wise verdict against the
///    distribution of the smallest p-value of a replicate (single-step min-P [Westfall93]).
///  * automatic: gaussian when the model's errors are Gaussian to within what the suite's runs
///    could detect (every effect Gaussian on the world side, non_gaussian_effect, and little
///    heading nonlinearity), else simulation.
enum class CalibrationMethod { automatic, gaussian, simulation };
const char* calibration_name(CalibrationMethod method);  // "automatic", "gaussian", "simulation"

/// Replicates: kReferenceReplicates make each test's reference; the data are then ranked against
/// replicates drawn apart, with a look after 99, 199, 399, 799, ... of them (B + 1 = 100 2^i),
/// until the sequential test decides (docs/diagnose.md, "How many replicates");
/// kDefaultReplicates caps B.
inline constexpr std::int64_t kReferenceReplicates = 99;
inline constexpr std::int64_t kFirstLookReplicates = 99;
inline constexpr std::int64_t kDefaultReplicates = 1599;
inline constexpr std::int64_t kMaxReplicates = 1'000'000;
inline constexpr std::uint64_t kDefaultRefereeSeed = 1;

/// How far the referee has got, for a progress display: replicates simulated and the number it
/// is heading for (the next look).
struct RefereeProgress {
  std::atomic<std::int64_t> done{0};
  std::atomic<std::int64_t> target{0};
};

struct CalibrationOptions {
  CalibrationMethod method = CalibrationMethod::automatic;
  std::int64_t max_replicates = kDefaultReplicates;  // B at most (sequential looks stop earlier)
  std::uint64_t seed = kDefaultRefereeSeed;
  RefereeProgress* progress = nullptr;
};

/// What the verdict used (docs/json.md, "compare": calibration).
struct Calibration {
  CalibrationMethod method = CalibrationMethod::gaussian;  // gaussian or simulation
  std::string reason;       // why, in plain words
  std::int64_t replicates = 0;  // B (simulation): the replicates the data are ranked against
  std::int64_t reference_replicates = 0;  // those, apart, that make each test's reference
  std::uint64_t seed = 0;
  int tests = 0;            // valid tests in the family
  /// Family-wise p-value of the verdict: with the simulation, the sequential test's stagewise
  /// p-value of the data's rank and, beyond every replicate, the tail model's, combined.
  double p_value = 1.0;
  double p_mc_error = 0.0;  // its Monte-Carlo standard error
  double p_interval[2] = {1.0, 1.0};  // Clopper-Pearson interval of the exceedance probability
  double resolution = 0.0;  // 1/(B + 1): the smallest p-value the replicates resolve
  /// The data are more extreme than every replicate: p_value is then also bounded by the tail
  /// model (Bonferroni over the tests' standardised p-values).
  bool beyond_replicates = false;
  /// At the largest B allowed, the interval of the exceedance probability still contains alpha.
  bool close_call = false;
  double risk_per_look = 0.0;  // a look accepts when the interval of level 1 - risk lies above alpha
  int looks = 0;
};

struct Comparison {
  double alpha = 0.0;  // family-wise level of the suite
  /// The p-value below which one test fails: Bonferroni, alpha over 2 tests per experiment and
  /// the kurtosis (Gaussian); with the simulation, the min-P critical value: the smallest
  /// p-values below it have a family-wise p-value at or below alpha at the look that decided.
  double alpha_per_test = 0.0;
  std::vector<ExperimentComparison> experiments;
  TestResult kurtosis;  // Mardia's b2, each experiment standardised by its own covariance
  CalibratedTest kurtosis_calibration;
  double mardia_b2 = 0.0;        // run-weighted mean of the experiments' b2
  double mardia_expected = 0.0;  // its expectation for Gaussian errors (15 (n-1)/(n+1))
  /// Its median in the model's own world (simulation; NaN with the Gaussian reference, where it
  /// is mardia_expected): a model with bumps expects heavier tails than Gaussian.
  double mardia_model = 0.0;
  double log_likelihood = 0.0;
  Verdict verdict;
  Calibration calibration;
  std::vector<Failure> failures;  // worst experiment first
};

/// The model against every experiment of the suite ("where it fails" included), its tests and
/// the verdict at the family-wise `alpha` calibrated as `calibration` says: the Gaussian
/// references where they are exact, else the simulated world of the model (the referee), seeded
/// by calibration.seed. The kurtosis test joins every verdict.
Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const CalibrationOptions& calibration = {});
/// The same from the model's residuals(suite, model), already computed (diagnose's cache).
Comparison compare(const Suite& suite, const SuiteModel& model, double alpha,
                   const std::vector<std::vector<RunResidual>>& residuals,
                   const CalibrationOptions& calibration = {});

/// compare's covariance test is the likelihood ratio (its Bartlett-corrected chi^2 is accurate
/// from about ten runs) in an experiment of this many runs or more, else the NEES test; its
/// kurtosis test pools such experiments only.
inline constexpr std::int64_t kMinRunsForLrt = 10;

/// The data's tails against the model's own world, for a decision that compare's kurtosis test
/// cannot make (it pools only experiments of kMinRunsForLrt runs or more, and a lab of a few runs
/// per session has none): Mardia's b2 pooled as compare pools it, run-weighted, over every
/// experiment of at least 5 runs whose runs all whiten, each run whitened by its predicted
/// covariance and each experiment then standardised by its own mean and covariance, so that
/// only the shape of the errors counts; set against `replicates` replicates of the model's world
/// (ModelWorld, seeded), whitened alike. Its two-sided p-value is
/// 2 (1 + min(#{b2* >= b2}, #{b2* <= b2})) / (1 + replicates): tails heavier or lighter than the
/// model's own (bumps that the data do not show, or tails beyond a Gaussian model's). Not valid
/// when no experiment qualifies or the model's effects cannot be simulated.
struct TailsTest {
  double b2 = 0.0;        // the data's pooled b2
  double model = 0.0;     // its median in the model's world
  double mean = 0.0;      // its mean in the model's world
  double gaussian = 0.0;  // its expectation for Gaussian errors (Mardia's exact moments)
  double p_value = 1.0;   // two-sided
  int experiments = 0;    // pooled
  bool valid = false;
};
TailsTest tails_test(const Suite& suite, const SuiteModel& model,
                     const std::vector<std::vector<RunResidual>>& residuals, int replicates, std::uint64_t seed);

}  // namespace odomcov
