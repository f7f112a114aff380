// The random-number layer: ziggurat tables, and the normal generator's distribution checked at
// a stated alpha with fixed keys.
#include "base/random.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <cmath>
#include <vector>

namespace odomcov::random {
namespace {

constexpr double kAlpha = 1e-3;

/// Kolmogorov's limiting distribution: P(sqrt(n) D > x) = 2 sum (-1)^(k-1) exp(-2 k^2 x^2).
double kolmogorov_sf(double x) {
  double sum = 0;
  for (int k = 1; k < 100; ++k) sum += (k % 2 ? 2.0 : -2.0) * std::exp(-2.0 * k * k * x * x);
  return std::clamp(sum, 0.0, 1.0);
}

std::vector<double> draws(std::size_t n, std::uint64_t seed) {
  const auto key = key_from_seed(seed);
  std::vector<double> z(n);
  for (std::size_t i = 0; i < n; ++i) {
    z[i] = normal_at(key, i >> 20, static_cast<std::uint32_t>(i & 0xFFFFF), kTagEffect);
  }
  return z;
}

TEST(Random, ZigguratBlocksHaveEqualArea) {
  const ZigguratTables& t = kZiggurat;
  auto f = [](double x) { return std::exp(-0.5 * x * x); };
  for (int i = 1; i < ZigguratTables::kBlocks; ++i) {
    ASSERT_GT(t.x[i], t.x[i + 1]);
    EXPECT_NEAR(t.x[i] * (f(t.x[i + 1]) - f(t.x[i])), t.v, 1e-12 * t.v) << "block " << i;
  }
  EXPECT_GT(t.x[ZigguratTables::kBlocks - 1], 0.0);
  EXPECT_NEAR(t.x[0] * f(t.kR), t.v, 1e-15);
}

TEST(Random, DrawIsRandom123Philox) {
  const auto key = key_from_seed(0x0123456789ABCDEFull);
  const Philox::ctr_type out = Philox()(counter(77, 5, 3), key);
  const Bits128 b = draw(key, 77, 5, 3);
  EXPECT_EQ(b.lo, out[0] | (std::uint64_t{out[1]} << 32));
  EXPECT_EQ(b.hi, out[2] | (std::uint64_t{out[3]} << 32));
}

TEST(Random, NormalsPassKolmogorovSmirnov) {
  std::vector<double> z = draws(2'000'000, 42);
  std::sort(z.begin(), z.end());
  const boost::math::normal phi;
  double d = 0;
  const double n = static_cast<double>(z.size());
  for (std::size_t i = 0; i < z.size(); ++i) {
    const double c = boost::math::cdf(phi, z[i]);
    d = std::max({d, c - static_cast<double>(i) / n, static_cast<double>(i + 1) / n - c});
  }
  EXPECT_GE(kolmogorov_sf(std::sqrt(n) * d), kAlpha) << "D = " << d;
}

TEST(Random, NormalMomentsAndTails) {
  const std::vector<double> z = draws(4'000'000, 7);
  const double n = static_cast<double>(z.size());
  double m1 = 0, m2 = 0, m4 = 0, beyond_r = 0, beyond_2 = 0;
  for (double x : z) {
    m1 += x, m2 += x * x, m4 += x * x * x * x;
    beyond_r += std::abs(x) > ZigguratTables::kR;  // the tail algorithm's region
    beyond_2 += std::abs(x) > 2.0;                  // wedges
  }
  m1 /= n, m2 /= n, m4 /= n;
  const double z_crit = boost::math::quantile(boost::math::normal(), 1 - kAlpha / 2);
  EXPECT_NEAR(m1, 0.0, z_crit / std::sqrt(n));
  EXPECT_NEAR(m2, 1.0, z_crit * std::sqrt(2.0 / n));
  EXPECT_NEAR(m4, 3.0, z_crit * std::sqrt(96.0 / n));  // Var(x^4) = 105 - 9
  for (auto [count, edge] : {std::pair{beyond_r, ZigguratTables::kR}, std::pair{beyond_2, 2.0}}) {
    const double p = 2 * boost::math::cdf(boost::math::complement(boost::math::normal(), edge));
    EXPECT_NEAR(count / n, p, z_crit * std::sqrt(p * (1 - p) / n)) << "beyond " << edge;
  }
}

TEST(Random, NormalsFillEquiprobableBins) {
  // Pearson chi^2 over 200 bins of equal N(0,1) probability.
  const std::vector<double> z = draws(1'000'000, 3);
  const int bins = 200;
  std::vector<double> counts(bins, 0.0);
  const boost::math::normal phi;
  for (double x : z) {
    counts[std::min(bins - 1, static_cast<int>(boost::math::cdf(phi, x) * bins))] += 1;
  }
  const double expected = static_cast<double>(z.size()) / bins;
  double chi2 = 0;
  for (double c : counts) chi2 += (c - expected) * (c - expected) / expected;
  const double p = boost::math::cdf(boost::math::complement(boost::math::chi_squared(bins - 1), chi2));
  EXPECT_GE(p, kAlpha) << "chi2 = " << chi2;
}

}  // namespace
}  // namespace odomcov::random
