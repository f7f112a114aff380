// Streaming moments and the statistical tests of the reports: the end-pose error sample against
// a predicted mean and covariance.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "odomcov/closed_form/closed_form.hpp"

namespace odomcov {

using Matrix6 = Eigen::Matrix<double, 6, 6>;

/// Streaming mean, covariance and third and fourth central co-moments of 3-vectors: Welford's
/// update for single samples and the pairwise merge of [Chan79], extended to the third and
/// fourth co-moments by [Pebay08] eqs. (3.1)-(3.2) for partial results, so a parallel reduction
/// can combine blocks (in a fixed tree, deterministically). Memory is constant in the number of
/// samples. With delta = mean_B - mean_A and n = n_A + n_B, sums over the distinct placements
/// of the indices:
///   M2_ij   += M2B_ij + d_i d_j n_A n_B / n
///   M3_ijk  += M3B_ijk + d_i d_j d_k n_A n_B (n_A - n_B)/n^2
///              + (1/n) sum_3 (n_A M2B_ij - n_B M2A_ij) d_k
///   M4_ijkl += M4B_ijkl + d_i d_j d_k d_l n_A n_B (n_A^2 - n_A n_B + n_B^2)/n^3
///              + (1/n^2) sum_6 (n_A^2 M2B_ij + n_B^2 M2A_ij) d_k d_l
///              + (1/n) sum_4 (n_A M3B_ijk - n_B M3A_ijk) d_l
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
  /// Sum of fourth-order products of deviations from the mean, M4_ijkl (i, j, k, l in 0..2).
  double fourth(int i, int j, int k, int l) const { return m4_[((i * 3 + j) * 3 + k) * 3 + l]; }
  /// The ADF estimate of the asymptotic covariance of sqrt(n) vech(S) [Browne84, eq. (2.10)]:
  ///   Gamma_(ij),(kl) = M4_ijkl / n - (M2_ij / n)(M2_kl / n),  vech order xx, xy, xt, yy, yt, tt.
  Matrix6 gamma() const;

 private:
  std::int64_t n_ = 0;
  Vector3 mean_ = Vector3::Zero();
  Matrix3 m2_ = Matrix3::Zero();
  double m3_[27] = {};
  double m4_[81] = {};
};

/// Sample moments as reported: n, mean and unbiased covariance, and (from an accumulator) the
/// fourth-moment matrix Gamma of the ADF covariance test.
struct SampleMoments {
  std::int64_t n = 0;
  Vector3 mean = Vector3::Zero();
  Matrix3 cov = Matrix3::Zero();
  Matrix6 gamma = Matrix6::Zero();
  bool has_gamma = false;
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

/// Browne's asymptotically distribution-free test of Sigma = Sigma0 [Browne84, Prop. 4]:
///   T = n (s - sigma0)' Gamma^-1 (s - sigma0) ~ chi^2_6,  s = vech(S), sigma0 = vech(Sigma0),
/// with Gamma the sample's own fourth-moment matrix (MomentAccumulator::gamma). Its size holds
/// for any distribution with finite fourth moments (the banana of large heading noise), where
/// the LRT's chi^2 assumes normality. Needs has_gamma and n > 6.
TestResult covariance_test_adf(const SampleMoments& s, const Matrix3& sigma0);

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
