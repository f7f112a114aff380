#include "base/random.hpp"

#include <stdexcept>

namespace odomcov::random {
namespace {

double gauss_density(double x) { return std::exp(-0.5 * x * x); }

// The wedge test's exp, the same polynomial the SIMD kernels evaluate.
#include "base/wedge_exp-inl.hpp"

double identity(double v) { return v; }

}  // namespace

ZigguratTables::ZigguratTables() {
  const double R = kR;
  v = R * gauss_density(R) + std::sqrt(M_PI / 2) * std::erfc(R / std::sqrt(2.0));
  x[0] = v / gauss_density(R);
  x[1] = R;
  for (int i = 2; i < kBlocks; ++i) {
    x[i] = std::sqrt(-2.0 * std::log(v / x[i - 1] + gauss_density(x[i - 1])));
  }
  x[kBlocks] = 0.0;
  for (int i = 0; i < kBlocks; ++i) ratio[i] = x[i + 1] / x[i];
}

const ZigguratTables kZiggurat;

double zig_slow(std::uint64_t bits, const Philox::key_type& key, std::uint64_t run,
                std::uint32_t sample, std::uint32_t retry_base, std::uint32_t first_attempt) {
  const ZigguratTables& t = kZiggurat;
  for (std::uint32_t k = first_attempt; k <= kMaxRetries; ++k) {
    const int i = zig_index(bits);
    const double u = uniform52(bits);
    const double sign = zig_negative(bits) ? -1.0 : 1.0;
    if (u < t.ratio[i]) return sign * u * t.x[i];
    const Bits128 fresh = draw(key, run, sample, retry_base | (k << kRetryShift));
    if (i == 0) {
      // Tail beyond R [Marsaglia64]: x = -ln(U1)/R, y = -ln(U2), accept when 2y > x^2; on
      // rejection the same (tail) candidate is tried again with the next attempt's bits.
      const double x = -std::log(uniform52_open0(fresh.lo)) / t.kR;
      const double y = -std::log(uniform52_open0(fresh.hi));
      if (y + y > x * x) return sign * (t.kR + x);
      continue;
    }
    // Wedge: the point (x, f(x_i) + U (f(x_{i+1}) - f(x_i))) lies under the density when
    // f0 + U (f1 - f0) < 1 with f0 = f(x_i)/f(x), f1 = f(x_{i+1})/f(x) [Doornik05].
    const double x = u * t.x[i];
    const double f0 = wedge_exp(-0.5 * (t.x[i] * t.x[i] - x * x), identity);
    const double f1 = wedge_exp(-0.5 * (t.x[i + 1] * t.x[i + 1] - x * x), identity);
    if (f0 + uniform52(fresh.hi) * (f1 - f0) < 1.0) return sign * x;
    bits = fresh.lo;  // a new candidate
  }
  // Each attempt accepts with probability > 0.5; 255 failures have probability < 1e-76.
  throw std::logic_error("ziggurat: retry budget exhausted");
}

}  // namespace odomcov::random
