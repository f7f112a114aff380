#include "odomcov/statistics.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <cmath>
#include <limits>
#include <ostream>

namespace odomcov {
namespace {

constexpr int kDim = 3;

/// Cholesky of a covariance; nullopt-like failure when not positive definite.
bool cholesky(const Matrix3& sigma, Eigen::LLT<Matrix3>& llt) {
  llt.compute(sigma);
  return llt.info() == Eigen::Success && sigma.allFinite();
}

TestResult invalid(int dof) {
  TestResult r;
  r.statistic = std::numeric_limits<double>::quiet_NaN();
  r.p_value = std::numeric_limits<double>::quiet_NaN();
  r.dof = dof;
  r.valid = false;
  return r;
}

}  // namespace

void MomentAccumulator::add(const Vector3& x) {
  ++n_;
  const Vector3 delta = x - mean_;
  mean_ += delta / static_cast<double>(n_);
  // delta (x - mean_new)' = delta delta' (n-1)/n, written symmetric.
  m2_ += (delta * delta.transpose()) * (static_cast<double>(n_ - 1) / static_cast<double>(n_));
}

void MomentAccumulator::merge(const MomentAccumulator& other) {
  if (other.n_ == 0) return;
  if (n_ == 0) {
    *this = other;
    return;
  }
  const double na = static_cast<double>(n_);
  const double nb = static_cast<double>(other.n_);
  const double n = na + nb;
  const Vector3 delta = other.mean_ - mean_;
  mean_ += delta * (nb / n);
  m2_ += other.m2_ + (delta * delta.transpose()) * (na * nb / n);
  n_ += other.n_;
}

Matrix3 MomentAccumulator::covariance() const {
  return n_ > 1 ? Matrix3(m2_ / static_cast<double>(n_ - 1)) : Matrix3::Zero();
}

SampleMoments moments(const MomentAccumulator& acc) {
  return {acc.count(), acc.mean(), acc.covariance()};
}

SampleMoments moments(const std::vector<Vector3>& samples) {
  MomentAccumulator acc;
  for (const Vector3& x : samples) acc.add(x);
  return moments(acc);
}

Matrix3 std_corr_matrix(const Matrix3& cov) {
  Matrix3 out;
  const Vector3 sd = cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      out(i, j) = i == j ? sd(i) : (sd(i) > 0 && sd(j) > 0 ? cov(i, j) / (sd(i) * sd(j)) : 0.0);
    }
  }
  return out;
}

double chi2_sf(double x, double dof) {
  if (std::isnan(x) || !(dof > 0.0) || !std::isfinite(dof)) return std::numeric_limits<double>::quiet_NaN();
  if (!(x > 0.0)) return 1.0;
  if (std::isinf(x)) return 0.0;
  return boost::math::cdf(boost::math::complement(boost::math::chi_squared(dof), x));
}

TestResult mean_test_known_covariance(const SampleMoments& s, const Vector3& mu0,
                                      const Matrix3& sigma0) {
  Eigen::LLT<Matrix3> llt;
  if (s.n < 1 || !cholesky(sigma0, llt) || !s.mean.allFinite() || !mu0.allFinite()) return invalid(kDim);
  const Vector3 d = s.mean - mu0;
  TestResult r;
  r.dof = kDim;
  r.statistic = static_cast<double>(s.n) * d.dot(llt.solve(d));
  r.p_value = chi2_sf(r.statistic, kDim);
  return r;
}

TestResult hotelling_test(const SampleMoments& s, const Vector3& mu0) {
  Eigen::LLT<Matrix3> llt;
  if (s.n <= kDim || !cholesky(s.cov, llt)) return invalid(kDim);
  const double n = static_cast<double>(s.n);
  const Vector3 d = s.mean - mu0;
  TestResult r;
  r.dof = kDim;
  r.statistic = n * d.dot(llt.solve(d));
  if (!std::isfinite(r.statistic)) return invalid(kDim);
  const double f = (n - kDim) / (kDim * (n - 1.0)) * r.statistic;
  r.p_value = f > 0.0 ? boost::math::cdf(boost::math::complement(
                            boost::math::fisher_f(kDim, n - kDim), f))
                      : 1.0;
  return r;
}

TestResult covariance_test(const SampleMoments& s, const Matrix3& sigma0) {
  constexpr int kDof = kDim * (kDim + 1) / 2;
  Eigen::LLT<Matrix3> llt;
  if (s.n <= kDim || !cholesky(sigma0, llt) || !s.cov.allFinite()) return invalid(kDof);
  const Matrix3 m = llt.solve(s.cov);  // Sigma0^-1 S: same trace and determinant as S Sigma0^-1
  const double det = m.determinant();
  if (!(det > 0.0)) {
    TestResult r;
    r.dof = kDof;
    r.statistic = std::numeric_limits<double>::infinity();
    r.p_value = 0.0;
    return r;
  }
  const double n1 = static_cast<double>(s.n - 1);
  const double rho = 1.0 - (2.0 * kDim * kDim + 3.0 * kDim - 1.0) / (6.0 * n1 * (kDim + 1.0));
  TestResult r;
  r.dof = kDof;
  r.statistic = rho * n1 * (m.trace() - std::log(det) - kDim);
  r.p_value = chi2_sf(r.statistic, kDof);
  return r;
}

double nees_mean(const SampleMoments& s, const Vector3& mu, const Matrix3& sigma) {
  Eigen::LLT<Matrix3> llt;
  if (s.n < 1 || !cholesky(sigma, llt)) return std::numeric_limits<double>::quiet_NaN();
  const double n = static_cast<double>(s.n);
  const Vector3 d = s.mean - mu;
  const Matrix3 second = s.cov * ((n - 1.0) / n) + d * d.transpose();
  return llt.solve(second).trace();
}

const char* Verdict::name() const {
  switch (kind) {
    case Kind::consistent: return "consistent";
    case Kind::inconsistent: return "inconsistent";
    case Kind::untestable: return "untestable";
  }
  return "untestable";
}

std::string Verdict::text() const {
  return untestable() && !reason.empty() ? std::string(name()) + " (" + reason + ")" : name();
}

void Verdict::combine(const Verdict& other) {
  if (inconsistent() || other.consistent()) return;
  if (other.inconsistent() || consistent()) *this = other;
}

std::ostream& operator<<(std::ostream& out, const Verdict& v) { return out << v.text(); }

Verdict verdict(const TestResult& mean, const TestResult& cov, double alpha) {
  if ((mean.valid && mean.p_value < alpha) || (cov.valid && cov.p_value < alpha)) {
    return {Verdict::Kind::inconsistent, ""};
  }
  if (!mean.valid) {
    return Verdict::untestable("the mean test cannot be computed: the predicted covariance is "
                               "singular (no noise in some direction) or not finite");
  }
  if (std::isnan(mean.p_value) || (cov.valid && std::isnan(cov.p_value))) {
    return Verdict::untestable("a test statistic is not a number");
  }
  return {};
}

double gaussian_log_density(const Vector3& x, const Vector3& mu, const Matrix3& sigma) {
  Eigen::LLT<Matrix3> llt;
  if (!cholesky(sigma, llt)) return -std::numeric_limits<double>::infinity();
  const Vector3 d = x - mu;
  const Eigen::Matrix3d L = llt.matrixL();
  const double log_det = 2.0 * L.diagonal().array().log().sum();
  return -0.5 * (d.dot(llt.solve(d)) + log_det + kDim * std::log(2.0 * M_PI));
}

}  // namespace odomcov
