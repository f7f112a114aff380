// Counter-based random numbers for the simulator: Philox4x32-10 [Salmon11] from Random123, and
// standard normals by the ziggurat method with 256 blocks [Marsaglia00] in the ZIGNOR form of
// [Doornik05], which takes the block index and the value from disjoint bits.
//
// Stream layout. One key per seed; every draw is Philox(counter, key) with
//   counter = (sample index, stream tag, run index low 32 bits, run index high 32 bits).
// A run's numbers therefore depend only on (seed, run, sample, tag): not on the thread, the
// lane or the order in which runs are simulated. A tag is a 24-bit base plus, in bits 24..31,
// the attempt number k >= 1 of a ziggurat retry (k = 0 is the first draw). Bases:
//   kTagWheelNoise       the two wheel normals of each sample (128 bits, one per 64)
//   kTagWheelRetry + w   retries of the normal of wheel w (0 left, 1 right)
//   kTagEffect | e << 8 | i   per-sample draw i (< 256) of effect slot e (< 16)
//   kTagPerRun | e << 8       per-run draws of effect slot e (the counter's sample = draw number)
//   kTagMeasurement           measurement noise of synthesised suites
//   kTagGroup                 group_variation's draw per group (run = hash of the group name)
//   kTagStartHeading          a synthesised run's start heading (world experiments' heading0)
//
// The seed -> numbers mapping, in full (docs/performance.md; the SIMD kernels keep it exactly):
// key = (seed bits 0-31, seed bits 32-63). A draw's four output words w0..w3 give two 64-bit
// candidates, lo = w0 | w1 << 32 and hi = w2 | w3 << 32: a sample's left wheel normal comes from
// lo and its right wheel normal from hi of the draw at kTagWheelNoise; a per-sample or per-run
// normal of an effect from lo of its own draw. A candidate is a normal by ZIGNOR: block
// i = bits 0-7, sign = bit 8, u = bits 12-63 / 2^52; accepted when u < ratio[i] (z = +-u x[i]),
// else zig_slow: the wedge test with the polynomial exp of wedge_exp-inl.hpp (no C library
// function, so every machine decides it alike), the tail by std::log, new candidates from the
// retry draws. Test: Simulator.SeedGivesTheDocumentedBits pins three runs' bits.
#pragma once

#include <Random123/philox.h>

#include <cmath>
#include <cstdint>

namespace odomcov::random {

using Philox = r123::Philox4x32;  // 10 rounds

inline constexpr std::uint32_t kTagWheelNoise = 0;
inline constexpr std::uint32_t kTagWheelRetry = 1;     // + wheel
inline constexpr std::uint32_t kTagEffect = 0x10000;
inline constexpr std::uint32_t kTagPerRun = 0x20000;
inline constexpr std::uint32_t kTagMeasurement = 0x30000;
inline constexpr std::uint32_t kTagGroup = 0x40000;
inline constexpr std::uint32_t kTagStartHeading = 0x50000;
/// derive_seed(seed, kGroupSeedStream) keys the group draws (group_effects), apart from every
/// experiment's own seed derive_seed(seed, i) for i < 2^62.
inline constexpr std::uint64_t kGroupSeedStream = 0xC000000000000001ull;
inline constexpr int kRetryShift = 24;
inline constexpr std::uint32_t kMaxRetries = 255;

/// SplitMix64 [Steele14]: a bijective 64-bit mixer.
inline std::uint64_t splitmix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

/// The seed of the i-th independent job (a sweep point, a synthesised experiment) of `seed`.
inline std::uint64_t derive_seed(std::uint64_t seed, std::uint64_t i) {
  return splitmix64(seed ^ splitmix64(i));
}

inline Philox::key_type key_from_seed(std::uint64_t seed) {
  return {{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32)}};
}

inline Philox::ctr_type counter(std::uint64_t run, std::uint32_t sample, std::uint32_t tag) {
  return {{sample, tag, static_cast<std::uint32_t>(run), static_cast<std::uint32_t>(run >> 32)}};
}

/// The four 32-bit words of one draw, as two 64-bit halves.
struct Bits128 {
  std::uint64_t lo;
  std::uint64_t hi;
};

inline Bits128 draw(const Philox::key_type& key, std::uint64_t run, std::uint32_t sample,
                    std::uint32_t tag) {
  const Philox::ctr_type out = Philox()(counter(run, sample, tag), key);
  return {out[0] | (std::uint64_t{out[1]} << 32), out[2] | (std::uint64_t{out[3]} << 32)};
}

/// Uniform in [0, 1) with 52 random bits (bits 12..63), exactly as the vector kernel builds it:
/// the bits become the mantissa of a double in [1, 2), minus one.
inline double uniform52(std::uint64_t bits) {
  const std::uint64_t mantissa = (bits >> 12) | 0x3FF0000000000000ull;
  double one_to_two;
  static_assert(sizeof one_to_two == sizeof mantissa);
  __builtin_memcpy(&one_to_two, &mantissa, sizeof one_to_two);
  return one_to_two - 1.0;
}

/// Uniform in (0, 1], for logarithms.
inline double uniform52_open0(std::uint64_t bits) { return 1.0 - uniform52(bits); }

/// Ziggurat tables for N(0, 1), 256 blocks of equal area V with right edge R [Marsaglia00].
/// x[0] = V/f(R) is the base block's virtual width; x[256] = 0; ratio[i] = x[i+1]/x[i].
struct ZigguratTables {
  static constexpr int kBlocks = 256;
  static constexpr double kR = 3.6541528853610088;
  double v;  // R f(R) + int_R^inf f, computed from R so the top block closes exactly
  alignas(64) double x[kBlocks + 1];
  alignas(64) double ratio[kBlocks];
  ZigguratTables();
};
extern const ZigguratTables kZiggurat;

/// A 64-bit candidate: index = bits 0..7, sign = bit 8, magnitude = bits 12..63.
inline int zig_index(std::uint64_t bits) { return static_cast<int>(bits & 0xFF); }
inline bool zig_negative(std::uint64_t bits) { return (bits & 0x100) != 0; }

/// The fast path: accepted when the uniform falls inside the block's inner rectangle (98.8%).
inline bool zig_fast(std::uint64_t bits, double& z) {
  const int i = zig_index(bits);
  const double u = uniform52(bits);
  if (u >= kZiggurat.ratio[i]) return false;
  z = (zig_negative(bits) ? -u : u) * kZiggurat.x[i];
  return true;
}

/// The full ziggurat for a candidate rejected by zig_fast: the wedge test (its exp is the
/// polynomial of wedge_exp-inl.hpp, the same on every machine and instruction set), the tail
/// (Marsaglia's exponential method, std::log) and new candidates, drawing fresh bits at
/// (run, sample, retry_base | k << kRetryShift) for attempts k = 1, 2, ... (from
/// `first_attempt` on: the SIMD kernel hands over a tail candidate at its attempt).
double zig_slow(std::uint64_t bits, const Philox::key_type& key, std::uint64_t run,
                std::uint32_t sample, std::uint32_t retry_base, std::uint32_t first_attempt = 1);

/// A standard normal from a 64-bit candidate (fast path, else the full method).
inline double normal(std::uint64_t bits, const Philox::key_type& key, std::uint64_t run,
                     std::uint32_t sample, std::uint32_t retry_base) {
  double z;
  return zig_fast(bits, z) ? z : zig_slow(bits, key, run, sample, retry_base);
}

/// A standard normal for effects and per-run draws: one Philox draw per value at `tag`.
inline double normal_at(const Philox::key_type& key, std::uint64_t run, std::uint32_t sample,
                        std::uint32_t tag) {
  return normal(draw(key, run, sample, tag).lo, key, run, sample, tag);
}

/// Uniform in [0, 1) for effects: one Philox draw per value at `tag`.
inline double uniform_at(const Philox::key_type& key, std::uint64_t run, std::uint32_t sample,
                         std::uint32_t tag) {
  return uniform52(draw(key, run, sample, tag).lo);
}

}  // namespace odomcov::random
