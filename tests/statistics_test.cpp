#include "odomcov/statistics.hpp"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <boost/math/distributions/normal.hpp>
#include <random>

namespace odomcov {
namespace {

/// Level of the statistical assertions here.
constexpr double kAlpha = 1e-3;

Matrix3 example_sigma() {
  Matrix3 s;
  s << 3.0e-5, -4.8e-5, -2.8e-5, -4.8e-5, 9.0e-5, 4.7e-5, -2.8e-5, 4.7e-5, 3.5e-5;
  return s;
}

/// Draws n samples of N(mu, sigma) with a fixed-seed std::mt19937_64.
std::vector<Vector3> gaussian_sample(std::mt19937_64& rng, int n, const Vector3& mu,
                                     const Matrix3& sigma) {
  const Matrix3 L = sigma.llt().matrixL();
  std::normal_distribution<double> z;
  std::vector<Vector3> out;
  for (int i = 0; i < n; ++i) out.push_back(mu + L * Vector3(z(rng), z(rng), z(rng)));
  return out;
}

TEST(Statistics, WelfordIsAccurateWithALargeOffset) {
  // E[x^2] - E[x]^2 would lose all digits here; Welford keeps ~1e-9 relative.
  std::mt19937_64 rng(1);
  std::vector<Vector3> xs = gaussian_sample(rng, 10000, Vector3(1e6, -2e6, 3e5), example_sigma());
  Vector3 mean = Vector3::Zero();
  for (const auto& x : xs) mean += x;
  mean /= 10000.0;
  Matrix3 two_pass = Matrix3::Zero();
  for (const auto& x : xs) two_pass += (x - mean) * (x - mean).transpose();
  two_pass /= 9999.0;
  const SampleMoments m = moments(xs);
  EXPECT_LT((m.cov - two_pass).cwiseAbs().maxCoeff(), 1e-6 * two_pass.cwiseAbs().maxCoeff());
}

TEST(Statistics, MergeEqualsSequential) {
  std::mt19937_64 rng(2);
  const std::vector<Vector3> xs = gaussian_sample(rng, 1000, Vector3(1, 2, 3), example_sigma());
  MomentAccumulator all, a, b, c;
  for (int i = 0; i < 1000; ++i) {
    all.add(xs[i]);
    (i < 300 ? a : i < 301 ? b : c).add(xs[i]);
  }
  a.merge(b);
  a.merge(c);
  a.merge(MomentAccumulator{});
  EXPECT_EQ(a.count(), 1000);
  EXPECT_LT((a.mean() - all.mean()).norm(), 1e-14);
  EXPECT_LT((a.covariance() - all.covariance()).cwiseAbs().maxCoeff(), 1e-18);
}

TEST(Statistics, Chi2SurvivalKnownValues) {
  // Upper 5% points of chi^2 (Abramowitz & Stegun, Table 26.8).
  EXPECT_NEAR(chi2_sf(7.8147, 3), 0.05, 1e-5);
  EXPECT_NEAR(chi2_sf(12.5916, 6), 0.05, 1e-5);
  EXPECT_EQ(chi2_sf(0.0, 3), 1.0);
}

/// Rejection rate under H0 of a test over `reps` replications must be alpha_test within the
/// binomial band z sqrt(a(1-a)/reps), z the two-sided kAlpha normal quantile.
template <class F>
void expect_size(F test_p_value, double alpha_test, int reps, const char* what) {
  int rejected = 0;
  for (int r = 0; r < reps; ++r) rejected += test_p_value(r) < alpha_test;
  const double z = boost::math::quantile(boost::math::normal(), 1 - kAlpha / 2);
  EXPECT_NEAR(static_cast<double>(rejected) / reps, alpha_test,
              z * std::sqrt(alpha_test * (1 - alpha_test) / reps))
      << what;
}

TEST(Statistics, TestsHaveTheirNominalSizeAtSmallN) {
  // n = 40 measured runs is a realistic lab suite; the Bartlett correction keeps the LRT's
  // size at alpha there (the uncorrected statistic rejects ~7.5% at a nominal 5%).
  std::mt19937_64 rng(3);
  const Matrix3 sigma = example_sigma();
  const Vector3 mu(0.001, -0.002, 0.0);
  const int n = 40;
  expect_size([&](int) { return covariance_test(moments(gaussian_sample(rng, n, mu, sigma)), sigma).p_value; },
              0.05, 4000, "covariance LRT");
  expect_size([&](int) { return mean_test_known_covariance(moments(gaussian_sample(rng, n, mu, sigma)), mu, sigma).p_value; },
              0.05, 4000, "mean chi^2");
  expect_size([&](int) { return hotelling_test(moments(gaussian_sample(rng, n, mu, sigma)), mu).p_value; },
              0.05, 4000, "Hotelling T^2");
}

TEST(Statistics, TestsRejectWrongModels) {
  std::mt19937_64 rng(4);
  const Matrix3 sigma = example_sigma();
  const SampleMoments s = moments(gaussian_sample(rng, 2000, Vector3::Zero(), sigma));
  EXPECT_LT(covariance_test(s, 1.2 * sigma).p_value, kAlpha);
  EXPECT_LT(mean_test_known_covariance(s, Vector3(3e-4, 0, 0), sigma).p_value, kAlpha);
}

TEST(Statistics, NeesMeanFromMomentsEqualsTheDirectAverage) {
  std::mt19937_64 rng(5);
  const Matrix3 sigma = example_sigma();
  const Vector3 mu(1e-3, 0, -1e-3);
  const std::vector<Vector3> xs = gaussian_sample(rng, 500, Vector3::Zero(), sigma);
  double direct = 0;
  for (const auto& x : xs) direct += (x - mu).dot(sigma.llt().solve(x - mu));
  EXPECT_NEAR(nees_mean(moments(xs), mu, sigma), direct / 500, 1e-10);
}

TEST(Statistics, SingularReferenceMakesTestsInapplicable) {
  const SampleMoments s{100, Vector3::Zero(), Matrix3::Identity()};
  EXPECT_FALSE(covariance_test(s, Matrix3::Zero()).valid);
  EXPECT_FALSE(mean_test_known_covariance(s, Vector3::Zero(), Matrix3::Zero()).valid);
}

TEST(Statistics, GaussianLogDensity) {
  const Matrix3 sigma = Vector3(4.0, 1.0, 0.25).asDiagonal();
  const Vector3 x(2.0, 1.0, 0.5);  // each coordinate one sigma out
  EXPECT_NEAR(gaussian_log_density(x, Vector3::Zero(), sigma),
              -0.5 * (3.0 + std::log(1.0) + 3 * std::log(2 * M_PI)), 1e-14);
}

}  // namespace
}  // namespace odomcov
