// Streaming moments and the statistical tests of the reports: the end-pose error sample against
// a predicted mean and covariance.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "odomcov/closed_form.hpp"

namespace odomcov {

/// Streaming mean and covariance of 3-vectors: Welford's update for single samples and the
/// pairwise merge of [Chan79] for partial results, so a parallel reduction can combine blocks.
/// Memory is constant in the number of samples.
class MomentAccumulator {
 public:
  void add(const Vector3& x);
  void merge(const MomentAccumulator& other);

  std::int64_t count() const { return n_; }
  const Vector3& mean() const { return mean_; }
  /// Sum of outer products of deviations from the mean (Anderson's A).
  const Matrix3& scatter() const { return m2_; }
  /// Unbiased sample covariance A/(n - 1).
  Matrix3 covariance() const;

 private:
  std::int64_t n_ = 0;
  Vector3 mean_ = Vector3::Zero();
  Matrix3 m2_ = Matrix3::Zero();
};

/// Sample moments as reported: n, mean and unbiased covariance.
struct SampleMoments {
  std::int64_t n = 0;
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
};
SampleMoments moments(const MomentAccumulator& acc);
SampleMoments moments(const std::vector<Vector3>& samples);

struct TestResult {
  double statistic = 0.0;
  int dof = 0;
  double p_value = 1.0;
  bool valid = true;  // false when the reference covariance is singular or n is too small
};

/// Standard deviations on the diagonal, correlation coefficients off it ([Kleeman95] §7); a
/// correlation with a zero standard deviation is 0.
Matrix3 std_corr_matrix(const Matrix3& cov);

/// Survival function of chi^2_dof (Boost.Math).
double chi2_sf(double x, double dof);

/// Mean with the predicted covariance known: n (m - mu0)' Sigma0^-1 (m - mu0) ~ chi^2_3.
TestResult mean_test_known_covariance(const SampleMoments& s, const Vector3& mu0,
                                      const Matrix3& sigma0);

/// Hotelling's T^2 with the sample covariance [Anderson03, §5.2]:
/// T^2 = n (m - mu0)' S^-1 (m - mu0); (n - p)/(p (n - 1)) T^2 ~ F(p, n - p). Reports T^2 with
/// dof = p and the F-based p-value. Needs n > p.
TestResult hotelling_test(const SampleMoments& s, const Vector3& mu0);

/// Likelihood-ratio test of Sigma = Sigma0 with the mean unknown [Anderson03, §10.8]:
///   statistic = rho n' (tr(S Sigma0^-1) - ln det(S Sigma0^-1) - p),  n' = n - 1, S unbiased,
///   rho = 1 - (2p^2 + 3p - 1)/(6 n' (p + 1))  (Bartlett correction, [Muirhead82, Thm 8.4.7]),
/// asymptotically chi^2 with p(p+1)/2 = 6 dof, with error O(n^-2).
TestResult covariance_test(const SampleMoments& s, const Matrix3& sigma0);

/// Mean NEES, (1/n) sum (x_i - mu)' Sigma^-1 (x_i - mu), from the moments alone:
/// tr(Sigma^-1 ((n-1)/n S + (m - mu)(m - mu)')). Expected value 3 when the model is right.
double nees_mean(const SampleMoments& s, const Vector3& mu, const Matrix3& sigma);

/// The outcome of a consistency check. Spelled "consistent", "inconsistent" or "untestable" in
/// JSON, CSV and text. Untestable: a statistic could not be computed (a singular or zero
/// predicted covariance, NaN anywhere); it is never read as consistent, and `--check` fails.
struct Verdict {
  enum class Kind { consistent, inconsistent, untestable };
  Kind kind = Kind::consistent;
  std::string reason;  // why, when untestable

  static Verdict untestable(std::string why) { return {Kind::untestable, std::move(why)}; }
  bool consistent() const { return kind == Kind::consistent; }
  bool inconsistent() const { return kind == Kind::inconsistent; }
  bool untestable() const { return kind == Kind::untestable; }
  const char* name() const;
  /// For reports: the name, and the reason when untestable.
  std::string text() const;
  /// Several checks together: inconsistent if any is, else untestable if any is.
  void combine(const Verdict& other);
  bool operator==(const char* spelling) const { return std::string(name()) == spelling; }
  bool operator==(const std::string& spelling) const { return name() == spelling; }
};
std::ostream& operator<<(std::ostream& out, const Verdict& v);

/// Inconsistent when a valid test rejects at alpha; untestable when the mean test cannot be
/// computed (singular reference covariance) or a p-value is NaN; else consistent.
Verdict verdict(const TestResult& mean, const TestResult& cov, double alpha);

/// Gaussian log-density of x under N(mu, sigma).
double gaussian_log_density(const Vector3& x, const Vector3& mu, const Matrix3& sigma);

}  // namespace odomcov
