#include "odomcov/engine/statistics.hpp"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <algorithm>
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

/// The Cholesky of a predicted covariance that a test can be taken against: positive definite,
/// and, scaled to unit diagonal, no pivot below kMinCorrelationPivot. Two components whose
/// correlation is 1 (a straight line with one wheel noise-free ties the heading to the travel)
/// make the covariance singular, but rounding leaves it barely positive definite, and a test
/// against that would call any spread inconsistent (a NEES of 1e11): untestable instead.
constexpr double kMinCorrelationPivot = 1e-12;
bool cholesky_of_prediction(const Matrix3& sigma, Eigen::LLT<Matrix3>& llt) {
  if (!cholesky(sigma, llt)) return false;
  const Matrix3 L = llt.matrixL();
  for (int i = 0; i < kDim; ++i) {
    const double pivot = L(i, i) / std::sqrt(sigma(i, i));  // the unit-diagonal matrix's Cholesky
    if (!(pivot * pivot >= kMinCorrelationPivot)) return false;
  }
  return true;
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

namespace {

int at3(int i, int j, int k) { return (i * 3 + j) * 3 + k; }
int at4(int i, int j, int k, int l) { return ((i * 3 + j) * 3 + k) * 3 + l; }

}  // namespace

/// The distinct index sets of the symmetric co-moment tensors (i <= j <= k [<= l]) and, for
/// every full index, which set it belongs to.
struct SymmetricIndex {
  int sets4[15][4];
  int of4[81];
  int sets3[10][3];
  int of3[27];
  SymmetricIndex() {
    int n4 = 0, n3 = 0;
    for (int i = 0; i < 3; ++i) {
      for (int j = i; j < 3; ++j) {
        for (int k = j; k < 3; ++k) {
          sets3[n3][0] = i, sets3[n3][1] = j, sets3[n3][2] = k;
          int p3[3] = {i, j, k};
          do of3[at3(p3[0], p3[1], p3[2])] = n3; while (std::next_permutation(p3, p3 + 3));
          ++n3;
          for (int l = k; l < 3; ++l) {
            sets4[n4][0] = i, sets4[n4][1] = j, sets4[n4][2] = k, sets4[n4][3] = l;
            int p4[4] = {i, j, k, l};
            do of4[at4(p4[0], p4[1], p4[2], p4[3])] = n4; while (std::next_permutation(p4, p4 + 4));
            ++n4;
          }
        }
      }
    }
  }
};
const SymmetricIndex kSym;

void MomentAccumulator::add(const Vector3& x) {
  // The merge below with B = {x}: n_B = 1, M2B = M3B = M4B = 0.
  if (n_ == 0) {
    n_ = 1;
    mean_ = x;
    return;
  }
  const double na = static_cast<double>(n_);
  const double n = na + 1.0;
  const Vector3 d = x - mean_;
  const Matrix3& a2 = m2_;
  const double c4 = na * (na * na - na + 1.0) / (n * n * n);
  const double c3 = na * (na - 1.0) / (n * n);
  double v4[15], v3[10];
  for (int s = 0; s < 15; ++s) {
    const int i = kSym.sets4[s][0], j = kSym.sets4[s][1], k = kSym.sets4[s][2], l = kSym.sets4[s][3];
    v4[s] = c4 * d(i) * d(j) * d(k) * d(l) +
            (a2(i, j) * d(k) * d(l) + a2(i, k) * d(j) * d(l) + a2(i, l) * d(j) * d(k) +
             a2(j, k) * d(i) * d(l) + a2(j, l) * d(i) * d(k) + a2(k, l) * d(i) * d(j)) / (n * n) -
            (m3_[at3(i, j, k)] * d(l) + m3_[at3(i, j, l)] * d(k) + m3_[at3(i, k, l)] * d(j) +
             m3_[at3(j, k, l)] * d(i)) / n;
  }
  for (int s = 0; s < 10; ++s) {
    const int i = kSym.sets3[s][0], j = kSym.sets3[s][1], k = kSym.sets3[s][2];
    v3[s] = c3 * d(i) * d(j) * d(k) - (a2(i, j) * d(k) + a2(i, k) * d(j) + a2(j, k) * d(i)) / n;
  }
  for (int p = 0; p < 81; ++p) m4_[p] += v4[kSym.of4[p]];
  for (int p = 0; p < 27; ++p) m3_[p] += v3[kSym.of3[p]];
  mean_ += d / n;
  m2_ += (d * d.transpose()) * (na / n);
  n_ += 1;
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
  const Vector3 d = other.mean_ - mean_;
  const Matrix3& a2 = m2_;
  const Matrix3& b2 = other.m2_;
  // Fourth, then third co-moments, from the old lower ones ([Pebay08] eqs. (3.1)-(3.2)),
  // computed once per distinct index set (i <= j <= k <= l) and mirrored.
  const double c4 = na * nb * (na * na - na * nb + nb * nb) / (n * n * n);
  const double c3 = na * nb * (na - nb) / (n * n);
  auto two4 = [&](int p, int q, int r, int s) {
    return (na * na * b2(p, q) + nb * nb * a2(p, q)) * d(r) * d(s);
  };
  auto three4 = [&](int p, int q, int r, int s) {
    return (na * other.m3_[at3(p, q, r)] - nb * m3_[at3(p, q, r)]) * d(s);
  };
  auto two3 = [&](int p, int q, int r) { return (na * b2(p, q) - nb * a2(p, q)) * d(r); };
  double m4[81];
  double m3[27];
  for (int i = 0; i < 3; ++i) {
    for (int j = i; j < 3; ++j) {
      for (int k = j; k < 3; ++k) {
        const double v3 = m3_[at3(i, j, k)] + other.m3_[at3(i, j, k)] + c3 * d(i) * d(j) * d(k) +
                          (two3(i, j, k) + two3(i, k, j) + two3(j, k, i)) / n;
        const int p3[6][3] = {{i, j, k}, {i, k, j}, {j, i, k}, {j, k, i}, {k, i, j}, {k, j, i}};
        for (const auto& p : p3) m3[at3(p[0], p[1], p[2])] = v3;
        for (int l = k; l < 3; ++l) {
          const double v4 =
              m4_[at4(i, j, k, l)] + other.m4_[at4(i, j, k, l)] + c4 * d(i) * d(j) * d(k) * d(l) +
              (two4(i, j, k, l) + two4(i, k, j, l) + two4(i, l, j, k) + two4(j, k, i, l) +
               two4(j, l, i, k) + two4(k, l, i, j)) / (n * n) +
              (three4(i, j, k, l) + three4(i, j, l, k) + three4(i, k, l, j) + three4(j, k, l, i)) / n;
          int idx[4] = {i, j, k, l};  // every permutation of the sorted index set
          do {
            m4[at4(idx[0], idx[1], idx[2], idx[3])] = v4;
          } while (std::next_permutation(idx, idx + 4));
        }
      }
    }
  }
  std::copy(m4, m4 + 81, m4_);
  std::copy(m3, m3 + 27, m3_);
  mean_ += d * (nb / n);
  m2_ += other.m2_ + (d * d.transpose()) * (na * nb / n);
  n_ += other.n_;
}

Matrix6 MomentAccumulator::gamma() const {
  static constexpr int kVech[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  Matrix6 g = Matrix6::Zero();
  if (n_ < 1) return g;
  const double n = static_cast<double>(n_);
  for (int a = 0; a < 6; ++a) {
    for (int b = 0; b < 6; ++b) {
      const int i = kVech[a][0], j = kVech[a][1], k = kVech[b][0], l = kVech[b][1];
      g(a, b) = m4_[at4(i, j, k, l)] / n - (m2_(i, j) / n) * (m2_(k, l) / n);
    }
  }
  return g;
}

Matrix3 MomentAccumulator::covariance() const {
  return n_ > 1 ? Matrix3(m2_ / static_cast<double>(n_ - 1)) : Matrix3::Zero();
}

SampleMoments moments(const MomentAccumulator& acc) {
  return {acc.count(), acc.mean(), acc.covariance(), acc.gamma(), acc.count() > 0};
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
  if (s.n < 1 || !cholesky_of_prediction(sigma0, llt) || !s.mean.allFinite() || !mu0.allFinite()) return invalid(kDim);
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
  if (s.n <= kDim || !cholesky_of_prediction(sigma0, llt) || !s.cov.allFinite()) return invalid(kDof);
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

TestResult covariance_test_adf(const SampleMoments& s, const Matrix3& sigma0) {
  constexpr int kDof = kDim * (kDim + 1) / 2;
  static constexpr int kVech[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
  if (!s.has_gamma || s.n <= kDof || !sigma0.allFinite()) return invalid(kDof);
  Eigen::Matrix<double, 6, 1> diff;
  for (int a = 0; a < 6; ++a) diff(a) = s.cov(kVech[a][0], kVech[a][1]) - sigma0(kVech[a][0], kVech[a][1]);
  // Gamma is scaled to unit diagonal before the Cholesky, as its entries span many decades.
  const Eigen::Matrix<double, 6, 1> scale = s.gamma.diagonal().cwiseMax(0.0).cwiseSqrt();
  if (!(scale.minCoeff() > 0.0)) return invalid(kDof);
  const Matrix6 unit = scale.cwiseInverse().asDiagonal() * s.gamma * scale.cwiseInverse().asDiagonal();
  const Eigen::LLT<Matrix6> llt(unit);
  if (llt.info() != Eigen::Success) return invalid(kDof);
  const Eigen::Matrix<double, 6, 1> z = diff.cwiseQuotient(scale);
  TestResult r;
  r.dof = kDof;
  r.statistic = static_cast<double>(s.n) * z.dot(llt.solve(z));
  r.p_value = chi2_sf(r.statistic, kDof);
  return r;
}

double nees_mean(const SampleMoments& s, const Vector3& mu, const Matrix3& sigma) {
  Eigen::LLT<Matrix3> llt;
  if (s.n < 1 || !cholesky_of_prediction(sigma, llt)) return std::numeric_limits<double>::quiet_NaN();
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
