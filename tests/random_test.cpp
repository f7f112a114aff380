// The random-number layer: the stream layout (Philox words), the normal generator's accuracy
// against the exact normal quantile and its bits on every SIMD target, and its distribution
// checked at a stated alpha with fixed keys.
#include "base/random.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/special_functions/erf.hpp>
#include <cmath>
#include <cstring>
#include <vector>

#include "engine/lane_plan.hpp"

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

/// The exact normal at a word's grid point: sign(word) sqrt(2) erfc^-1((m + 1/2) 2^-31).
double exact_normal(std::uint32_t word) {
  const double a = (static_cast<double>(word & 0x7FFFFFFFu) + 0.5) * 0x1p-31;
  const double z = std::sqrt(2.0) * boost::math::erfc_inv(a);
  return (word & 0x80000000u) != 0 ? -z : z;
}

/// Words covering every magnitude: in each octave 2^b <= m < 2^(b+1) of the 31-bit magnitude
/// (and m = 0), `per` evenly spaced points, the octave's ends among them, with both signs; every
/// m below 2^10 (the far tail, w >= 16, is m < 128).
std::vector<std::uint32_t> spread_words(std::uint32_t per) {
  std::vector<std::uint32_t> w;
  for (std::uint32_t m = 0; m < 1024; ++m) w.push_back(m);
  for (int b = 10; b < 31; ++b) {
    const std::uint64_t lo = std::uint64_t{1} << b, span = lo - 1;
    for (std::uint32_t i = 0; i <= per; ++i)
      w.push_back(static_cast<std::uint32_t>(lo + span * i / per));
  }
  const std::size_t n = w.size();
  for (std::size_t i = 0; i < n; ++i) w.push_back(w[i] | 0x80000000u);
  return w;
}

TEST(Random, WordsAreRandom123PhiloxFourPerDraw) {
  const auto key = key_from_seed(0x0123456789ABCDEFull);
  for (std::uint32_t index : {0u, 1u, 2u, 3u, 4u, 77u, 0xFFFFFFFFu}) {
    const Philox::ctr_type out = Philox()(counter(77, index >> 2, 3), key);
    EXPECT_EQ(word_at(key, 77, index, 3), out[index & 3]) << index;
  }
  // The counter is (index / 4, tag, run low, run high).
  const Philox::ctr_type c = counter(0x100000002ull, 9, 5);
  EXPECT_EQ(c[0], 9u);
  EXPECT_EQ(c[1], 5u);
  EXPECT_EQ(c[2], 2u);
  EXPECT_EQ(c[3], 1u);
}

// The seed -> normals mapping pinned: these words and normals are the stream's (computed by this
// implementation when the stream was laid out; docs/performance.md, "Reproducibility").
TEST(Random, SeedGivesTheDocumentedNormals) {
  const auto key = key_from_seed(42);
  EXPECT_EQ(word_at(key, 5, 6, kTagWheelLeft), 1480969198u);
  const float expected[4] = {-0.112824321f, -0.825474083f, 1.37253916f, -1.83935988f};
  for (std::uint32_t i = 0; i < 4; ++i) {
    const float z = normal_from_word(word_at(key, 5, i, kTagWheelRight));
    std::uint32_t bits, want;
    std::memcpy(&bits, &z, sizeof bits);
    std::memcpy(&want, &expected[i], sizeof want);
    EXPECT_EQ(bits, want) << "sample " << i;
  }
}

// Accuracy: every normal within 3.5e-7 relative of the exact quantile at its grid point
// (bench/normal_icdf_accuracy checks all 2^32 words; these are the octaves' spread).
TEST(Random, NormalFromWordIsTheNormalQuantileToSinglePrecision) {
  double worst = 0.0;
  std::uint32_t at = 0;
  for (const std::uint32_t w : spread_words(2048)) {
    const double exact = exact_normal(w);
    const double rel = std::abs(static_cast<double>(normal_from_word(w)) - exact) / std::abs(exact);
    if (rel > worst) worst = rel, at = w;
  }
  EXPECT_LT(worst, 3.5e-7) << "word " << at;
  // The largest normal is word 0's, sqrt(2) erfc^-1(2^-32) = 6.338.
  EXPECT_NEAR(normal_from_word(0), 6.338, 1e-3);
  EXPECT_EQ(normal_from_word(0x80000000u), -normal_from_word(0));
}

TEST(Random, NormalsAreOddInTheSignBit) {
  for (const std::uint32_t w : spread_words(512)) {
    if ((w & 0x80000000u) != 0) continue;
    EXPECT_EQ(normal_from_word(w | 0x80000000u), -normal_from_word(w)) << w;
  }
}

TEST(Random, UniformFromWordIsTheGridMidpoint) {
  EXPECT_EQ(uniform_from_word(0), 0x1p-33);
  EXPECT_EQ(uniform_from_word(0xFFFFFFFFu), 1.0 - 0x1p-33);
  EXPECT_EQ(uniform_from_word(0x80000000u), 0.5 + 0x1p-33);
}

// Every SIMD target computes the scalar generator's bits, the rare tails included (each octave's
// spread holds words of all three polynomials).
TEST(Random, EveryTargetGivesTheScalarNormals) {
  const std::vector<std::uint32_t> words = spread_words(4096);
  std::vector<float> scalar(words.size());
  for (std::size_t i = 0; i < words.size(); ++i) scalar[i] = normal_from_word(words[i]);
  for (const lanes::Target& t : lanes::supported_targets()) {
    std::vector<float> z(words.size());
    t.normals(words.data(), words.size(), z.data());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < words.size(); ++i)
      differ += std::memcmp(&z[i], &scalar[i], sizeof(float)) != 0;
    EXPECT_EQ(differ, 0u) << t.name;
  }
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
  // The tail polynomial takes over at w = 5, |z| = sqrt(2) erf^-1(sqrt(1 - e^-5)).
  const double tail = std::sqrt(2.0) * boost::math::erf_inv(std::sqrt(1.0 - std::exp(-5.0)));
  double m1 = 0, m2 = 0, m4 = 0, beyond_tail = 0, beyond_2 = 0;
  for (double x : z) {
    m1 += x, m2 += x * x, m4 += x * x * x * x;
    beyond_tail += std::abs(x) > tail;
    beyond_2 += std::abs(x) > 2.0;
  }
  m1 /= n, m2 /= n, m4 /= n;
  const double z_crit = boost::math::quantile(boost::math::normal(), 1 - kAlpha / 2);
  EXPECT_NEAR(m1, 0.0, z_crit / std::sqrt(n));
  EXPECT_NEAR(m2, 1.0, z_crit * std::sqrt(2.0 / n));
  EXPECT_NEAR(m4, 3.0, z_crit * std::sqrt(96.0 / n));  // Var(x^4) = 105 - 9
  for (auto [count, edge] : {std::pair{beyond_tail, tail}, std::pair{beyond_2, 2.0}}) {
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
  const double p =
      boost::math::cdf(boost::math::complement(boost::math::chi_squared(bins - 1), chi2));
  EXPECT_GE(p, kAlpha) << "chi2 = " << chi2;
}

}  // namespace
}  // namespace odomcov::random
