// Counter-based random numbers for the simulator: Philox4x32-10 [Salmon11] from Random123, and
// standard normals by inversion of one 32-bit word each (base/normal_icdf-inl.hpp).
//
// Stream layout. One key per seed; every draw is Philox(counter, key) with
//   counter = (index >> 2, stream tag, run index low 32 bits, run index high 32 bits),
// and a draw's four output words serve four consecutive indices: index i reads word i & 3 of the
// draw at i >> 2. The index is the sample for per-sample streams and the draw number for per-run
// ones. A run's numbers therefore depend only on (seed, run, index, tag): not on the thread, the
// lane or the order in which runs are simulated. (tag, index) names one 32-bit word; a normal and
// a uniform at the same (tag, index) are functions of that one word. Tags:
//   kTagWheelLeft, kTagWheelRight   the wheel normals of each sample
//   kTagEffect | e << 8 | i         per-sample draw i (< 256) of effect slot e (< 16)
//   kTagPerRun | e << 8             per-run draws of effect slot e (index = draw number)
//   kTagMeasurement                 measurement noise of synthesised suites
//   kTagGroup                       group_variation's draw per group (run = hash of the group name)
//   kTagStartHeading                a synthesised run's start heading (world experiments' heading0)
//
// The seed -> numbers mapping, in full (docs/performance.md; the SIMD kernels keep it exactly):
// key = (seed bits 0-31, seed bits 32-63); a word becomes a normal by normal_from_word (bit 31
// the sign, bits 0-30 a point of a 2^31 grid inverted through the normal CDF in single precision)
// and a uniform by uniform_from_word ((word + 1/2) 2^-32). Tests: Random.* pin the words and the
// normals; Simulator.SeedGivesTheDocumentedBits pins three runs' bits.
#pragma once

#include <Random123/philox.h>

#include <cmath>
#include <cstdint>
#include <cstring>

namespace odomcov::random {

using Philox = r123::Philox4x32;  // 10 rounds

inline constexpr std::uint32_t kTagWheelLeft = 0;
inline constexpr std::uint32_t kTagWheelRight = 1;
inline constexpr std::uint32_t kTagEffect = 0x10000;
inline constexpr std::uint32_t kTagPerRun = 0x20000;
inline constexpr std::uint32_t kTagMeasurement = 0x30000;
inline constexpr std::uint32_t kTagGroup = 0x40000;
inline constexpr std::uint32_t kTagStartHeading = 0x50000;
/// derive_seed(seed, kGroupSeedStream) keys the group draws (group_effects), apart from every
/// experiment's own seed derive_seed(seed, i) for i < 2^62.
inline constexpr std::uint64_t kGroupSeedStream = 0xC000000000000001ull;

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

inline Philox::ctr_type counter(std::uint64_t run, std::uint32_t quad, std::uint32_t tag) {
  return {{quad, tag, static_cast<std::uint32_t>(run), static_cast<std::uint32_t>(run >> 32)}};
}

/// The four words of indices 4 quad .. 4 quad + 3 of stream `tag` of `run`.
inline Philox::ctr_type draw4(const Philox::key_type& key, std::uint64_t run, std::uint32_t quad,
                              std::uint32_t tag) {
  return Philox()(counter(run, quad, tag), key);
}

/// The word of index `index` of stream `tag` of `run`.
inline std::uint32_t word_at(const Philox::key_type& key, std::uint64_t run, std::uint32_t index,
                             std::uint32_t tag) {
  return draw4(key, run, index >> 2, tag)[index & 3];
}

/// The scalar arithmetic of normal_icdf-inl.hpp.
struct ScalarOps {
  using F = float;
  using I = std::int32_t;
  using M = bool;
  static F f(float c) { return c; }
  static I i(std::int32_t c) { return c; }
  static F to_float(I v) { return static_cast<float>(v); }
  static I bits(F v) {
    I b;
    std::memcpy(&b, &v, sizeof b);
    return b;
  }
  static F from_bits(I b) {
    F v;
    std::memcpy(&v, &b, sizeof v);
    return v;
  }
  static I shr23(I v) { return v >> 23; }  // arithmetic (C++20, and every compiler before)
  static I shl23(I v) { return static_cast<I>(static_cast<std::uint32_t>(v) << 23); }
  static F sqrt(F v) { return std::sqrt(v); }
  static M ge(F a, F b) { return a >= b; }
  static bool any(M m) { return m; }
  static F select(M m, F yes, F no) { return m ? yes : no; }
  static I And(I a, I b) { return a & b; }
  static I Xor(I a, I b) { return a ^ b; }
};

#include "base/normal_icdf-inl.hpp"  // IWYU pragma: export

/// The standard normal of one word (normal_icdf-inl.hpp; what every SIMD target computes).
inline float normal_from_word(std::uint32_t word) {
  const std::int32_t w[1] = {static_cast<std::int32_t>(word)};
  float z[1];
  normal_icdf<ScalarOps, 1>(w, z);
  return z[0];
}

/// The standard normals of N words at once (the same values as normal_from_word, word by word;
/// N independent chains, faster than one at a time).
template <int N>
inline void normals_from_words(const std::uint32_t (&words)[N], float (&z)[N]) {
  std::int32_t w[N];
  for (int j = 0; j < N; ++j) w[j] = static_cast<std::int32_t>(words[j]);
  normal_icdf<ScalarOps, N>(w, z);
}

/// The uniform of one word, (word + 1/2) 2^-32: in (0, 1), never 0 or 1 (exact in a double).
inline double uniform_from_word(std::uint32_t word) {
  return (static_cast<double>(word) + 0.5) * 0x1p-32;
}

/// A standard normal at (index, tag) of `run`: effects, per-run and measurement draws.
inline double normal_at(const Philox::key_type& key, std::uint64_t run, std::uint32_t index,
                        std::uint32_t tag) {
  return normal_from_word(word_at(key, run, index, tag));
}

/// A uniform in (0, 1) at (index, tag) of `run`.
inline double uniform_at(const Philox::key_type& key, std::uint64_t run, std::uint32_t index,
                         std::uint32_t tag) {
  return uniform_from_word(word_at(key, run, index, tag));
}

}  // namespace odomcov::random
