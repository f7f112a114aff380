// The simulator's SIMD kernel, compiled once per instruction set by Highway (foreach_target in
// lane_kernels.cpp; the roofline harness in bench/ includes it too). A block of runs advances in
// lock step, run j of the block in lane j, structure of arrays: K vectors of N doubles each.
//
// Per sample and lane it does exactly what the scalar reference (lane_plan.cpp, reference_run)
// does per run:
//   * Philox4x32-10 at counter (sample / 4, tag, run lo, run hi), with the four 32-bit words held
//     in 64-bit lanes (the 32x32 -> 64 multiply is MulEven; the upper half of a word may hold
//     garbage between rounds because MulEven reads only the lower half, so no masking per round);
//     its four words are the stream's words of four consecutive samples;
//   * a normal per word by inversion (base/normal_icdf-inl.hpp) in single precision, two samples'
//     words of kN runs per vector of floats, branch-free but for the rare tails;
//   * the stochastic effects' operations of the leg (plan.ops), events per lane in scalar code;
//   * the exact arc step of arc_step.hpp; lanes outside its series bounds take the scalar step.
// Only IEEE-exact operations (+ - * / sqrt, conversions, comparisons, bit operations) are used,
// never MulAdd, so every target gives the scalar reference's bits.

#if defined(ODOMCOV_ENGINE_LANE_KERNEL_INL_HPP_) == defined(HWY_TARGET_TOGGLE)
#ifdef ODOMCOV_ENGINE_LANE_KERNEL_INL_HPP_
#undef ODOMCOV_ENGINE_LANE_KERNEL_INL_HPP_
#else
#define ODOMCOV_ENGINE_LANE_KERNEL_INL_HPP_
#endif

#include <hwy/highway.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "engine/lane_plan.hpp"

HWY_BEFORE_NAMESPACE();
namespace odomcov::lanes::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<double>;
using DU = hn::RebindToUnsigned<DF>;
using DU32 = hn::Repartition<std::uint32_t, DF>;
using VF = hn::Vec<DF>;
using VU = hn::Vec<DU>;
using MF = hn::Mask<DF>;

/// Doubles per vector, and vectors per block (runs in lock step = kN kK).
inline constexpr std::size_t kN = hn::MaxLanes(DF());
inline constexpr std::size_t kK = kN >= 8 ? 4 : kN >= 4 ? 2 : 4;
inline constexpr std::size_t kBlock = kN * kK;
/// Whether the two wheels' Philox draws and normals of a quad run interleaved (2 kK chains, 4 kK
/// vectors of normals): where one wheel's leave the vector units waiting for a round's or a
/// polynomial step's latency (AVX2's 2 chains: its plain kernel 10-15% faster together,
/// simulator_roofline A/B), not with AVX-512's 4, whose 8 spill registers (7% slower together).
inline constexpr bool kWheelsTogether = kBlock < 32;
static_assert(kBlock <= kMaxRuns, "a block must fit the kernel's output");

HWY_INLINE VF splat(double c) { return hn::Set(DF(), c); }

// This target's copy of the step's polynomials and pose update (arc_step.hpp).
#include "engine/arc_series-inl.hpp"
HWY_INLINE VU splat_u(std::uint64_t c) { return hn::Set(DU(), c); }

// ---------------------------------------------------------------------------------------------
// Philox4x32-10 in lanes
// ---------------------------------------------------------------------------------------------

/// The ten round keys of a seed's key (Random123's Weyl sequence), zero-extended.
struct RoundKeys {
  std::uint64_t k0[10], k1[10];
  explicit RoundKeys(const random::Philox::key_type& key) {
    std::uint32_t a = key[0], b = key[1];
    for (int r = 0; r < 10; ++r) {
      k0[r] = a;
      k1[r] = b;
      a += 0x9E3779B9u;
      b += 0xBB67AE85u;
    }
  }
};

/// Counter words in, output words out; w1 and w3 of the output keep garbage above bit 31.
struct Words {
  VU w0, w1, w2, w3;
  // User-provided: GCC compiles implicit constructors without the target's options (NEON).
  HWY_INLINE Words() {}
  HWY_INLINE Words(VU a, VU b, VU c, VU d) : w0(a), w1(b), w2(c), w3(d) {}
};

/// The 64-bit product of the lower 32 bits of each lane and m.
HWY_INLINE VU mul_wide(VU a, std::uint32_t m) {
#if HWY_TARGET == HWY_SCALAR
  // One lane (Highway's scalar fallback cannot view a 64-bit lane as two 32-bit ones).
  return splat_u((hn::GetLane(a) & 0xFFFFFFFFu) * std::uint64_t{m});
#else
  const DU32 d32;
  return hn::MulEven(hn::BitCast(d32, a), hn::BitCast(d32, splat_u(m)));
#endif
}

/// Philox on C vectors of counters at once (independent chains interleaved: a round is a chain
/// of a multiply, a shift and an xor, so a few vectors at a time wait for its latency).
template <std::size_t C>
HWY_INLINE void philox(Words (&w)[C], const RoundKeys& keys) {
  for (int r = 0; r < 10; ++r) {
    const VU k0 = splat_u(keys.k0[r]), k1 = splat_u(keys.k1[r]);
    for (std::size_t k = 0; k < C; ++k) {
      const VU p0 = mul_wide(w[k].w0, 0xD2511F53u);
      const VU p1 = mul_wide(w[k].w2, 0xCD9E8D57u);
      w[k].w0 = hn::Xor3(hn::ShiftRight<32>(p1), w[k].w1, k0);
      w[k].w2 = hn::Xor3(hn::ShiftRight<32>(p0), w[k].w3, k1);
      w[k].w1 = p1;
      w[k].w3 = p0;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Normals
// ---------------------------------------------------------------------------------------------

/// Floats per vector (2 kN: two samples of a vector's kN runs), and per half (one sample).
using DF32 = hn::Repartition<float, DF>;
using DH32 = hn::Rebind<float, DF>;

#if HWY_TARGET != HWY_SCALAR
using DI32 = hn::RebindToSigned<DF32>;

/// This target's arithmetic for normal_icdf-inl.hpp.
struct VecOps {
  using F = hn::Vec<DF32>;
  using I = hn::Vec<DI32>;
  using M = hn::Mask<DF32>;
  static HWY_INLINE F f(float c) { return hn::Set(DF32(), c); }
  static HWY_INLINE I i(std::int32_t c) { return hn::Set(DI32(), c); }
  static HWY_INLINE F to_float(I v) { return hn::ConvertTo(DF32(), v); }
  static HWY_INLINE I bits(F v) { return hn::BitCast(DI32(), v); }
  static HWY_INLINE F from_bits(I b) { return hn::BitCast(DF32(), b); }
  static HWY_INLINE I shr23(I v) { return hn::ShiftRight<23>(v); }
  static HWY_INLINE I shl23(I v) { return hn::ShiftLeft<23>(v); }
  static HWY_INLINE F sqrt(F v) { return hn::Sqrt(v); }
  static HWY_INLINE M ge(F a, F b) { return hn::Ge(a, b); }
  static HWY_INLINE bool any(M m) { return !hn::AllFalse(DF32(), m); }
  static HWY_INLINE F select(M m, F yes, F no) { return hn::IfThenElse(m, yes, no); }
  static HWY_INLINE I And(I a, I b) { return hn::And(a, b); }
  static HWY_INLINE I Xor(I a, I b) { return hn::Xor(a, b); }
};

// This target's copy of the normal generator (base/normal_icdf-inl.hpp).
#include "base/normal_icdf-inl.hpp"

/// The words of two samples as one vector of floats' worth: lo's kN words (the low half of each
/// 64-bit lane), then hi's.
HWY_INLINE VecOps::I pack(VU lo, VU hi) {
  const DI32 d;
  return hn::ConcatEven(d, hn::BitCast(d, hi), hn::BitCast(d, lo));
}

/// The normals of C vectors of a quad's draws: z[2k] samples 0 and 1 of vector k's runs,
/// z[2k + 1] samples 2 and 3.
template <std::size_t C>
HWY_INLINE void quad_normals(const Words* w, VecOps::F (&z)[2 * C]) {
  VecOps::I words[2 * C];
  for (std::size_t k = 0; k < C; ++k) {
    words[2 * k] = pack(w[k].w0, w[k].w1);
    words[2 * k + 1] = pack(w[k].w2, w[k].w3);
  }
  normal_icdf<VecOps, 2 * C>(words, z);
}
#endif

// ---------------------------------------------------------------------------------------------
// The block
// ---------------------------------------------------------------------------------------------

/// Samples whose normals are drawn ahead of their steps.
inline constexpr std::uint32_t kChunk = 32;

/// Walks the samples of a plan's legs.
struct LegCursor {
  const Leg* leg;
  const Leg* end;
  std::int64_t done = 0;
  /// Samples left in the leg, at most `most`.
  HWY_INLINE std::uint32_t left(std::uint32_t most) const {
    const std::int64_t rest = leg->count - done;
    return rest < most ? static_cast<std::uint32_t>(rest) : most;
  }
  /// Moves on by m <= left() samples.
  HWY_INLINE void skip(std::uint32_t m) {
    done += m;
    if (done >= leg->count) {
      do ++leg; while (leg != end && leg->count == 0);
      done = 0;
    }
  }
};

/// A leg's step constants as vectors, the same in every lane: a leg of the path, broadcast.
struct SharedLeg {
  static constexpr bool kPerLane = false;
  const Leg& leg;
  HWY_INLINE VF center(std::size_t) const { return splat(leg.center_m); }
  HWY_INLINE VF half(std::size_t) const { return splat(leg.half_rad); }
  HWY_INLINE VF cos_half(std::size_t) const { return splat(leg.cos_half); }
  HWY_INLINE VF sin_half(std::size_t) const { return splat(leg.sin_half); }
  HWY_INLINE VF inv_two_b(std::size_t) const { return splat(leg.inv_two_b); }
  HWY_INLINE VF lateral(std::size_t) const { return splat(leg.lateral_m); }
  HWY_INLINE VF sigma_left(std::size_t) const { return splat(leg.sigma_left); }
  HWY_INLINE VF sigma_right(std::size_t) const { return splat(leg.sigma_right); }
  HWY_INLINE bool any_lateral() const { return leg.lateral_m != 0.0; }
  /// The scalar leg of lane j of vector k.
  HWY_INLINE const Leg& of(std::size_t, std::size_t) const { return leg; }
};

/// A block's legs when they differ between its runs (Plan::per_run_legs): each lane's leg
/// (run_leg) and its step constants structure of arrays, rebuilt at every leg of the path.
struct LaneLegs {
  alignas(64) double center[kBlock], half[kBlock], cos_half[kBlock], sin_half[kBlock];
  alignas(64) double inv_two_b[kBlock], lateral[kBlock], sigma_left[kBlock], sigma_right[kBlock];
  alignas(64) double short_series[kBlock];  // 1 where the lane's leg takes the short series
  Leg leg[kBlock];
  bool any_lateral = false;

  void set(std::size_t j, const Leg& l) {
    leg[j] = l;
    center[j] = l.center_m, half[j] = l.half_rad, cos_half[j] = l.cos_half;
    sin_half[j] = l.sin_half, inv_two_b[j] = l.inv_two_b, lateral[j] = l.lateral_m;
    sigma_left[j] = l.sigma_left, sigma_right[j] = l.sigma_right;
    short_series[j] = l.short_series ? 1.0 : 0.0;
  }
};

/// The step constants of a LaneLegs table, loaded per vector.
struct PerLaneLeg {
  static constexpr bool kPerLane = true;
  const LaneLegs& t;
  static HWY_INLINE VF at(const double* a, std::size_t k) { return hn::Load(DF(), a + k * kN); }
  HWY_INLINE VF center(std::size_t k) const { return at(t.center, k); }
  HWY_INLINE VF half(std::size_t k) const { return at(t.half, k); }
  HWY_INLINE VF cos_half(std::size_t k) const { return at(t.cos_half, k); }
  HWY_INLINE VF sin_half(std::size_t k) const { return at(t.sin_half, k); }
  HWY_INLINE VF inv_two_b(std::size_t k) const { return at(t.inv_two_b, k); }
  HWY_INLINE VF lateral(std::size_t k) const { return at(t.lateral, k); }
  HWY_INLINE VF sigma_left(std::size_t k) const { return at(t.sigma_left, k); }
  HWY_INLINE VF sigma_right(std::size_t k) const { return at(t.sigma_right, k); }
  HWY_INLINE bool any_lateral() const { return t.any_lateral; }
  HWY_INLINE MF short_series(std::size_t k) const { return hn::Eq(at(t.short_series, k), splat(1.0)); }
  HWY_INLINE const Leg& of(std::size_t k, std::size_t j) const { return t.leg[k * kN + j]; }
};

/// kGeneral: the stochastic effects' operations run (the general kernel); kPerLane: the legs
/// differ between the block's runs (a custom effect's `random:` parameters), so the step loads
/// each leg's constants per lane from a table built at the leg's start.
template <bool kGeneral, bool kPerLane = false>
class Block {
  static_assert(kGeneral || !kPerLane, "legs differ per run only through stochastic effects");

 public:
  Block(const Plan& plan, const random::Philox::key_type& key, std::uint64_t first)
      : plan_(plan), key_(key), keys_(key), first_(first) {
    const DU du;
    for (std::size_t k = 0; k < kK; ++k) {
      run_[k] = hn::Iota(du, first + k * kN);
      run_lo_[k] = hn::And(run_[k], splat_u(0xFFFFFFFFu));
      run_hi_[k] = hn::ShiftRight<32>(run_[k]);
      p_[k] = {splat(0.0), splat(0.0), splat(1.0), splat(0.0), splat(0.0)};
    }
    if constexpr (kGeneral) begin_runs();
  }

  void run() {
    LegCursor at = start();
    for (std::uint32_t n = 0; n < plan_.samples; n += kChunk) {
      const std::uint32_t count = plan_.samples - n < kChunk ? plan_.samples - n : kChunk;
      draw_chunk(at, n, count);
      step_chunk(at, n, count);
    }
  }

  void write(EndPose* out, std::size_t count) const {
    const DF df;
    alignas(64) double x[kBlock], y[kBlock], theta[kBlock];
    for (std::size_t k = 0; k < kK; ++k) {
      hn::Store(p_[k].x, df, x + k * kN);
      hn::Store(p_[k].y, df, y + k * kN);
      hn::Store(p_[k].theta, df, theta + k * kN);
    }
    for (std::size_t j = 0; j < count && j < kBlock; ++j) out[j] = {x[j], y[j], theta[j]};
  }

  // The parts, public for the roofline harness (bench/simulator_roofline.cpp).

  /// The first sample's leg.
  LegCursor start() const {
    LegCursor at{plan_.legs.data(), plan_.legs.data() + plan_.legs.size()};
    while (at.leg != at.end && at.leg->count == 0) ++at.leg;
    return at;
  }

  /// The normals of samples n .. n+count-1 (count <= kChunk, n a multiple of kChunk): the wheels'
  /// and, in the general kernel, the draws of the legs from `at` on. Whole quads of samples (one
  /// Philox draw each); a quad past `count` is drawn and never read.
  void draw_chunk(LegCursor at, std::uint32_t n, std::uint32_t count) {
    const std::uint32_t quads = (count + 3) / 4;
    for (std::uint32_t q = 0; q < quads; ++q) {
      if constexpr (kWheelsTogether) {
        draw_normals<2>(n / 4 + q, {random::kTagWheelLeft, random::kTagWheelRight}, {0, 1}, 4 * q, 0, 4);
      } else {
        draw_normals<1>(n / 4 + q, {random::kTagWheelLeft}, {0}, 4 * q, 0, 4);
        draw_normals<1>(n / 4 + q, {random::kTagWheelRight}, {1}, 4 * q, 0, 4);
      }
    }
    if constexpr (kGeneral) {
      for (std::uint32_t s = 0; s < count;) {
        const Leg& leg = *at.leg;
        const std::uint32_t m = at.left(count - s);
        for (std::uint32_t d = leg.draws_begin; d < leg.draws_end; ++d) {
          // A quad the leg shares with its neighbour keeps the neighbour's samples' values.
          for (std::uint32_t q = s / 4; 4 * q < s + m; ++q) {
            const std::uint32_t from = s > 4 * q ? s - 4 * q : 0;
            const std::uint32_t to = s + m < 4 * q + 4 ? s + m - 4 * q : 4;
            draw_normals<1>(n / 4 + q, {plan_.draw_tags[d]}, {2 + d - leg.draws_begin}, 4 * q, from, to);
          }
        }
        at.skip(m);
        s += m;
      }
    }
  }

  /// The steps of samples n .. n+count-1 from their normals; `at` moves past them. The poses
  /// are locals here, so they stay in registers.
  void step_chunk(LegCursor& at, std::uint32_t n, std::uint32_t count) {
    Pose<VF> p[kK];
    for (std::size_t k = 0; k < kK; ++k) p[k] = p_[k];
    for (std::uint32_t s = 0; s < count;) {
      const Leg& leg = *at.leg;
      const std::uint32_t m = at.left(count - s);
      if constexpr (kPerLane) {
        if (at.leg != built_) build_lane_legs(at.leg);
        const PerLaneLeg legs{lane_legs_};
        for (std::uint32_t e = s + m; s < e; ++s) step_sample(p, leg, legs, n + s, s);
      } else {
        const SharedLeg legs{leg};
        for (std::uint32_t e = s + m; s < e; ++s) step_sample(p, leg, legs, n + s, s);
      }
      at.skip(m);
    }
    for (std::size_t k = 0; k < kK; ++k) p_[k] = p[k];
  }

  /// The Philox words at (quad, tag) for every lane of the block.
  HWY_INLINE void draw(std::uint32_t quad, std::uint32_t tag, Words (&w)[kK]) const {
    for (std::size_t k = 0; k < kK; ++k) {
      w[k] = {splat_u(quad), splat_u(tag), run_lo_[k], run_hi_[k]};
    }
    philox(w, keys_);
  }

  /// The normals of streams tag[0..T) at samples 4 quad .. 4 quad + 3 into slots slot[0..T) of
  /// chunk samples s .. s+3; only samples s+from .. s+to-1 are written. The T streams' Philox
  /// draws, and their normals, run interleaved.
  template <std::size_t T>
  HWY_INLINE void draw_normals(std::uint32_t quad, const std::uint32_t (&tag)[T], const std::size_t (&slot)[T],
                               std::uint32_t s, std::uint32_t from, std::uint32_t to) {
    Words w[T * kK];
    for (std::size_t t = 0; t < T; ++t) {
      for (std::size_t k = 0; k < kK; ++k) w[t * kK + k] = {splat_u(quad), splat_u(tag[t]), run_lo_[k], run_hi_[k]};
    }
    philox(w, keys_);
#if HWY_TARGET == HWY_SCALAR
    for (std::size_t t = 0; t < T; ++t) {
      std::uint32_t words[4 * kK];
      float z[4 * kK];
      for (std::size_t k = 0; k < kK; ++k) {
        const Words& v = w[t * kK + k];
        words[4 * k] = static_cast<std::uint32_t>(hn::GetLane(v.w0));
        words[4 * k + 1] = static_cast<std::uint32_t>(hn::GetLane(v.w1));
        words[4 * k + 2] = static_cast<std::uint32_t>(hn::GetLane(v.w2));
        words[4 * k + 3] = static_cast<std::uint32_t>(hn::GetLane(v.w3));
      }
      random::normals_from_words(words, z);
      for (std::size_t k = 0; k < kK; ++k) {
        for (std::uint32_t j = from; j < to; ++j) z_[slot[t]][k][s + j][0] = z[4 * k + j];
      }
    }
#else
    const DF32 d;
    VecOps::F z[2 * T * kK];
    quad_normals<T * kK>(w, z);
    for (std::size_t t = 0; t < T; ++t) {
      for (std::size_t k = 0; k < kK; ++k) {
        const VecOps::F z01 = z[2 * (t * kK + k)], z23 = z[2 * (t * kK + k) + 1];
        float* out = &z_[slot[t]][k][s][0];
        if (HWY_LIKELY(from == 0 && to == 4)) {
          hn::Store(z01, d, out);
          hn::Store(z23, d, out + 2 * kN);
        } else {  // a quad the leg shares with its neighbour: only the leg's samples
          alignas(64) float quad_z[4 * kN];
          hn::Store(z01, d, quad_z);
          hn::Store(z23, d, quad_z + 2 * kN);
          std::memcpy(out + from * kN, quad_z + from * kN, (to - from) * kN * sizeof(float));
        }
      }
    }
#endif
  }

  /// The normal in slot `slot` of chunk sample s for vector k.
  HWY_INLINE VF normal(std::size_t slot, std::size_t k, std::uint32_t s) const {
    return hn::PromoteTo(DF(), hn::Load(DH32(), &z_[slot][k][s][0]));
  }

  /// Sample n's step from the normals of chunk sample s; `leg` is the path's (its operations),
  /// `legs` its step constants (SharedLeg or PerLaneLeg).
  template <class L>
  HWY_INLINE void step_sample(Pose<VF> (&p)[kK], const Leg& leg, const L& legs, std::uint32_t n,
                              std::uint32_t s) {
    VF noise_l[kK], noise_r[kK];
    for (std::size_t k = 0; k < kK; ++k) {
      noise_l[k] = legs.sigma_left(k) * normal(0, k, s);
      noise_r[k] = legs.sigma_right(k) * normal(1, k, s);
    }
    if constexpr (kGeneral) effects(leg, legs, n, s, noise_l, noise_r);
    for (std::size_t k = 0; k < kK; ++k) step(p[k], legs, k, noise_l[k], noise_r[k]);
    if ((n & arc::kRenormMask) == arc::kRenormMask) renormalise(p);
  }

  /// The exact arc step on vector k; lanes outside the series bounds redo it in scalar code.
  template <class L>
  static HWY_INLINE void step(Pose<VF>& p, const L& leg, std::size_t k, VF noise_l, VF noise_r) {
    const auto c = [](double v) { return splat(v); };
    const VF eps = (noise_r - noise_l) * leg.inv_two_b(k);
    const VF ds = leg.center(k) + c(0.5) * (noise_l + noise_r);
    const VF e2 = eps * eps;
    const VF h = leg.half(k) + eps;
    // The reference's rule (arc::step): the short series where the leg takes them and eps and h
    // are within their bounds, else the long ones; a lane outside every series bound is special.
    const MF in_short = hn::And(hn::Le(hn::Abs(eps), c(arc::kEpsShortMax)),
                                hn::Le(hn::Abs(h), c(arc::kSincShortMax)));
    VF se, ce, ch, sh, sinc;
    MF special;
    if constexpr (L::kPerLane) {
      // Each lane its own leg's choice.
      const MF use_short = hn::And(leg.short_series(k), in_short);
      se = hn::IfThenElse(use_short, sin_short(eps, e2, c), sin_taylor(eps, e2, c));
      ce = hn::IfThenElse(use_short, cos_short(e2, c), cos_taylor(e2, c));
      ch = leg.cos_half(k) * ce - leg.sin_half(k) * se;
      sh = leg.sin_half(k) * ce + leg.cos_half(k) * se;
      const VF h2 = h * h;
      sinc = hn::IfThenElse(use_short, sinc_short(h2, c),
                            hn::IfThenElse(hn::Le(hn::Abs(h), c(arc::kSincSeriesMax)),
                                           sinc_series(h2, c), sh / h));
      special = hn::AndNot(use_short, hn::Gt(hn::Abs(eps), c(arc::kEpsTaylorMax)));
    } else if (leg.leg.short_series) {
      se = sin_short(eps, e2, c);
      ce = cos_short(e2, c);
      ch = leg.cos_half(k) * ce - leg.sin_half(k) * se;
      sh = leg.sin_half(k) * ce + leg.cos_half(k) * se;
      sinc = sinc_short(h * h, c);
      special = hn::Not(in_short);
    } else {
      se = sin_taylor(eps, e2, c);
      ce = cos_taylor(e2, c);
      ch = leg.cos_half(k) * ce - leg.sin_half(k) * se;
      sh = leg.sin_half(k) * ce + leg.cos_half(k) * se;
      special = hn::Gt(hn::Abs(eps), c(arc::kEpsTaylorMax));
      if (leg.leg.series_sinc) {
        sinc = sinc_series(h * h, c);
        special = hn::Or(special, hn::Gt(hn::Abs(h), c(arc::kSincSeriesMax)));
      } else {
        sinc = sh / h;
        special = hn::Or(special, hn::Le(hn::Abs(h), c(arc::kSincSeriesMax)));
      }
    }
    if (HWY_LIKELY(hn::AllFalse(DF(), special))) {
      // A lane without slip in a vector with some takes advance_lateral with lat = 0, whose side
      // terms are then +-0 and leave its pose's bits as advance does.
      if (leg.any_lateral()) {  // this target's copies
        lanes::HWY_NAMESPACE::advance_lateral(p, ds, leg.lateral(k), ch, sh, sinc, h);
      } else {
        lanes::HWY_NAMESPACE::advance(p, ds, ch, sh, sinc, h);
      }
      return;
    }
    scalar_lanes(p, leg, k, noise_l, noise_r);
  }

 private:
  /// Rare: some lane is outside the series bounds; the vector takes the scalar step
  /// lane by lane from the pre-step state (within the bounds it is the vector formula).
  template <class L>
  static HWY_NOINLINE void scalar_lanes(Pose<VF>& p, const L& leg, std::size_t k, VF noise_l,
                                        VF noise_r) {
    const DF df;
    alignas(64) double v[7][kN];
    hn::Store(p.x, df, v[0]);
    hn::Store(p.y, df, v[1]);
    hn::Store(p.c, df, v[2]);
    hn::Store(p.s, df, v[3]);
    hn::Store(p.theta, df, v[4]);
    hn::Store(noise_l, df, v[5]);
    hn::Store(noise_r, df, v[6]);
    for (std::size_t j = 0; j < kN; ++j) {
      arc::Pose<double> q{v[0][j], v[1][j], v[2][j], v[3][j], v[4][j]};
      arc::step(q, leg.of(k, j), v[5][j], v[6][j]);
      v[0][j] = q.x, v[1][j] = q.y, v[2][j] = q.c, v[3][j] = q.s, v[4][j] = q.theta;
    }
    p = {hn::Load(df, v[0]), hn::Load(df, v[1]), hn::Load(df, v[2]), hn::Load(df, v[3]),
         hn::Load(df, v[4])};
  }

  static void renormalise(Pose<VF> (&p)[kK]) {
    for (std::size_t k = 0; k < kK; ++k) {
      const VF norm = hn::Sqrt(p[k].c * p[k].c + p[k].s * p[k].s);
      p[k].c = p[k].c / norm;
      p[k].s = p[k].s / norm;
    }
  }

  // ---- The general kernel's effects ----------------------------------------------------------

  /// Per-run values of every stochastic effect, lane by lane (begin_run is scalar code).
  void begin_runs() {
    for (std::size_t e = 0; e < plan_.stochastic.size(); ++e) {
      for (std::size_t j = 0; j < kBlock; ++j) {
        effects::RunState state;
        plan_.stochastic[e]->begin_run(state, effects::Draws(key_, first_ + j, plan_.slots[e]));
        for (int v = 0; v < 4; ++v) values_[e][v][j] = state.value[v];
      }
    }
  }

  /// Each lane's leg of the path leg at `path_leg` for its run's draws (run_leg, scalar: once
  /// per leg and block) into the table the steps load.
  HWY_NOINLINE void build_lane_legs(const Leg* path_leg) {
    const std::size_t i = static_cast<std::size_t>(path_leg - plan_.legs.data());
    effects::RunState states[kMaxEffects];
    bool any_lateral = false;
    for (std::size_t j = 0; j < kBlock; ++j) {
      for (const std::uint8_t e : plan_.per_run_terms) {
        for (int v = 0; v < 4; ++v) states[e].value[v] = values_[e][v][j];
      }
      const Leg leg = run_leg(plan_, i, states);
      lane_legs_.set(j, leg);
      any_lateral = any_lateral || leg.lateral_m != 0.0;
    }
    lane_legs_.any_lateral = any_lateral;
    built_ = path_leg;
  }

  /// The noise mixes, then each effect's operations in order; noise = sigma z + extra.
  template <class L>
  HWY_INLINE void effects(const Leg& leg, const L& legs, std::uint32_t n, std::uint32_t s,
                          VF (&noise_l)[kK], VF (&noise_r)[kK]) {
    const DF df;
    VF zl[kK], zr[kK], extra_l[kK], extra_r[kK];
    for (std::size_t k = 0; k < kK; ++k) {
      zl[k] = normal(0, k, s);
      zr[k] = normal(1, k, s);
      extra_l[k] = extra_r[k] = splat(0.0);
    }
    for (const NoiseMix& m : plan_.mixes) {
      for (std::size_t k = 0; k < kK; ++k) {
        zr[k] = splat(m.from_left) * zl[k] + splat(m.from_right) * zr[k];
      }
    }
    for (std::uint32_t o = leg.ops_begin; o < leg.ops_end; ++o) {
      const LaneOp& op = plan_.ops[o];
      if (op.kind == LaneOp::kEvent) {
        events(leg, n, op.effect, extra_l, extra_r);
        continue;
      }
      VF(&extra)[kK] = op.wheel == 0 ? extra_l : extra_r;
      for (std::size_t k = 0; k < kK; ++k) {
        const VF value = op.per_run ? hn::Load(df, &values_[op.effect][op.index][k * kN])
                                    : normal(2 + op.index, k, s);
        extra[k] = extra[k] + (value * splat(op.a)) * splat(op.b);
      }
    }
    for (std::size_t k = 0; k < kK; ++k) {
      noise_l[k] = legs.sigma_left(k) * zl[k] + extra_l[k];
      noise_r[k] = legs.sigma_right(k) * zr[k] + extra_r[k];
    }
  }

  /// An event effect's countdown: minus the sample's travel; lanes at or below zero handle their
  /// events in scalar code (rare).
  HWY_INLINE void events(const Leg& leg, std::uint32_t n, std::size_t e, VF (&extra_l)[kK],
                         VF (&extra_r)[kK]) {
    const DF df;
    bool any = false;
    for (std::size_t k = 0; k < kK; ++k) {
      double* to_next = &values_[e][0][k * kN];
      const VF left = hn::Load(df, to_next) - splat(leg.event_travel);
      hn::Store(left, df, to_next);
      any = any || !hn::AllFalse(df, hn::Le(left, splat(0.0)));
    }
    if (HWY_UNLIKELY(any)) scalar_events(n, e, extra_l, extra_r);
  }

  HWY_NOINLINE void scalar_events(std::uint32_t n, std::size_t e, VF (&extra_l)[kK],
                                  VF (&extra_r)[kK]) {
    const DF df;
    alignas(64) double el[kBlock], er[kBlock];
    for (std::size_t k = 0; k < kK; ++k) {
      hn::Store(extra_l[k], df, el + k * kN);
      hn::Store(extra_r[k], df, er + k * kN);
    }
    for (std::size_t j = 0; j < kBlock; ++j) {
      if (!(values_[e][0][j] <= 0.0)) continue;
      effects::RunState state;
      for (int v = 0; v < 4; ++v) state.value[v] = values_[e][v][j];
      plan_.stochastic[e]->event(n, state, effects::Draws(key_, first_ + j, plan_.slots[e]),
                                 el[j], er[j]);
      for (int v = 0; v < 4; ++v) values_[e][v][j] = state.value[v];
    }
    for (std::size_t k = 0; k < kK; ++k) {
      extra_l[k] = hn::Load(df, el + k * kN);
      extra_r[k] = hn::Load(df, er + k * kN);
    }
  }

  /// Normals per chunk sample: the two wheels', and in the general kernel the leg's draws.
  static constexpr std::size_t kSlots = kGeneral ? 2 + kMaxDraws : 2;

  const Plan& plan_;
  const random::Philox::key_type key_;
  const RoundKeys keys_;
  const std::uint64_t first_;
  VU run_[kK], run_lo_[kK], run_hi_[kK];
  Pose<VF> p_[kK];
  // Normals of the chunk in single precision, [slot][vector][sample][lane]: a quad's two vectors
  // of floats are contiguous, and a sample's kN lanes are what the step promotes to doubles.
  alignas(64) float z_[kSlots][kK][kChunk][kN];
  // The general kernel's per-run values, structure of arrays: [effect][value][lane].
  alignas(64) double values_[kGeneral ? kMaxEffects : 1][4][kBlock];
  // Per-lane legs: the table of the leg built last (a member array only where it is used).
  struct NoLegs {};
  using LegTable = std::conditional_t<kPerLane, LaneLegs, NoLegs>;
  LegTable lane_legs_;
  const Leg* built_ = nullptr;
};

/// The normals of `count` words as the kernel computes them (lane_plan.hpp's NormalsFn): groups
/// of 2 kK vectors of floats, as draw_normals converts a quad of samples.
inline void normals_of_words(const std::uint32_t* words, std::size_t count, float* out) {
#if HWY_TARGET == HWY_SCALAR
  constexpr std::size_t kGroup = 16;
  for (std::size_t i = 0; i < count; i += kGroup) {
    const std::size_t n = count - i < kGroup ? count - i : kGroup;
    std::uint32_t in[kGroup];
    float z[kGroup];
    for (std::size_t j = 0; j < kGroup; ++j) in[j] = words[i + (j < n ? j : 0)];
    random::normals_from_words(in, z);
    std::memcpy(out + i, z, n * sizeof(float));
  }
#else
  const DF32 d;
  const DI32 di;
  constexpr std::size_t kL = hn::MaxLanes(DF32()), kGroup = 2 * kK * kL;
  alignas(64) std::int32_t in[kGroup];
  alignas(64) float z_out[kGroup];
  for (std::size_t i = 0; i < count; i += kGroup) {
    const std::size_t n = count - i < kGroup ? count - i : kGroup;
    for (std::size_t j = 0; j < kGroup; ++j) in[j] = static_cast<std::int32_t>(words[i + (j < n ? j : 0)]);
    VecOps::I w[2 * kK];
    VecOps::F z[2 * kK];
    for (std::size_t v = 0; v < 2 * kK; ++v) w[v] = hn::Load(di, in + v * kL);
    normal_icdf<VecOps, 2 * kK>(w, z);
    for (std::size_t v = 0; v < 2 * kK; ++v) hn::Store(z[v], d, z_out + v * kL);
    std::memcpy(out + i, z_out, n * sizeof(float));
  }
#endif
}

/// The kernel entry point (lane_plan.hpp's KernelFn): blocks of kBlock runs; the last block's
/// lanes past `count` are simulated and dropped.
inline void run_blocks(const Plan& plan, const random::Philox::key_type& key, std::uint64_t first,
                       std::size_t count, EndPose* out) {
  for (std::size_t done = 0; done < count; done += kBlock) {
    const std::size_t valid = count - done < kBlock ? count - done : kBlock;
    if (plan.per_run_legs()) {
      Block<true, true> block(plan, key, first + done);
      block.run();
      block.write(out + done, valid);
    } else if (plan.general()) {
      Block<true> block(plan, key, first + done);
      block.run();
      block.write(out + done, valid);
    } else {
      Block<false> block(plan, key, first + done);
      block.run();
      block.write(out + done, valid);
    }
  }
}

}  // namespace odomcov::lanes::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#endif  // include guard toggle
