// The simulator's SIMD kernel, compiled once per instruction set by Highway (foreach_target in
// lane_kernels.cpp; the roofline harness in bench/ includes it too). A block of runs advances in
// lock step, run j of the block in lane j, structure of arrays: K vectors of N doubles each.
//
// Per sample and lane it does exactly what the scalar reference (simulator.cpp) does per run:
//   * Philox4x32-10 at counter (sample, tag, run lo, run hi), with the four 32-bit words held in
//     64-bit lanes (the 32x32 -> 64 multiply is MulEven; the upper half of a word may hold garbage
//     between rounds because MulEven reads only the lower half, so no masking per round);
//   * ZIGNOR ziggurat normals: the fast path in vectors (two gathers), the ~1.2% rejected lanes by
//     the scalar method (random::zig_slow, the reference's own code);
//   * the stochastic effects' operations of the leg (plan.ops), events per lane in scalar code;
//   * the exact arc step of arc_step.hpp; lanes outside its series bounds take the scalar step.
// Only IEEE-exact operations (+ - * / sqrt, comparisons, bit operations) are used, never MulAdd,
// so every target gives the scalar reference's bits.

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

#include "engine/lane_plan.hpp"

HWY_BEFORE_NAMESPACE();
namespace odomcov::lanes::HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using DF = hn::ScalableTag<double>;
using DU = hn::RebindToUnsigned<DF>;
using DI = hn::RebindToSigned<DF>;
using DU32 = hn::Repartition<std::uint32_t, DF>;
using VF = hn::Vec<DF>;
using VU = hn::Vec<DU>;
using MF = hn::Mask<DF>;

/// Doubles per vector, and vectors per block (runs in lock step = kN kK).
inline constexpr std::size_t kN = hn::MaxLanes(DF());
inline constexpr std::size_t kK = kN >= 8 ? 4 : kN >= 4 ? 2 : 4;
inline constexpr std::size_t kBlock = kN * kK;
static_assert(kBlock <= kMaxRuns, "a block must fit the kernel's output");
static_assert(kN <= 8 && kK <= 8, "a vector's mask must fit a byte, a row's a word");

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

/// Philox on kK vectors of counters at once (independent chains interleaved).
HWY_INLINE void philox(Words (&w)[kK], const RoundKeys& keys) {
  for (int r = 0; r < 10; ++r) {
    const VU k0 = splat_u(keys.k0[r]), k1 = splat_u(keys.k1[r]);
    for (std::size_t k = 0; k < kK; ++k) {
      const VU p0 = mul_wide(w[k].w0, 0xD2511F53u);
      const VU p1 = mul_wide(w[k].w2, 0xCD9E8D57u);
      w[k].w0 = hn::Xor3(hn::ShiftRight<32>(p1), w[k].w1, k0);
      w[k].w2 = hn::Xor3(hn::ShiftRight<32>(p0), w[k].w3, k1);
      w[k].w1 = p1;
      w[k].w3 = p0;
    }
  }
}

/// The 64-bit candidate of words (lo, hi): lo | hi << 32.
HWY_INLINE VU candidate(VU lo, VU hi) {
  return hn::OrAnd(hn::ShiftLeft<32>(hi), lo, splat_u(0xFFFFFFFFu));
}

// ---------------------------------------------------------------------------------------------
// Normals
// ---------------------------------------------------------------------------------------------

/// The ziggurat's fast path on N candidates (random::zig_fast in lanes); `accepted` marks the
/// lanes it decided.
HWY_INLINE VF zig_fast(VU bits, MF& accepted) {
  const DF df;
  const DI di;
  const random::ZigguratTables& zig = random::kZiggurat;
  const auto index = hn::BitCast(di, hn::And(bits, splat_u(0xFF)));
  const VF u = hn::BitCast(df, hn::Or(hn::ShiftRight<12>(bits), splat_u(0x3FF0000000000000ull))) -
               splat(1.0);
  const VF width = hn::GatherIndex(df, zig.x, index);
  const VF ratio = hn::GatherIndex(df, zig.ratio, index);
  accepted = hn::Lt(u, ratio);
  // sign u width: the sign bit of the candidate's bit 8 on the (non-negative) product.
  const VU sign = hn::ShiftLeft<55>(hn::And(bits, splat_u(0x100)));
  return hn::BitCast(df, hn::Xor(hn::BitCast(DU(), u * width), sign));
}

HWY_INLINE VF uniform52(VU bits) {
  return hn::BitCast(DF(), hn::Or(hn::ShiftRight<12>(bits), splat_u(0x3FF0000000000000ull))) -
         splat(1.0);
}

// This target's copy of the wedge test's exp (base/wedge_exp-inl.hpp).
#include "base/wedge_exp-inl.hpp"

/// Candidates the fast path rejected, waiting for the slow path: each one's bits and where its
/// normal goes (an index into the block's chunk of normals, which also says its sample, slot and
/// lane) with the attempts made so far in bits 32..39.
struct Rejects {
  static constexpr std::size_t kCapacity = 512;
  std::size_t count = 0;
  alignas(64) std::uint64_t bits[kCapacity + kBlock], at[kCapacity + kBlock];
};

/// Stores the lanes of `m` contiguously at `out` (a whole vector is written).
HWY_INLINE void compress_store(VU v, hn::Mask<DU> m, std::uint64_t* out) {
#if HWY_TARGET == HWY_AVX3 || HWY_TARGET == HWY_AVX3_DL
  // vpcompressq in registers (Highway 1.0.3 copies a 2 KB table per call; the memory form of
  // vpcompressq is microcoded on Zen 4).
  hn::StoreU(VU{_mm512_maskz_compress_epi64(m.raw, v.raw)}, DU(), out);
#else
  hn::StoreU(hn::Compress(v, m), DU(), out);
#endif
}

/// One attempt of the full ziggurat (random::zig_slow's loop body) on kBlock candidates at once
/// (kK vectors, interleaved), each with its own counter: the fast test, then (unless every lane
/// passed it) a fresh draw at the attempt's retry tag and the wedge test. state: 1 accepted (z
/// holds the normal), 2 a tail candidate (the scalar method takes it over at this attempt), 0
/// rejected again (bits holds the next candidate). `tag` carries the attempt k in bits 24..31.
HWY_NOINLINE void zig_attempt(std::size_t vectors, const std::uint64_t* bits_in,
                              const std::uint64_t* run, const std::uint64_t* sample,
                              const std::uint64_t* tag, const RoundKeys& keys, double* z_out,
                              std::uint64_t* bits_out, double* state) {
  const DF df;
  const DU du;
  const DI di;
  const random::ZigguratTables& zig = random::kZiggurat;
  const auto c = [](double v) { return splat(v); };
  VU bits[kK], sign[kK];
  VF u[kK], xi[kK];
  MF fast[kK];
  bool all_fast = true;
  for (std::size_t k = 0; k < vectors; ++k) {
    bits[k] = hn::Load(du, bits_in + k * kN);
    const auto index = hn::BitCast(di, hn::And(bits[k], splat_u(0xFF)));
    u[k] = uniform52(bits[k]);
    sign[k] = hn::ShiftLeft<55>(hn::And(bits[k], splat_u(0x100)));
    xi[k] = hn::GatherIndex(df, zig.x, index);
    fast[k] = hn::Lt(u[k], hn::GatherIndex(df, zig.ratio, index));
    all_fast = all_fast && hn::AllTrue(df, fast[k]);
  }
  if (all_fast) {  // new candidates mostly pass: no draw, no wedge
    for (std::size_t k = 0; k < vectors; ++k) {
      hn::Store(hn::BitCast(df, hn::Xor(hn::BitCast(du, u[k] * xi[k]), sign[k])), df, z_out + k * kN);
      hn::Store(c(1.0), df, state + k * kN);
    }
    return;
  }
  Words w[kK];
  for (std::size_t k = 0; k < kK; ++k) w[k] = {splat_u(0), splat_u(0), splat_u(0), splat_u(0)};
  for (std::size_t k = 0; k < vectors; ++k) {
    const VU runs = hn::Load(du, run + k * kN);
    w[k] = {hn::Load(du, sample + k * kN), hn::Load(du, tag + k * kN),
            hn::And(runs, splat_u(0xFFFFFFFFu)), hn::ShiftRight<32>(runs)};
  }
  philox(w, keys);
  for (std::size_t k = 0; k < vectors; ++k) {
    const auto index = hn::BitCast(di, hn::And(bits[k], splat_u(0xFF)));
    const auto tail = hn::AndNot(fast[k], hn::RebindMask(df, hn::Eq(index, hn::Zero(di))));
    // The wedge: accept when f0 + U (f1 - f0) < 1 (see random.cpp).
    const VF x = u[k] * xi[k];
    const VF xn = hn::GatherIndex(df, zig.x + 1, index);
    const VF f0 = wedge_exp(c(-0.5) * (xi[k] * xi[k] - x * x), c);
    const VF f1 = wedge_exp(c(-0.5) * (xn * xn - x * x), c);
    const VF u2 = uniform52(candidate(w[k].w2, w[k].w3));
    const auto wedge = hn::AndNot(hn::Or(fast[k], tail), hn::Lt(f0 + u2 * (f1 - f0), c(1.0)));
    const VF magnitude = hn::IfThenElse(fast[k], x, hn::IfThenElseZero(wedge, x));
    hn::Store(hn::BitCast(df, hn::Xor(hn::BitCast(du, magnitude), sign[k])), df, z_out + k * kN);
    hn::Store(candidate(w[k].w0, w[k].w1), du, bits_out + k * kN);
    hn::Store(hn::IfThenElse(hn::Or(fast[k], wedge), c(1.0), hn::IfThenElseZero(tail, c(2.0))),
              df, state + k * kN);
  }
}

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

template <bool kGeneral>
class Block {
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

  /// The normals of samples n .. n+count-1 (count <= kChunk), from the leg at `at` on: the fast
  /// path for every lane, then the slow path for the lanes it rejected.
  void draw_chunk(LegCursor at, std::uint32_t n, std::uint32_t count) {
    n0_ = n;
    for (std::uint32_t s = 0; s < count;) {
      const Leg& leg = *at.leg;
      const std::uint32_t m = at.left(count - s);
      for (std::uint32_t e = s + m; s < e; ++s) draw_sample(leg, n + s, s);
      at.skip(m);
    }
    queue_rejected();
    drain();
  }

  /// The steps of samples n .. n+count-1 from their normals; `at` moves past them. The poses
  /// are locals here, so they stay in registers.
  void step_chunk(LegCursor& at, std::uint32_t n, std::uint32_t count) {
    Pose<VF> p[kK];
    for (std::size_t k = 0; k < kK; ++k) p[k] = p_[k];
    for (std::uint32_t s = 0; s < count;) {
      const Leg& leg = *at.leg;
      const std::uint32_t m = at.left(count - s);
      for (std::uint32_t e = s + m; s < e; ++s) step_sample(p, leg, n + s, s);
      at.skip(m);
    }
    for (std::size_t k = 0; k < kK; ++k) p_[k] = p[k];
  }

  /// The Philox words at (n, tag) for every lane of the block.
  HWY_INLINE void draw(std::uint32_t n, std::uint32_t tag, Words (&w)[kK]) const {
    for (std::size_t k = 0; k < kK; ++k) {
      w[k] = {splat_u(n), splat_u(tag), run_lo_[k], run_hi_[k]};
    }
    philox(w, keys_);
  }

  /// The fast path of the normal from `bits` into slot `slot` of chunk sample s; the candidate
  /// and the lanes it rejected are kept for the slow path (fixed addresses, no branch).
  HWY_INLINE void normal(VU bits, std::size_t k, std::uint32_t s, std::size_t slot) {
    MF accepted;
    hn::Store(zig_fast(bits, accepted), DF(), &z_[s][slot][k * kN]);
    hn::Store(bits, DU(), &bits_[s][slot][k * kN]);
    hn::StoreMaskBits(DF(), hn::Not(accepted), &rejected_[s][slot][k]);
  }

  /// Marks slot `slot` of chunk sample s when the fast path rejected any of its lanes.
  HWY_INLINE void flag(std::uint32_t s, std::size_t slot) {
    std::uint64_t any = 0;
    std::memcpy(&any, &rejected_[s][slot][0], kK);
    const std::size_t bit = s * kSlots + slot;
    flags_[bit / 64] |= std::uint64_t{any != 0} << (bit % 64);
  }

  /// Queues the rejected lanes of the flagged slots for the slow path.
  HWY_NOINLINE void queue_rejected() {
    // The count in a local: stores through the queue's arrays could alias a member.
    std::size_t count = queue_->count;
    for (std::size_t w = 0; w < kFlagWords; ++w) {
      for (std::uint64_t f = flags_[w]; f != 0; f &= f - 1) {
        const std::size_t bit = w * 64 + hwy::Num0BitsBelowLS1Bit_Nonzero64(f);
        const std::size_t s = bit / kSlots, slot = bit % kSlots;
        Rejects& q = *queue_;
        const std::uint64_t first = static_cast<std::uint64_t>(&z_[s][slot][0] - &z_[0][0][0]);
        // Lane by lane (they are few: cheaper than compressing whole vectors), one loop over the
        // row's kK mask bytes read as one word: bit 8 k + i is lane k kN + i.
        std::uint64_t row = 0;
        std::memcpy(&row, &rejected_[s][slot][0], kK);
        for (; row != 0; row &= row - 1) {
          const std::size_t pos = hwy::Num0BitsBelowLS1Bit_Nonzero64(row);
          const std::size_t j = (pos / 8) * kN + pos % 8;
          q.bits[count] = bits_[s][slot][j];
          q.at[count] = first + j;
          ++count;
        }
        if (HWY_UNLIKELY(count + kBlock > Rejects::kCapacity)) {
          queue_->count = count;
          drain();
          count = queue_->count;
        }
      }
      flags_[w] = 0;
    }
    queue_->count = count;
  }

  /// Sample n's normals into chunk sample s: the wheels' and the leg's effect draws.
  HWY_INLINE void draw_sample(const Leg& leg, std::uint32_t n, std::uint32_t s) {
    Words w[kK];
    draw(n, random::kTagWheelNoise, w);
    for (std::size_t k = 0; k < kK; ++k) {
      normal(candidate(w[k].w0, w[k].w1), k, s, 0);
      normal(candidate(w[k].w2, w[k].w3), k, s, 1);
    }
    flag(s, 0);
    flag(s, 1);
    if constexpr (kGeneral) {
      tags_[s] = plan_.draw_tags.data() + leg.draws_begin;
      for (std::uint32_t d = leg.draws_begin; d < leg.draws_end; ++d) {
        const std::size_t slot = 2 + d - leg.draws_begin;
        draw(n, plan_.draw_tags[d], w);
        for (std::size_t k = 0; k < kK; ++k) normal(candidate(w[k].w0, w[k].w1), k, s, slot);
        flag(s, slot);
      }
    }
  }

  /// The slow path of every queued candidate: attempt by attempt, N candidates per vector, the
  /// rejected ones queued again for their next attempt.
  HWY_NOINLINE void drain() {
    while (queue_->count > 0) {
      Rejects& in = *queue_;
      Rejects& out = queue_ == &rejects_[0] ? rejects_[1] : rejects_[0];
      out.count = 0;
      for (std::size_t i = 0; i < in.count; i += kBlock) attempt(in, i, out);
      in.count = 0;
      queue_ = &out;
    }
  }

  /// One attempt on queued candidates i .. i+kBlock-1 (branch-free but for the rare tail).
  HWY_INLINE void attempt(Rejects& in, std::size_t i, Rejects& out) {
    const std::size_t c = in.count - i < kBlock ? in.count - i : kBlock;
    const std::size_t vectors = (c + kN - 1) / kN, lanes = vectors * kN;
    for (std::size_t j = c; j < lanes; ++j) in.bits[i + j] = in.bits[i], in.at[i + j] = in.at[i];
    alignas(64) std::uint64_t run[kBlock], sample[kBlock], tag[kBlock], next[kBlock];
    alignas(64) double z[kBlock], state[kBlock];
    for (std::size_t j = 0; j < lanes; ++j) {
      const std::uint64_t at = in.at[i + j];
      const std::uint64_t index = at & 0xFFFFFFFFu, q = index / kBlock;
      const std::size_t slot = q % kSlots, s = q / kSlots;
      run[j] = first_ + index % kBlock;
      sample[j] = n0_ + s;
      tag[j] = retry_base(s, slot) | ((at >> 32) + 1) << random::kRetryShift;
    }
    zig_attempt(vectors, in.bits + i, run, sample, tag, keys_, z, next, state);
    double* zs = &z_[0][0][0];
    std::size_t count = out.count;  // a local: the stores below could alias the member
    for (std::size_t j = 0; j < c; ++j) {
      const std::uint64_t at = in.at[i + j] + (std::uint64_t{1} << 32);  // one more attempt
      zs[at & 0xFFFFFFFFu] = z[j];  // meaningful when accepted, rewritten otherwise
      out.bits[count] = next[j];
      out.at[count] = at;
      const bool retry = state[j] == 0.0 && (at >> 32) < random::kMaxRetries;
      count += retry ? 1 : 0;
      if (HWY_UNLIKELY(state[j] == 2.0 || (state[j] == 0.0 && !retry))) {
        // The tail (and an exhausted budget, which throws) by the scalar method.
        const std::uint32_t k = static_cast<std::uint32_t>(tag[j] >> random::kRetryShift);
        zs[at & 0xFFFFFFFFu] = random::zig_slow(
            in.bits[i + j], key_, run[j], static_cast<std::uint32_t>(sample[j]),
            static_cast<std::uint32_t>(tag[j]) & ((1u << random::kRetryShift) - 1), k);
      }
    }
    out.count = count;
  }

  /// The retry tag of slot `slot` of chunk sample s's normals.
  std::uint32_t retry_base(std::size_t s, std::size_t slot) const {
    if constexpr (kGeneral) {
      if (slot >= 2) return tags_[s][slot - 2];
    }
    (void)s;
    return random::kTagWheelRetry + static_cast<std::uint32_t>(slot);
  }

  /// Sample n's step from the normals of chunk sample s.
  HWY_INLINE void step_sample(Pose<VF> (&p)[kK], const Leg& leg, std::uint32_t n,
                              std::uint32_t s) {
    const DF df;
    VF noise_l[kK], noise_r[kK];
    for (std::size_t k = 0; k < kK; ++k) {
      noise_l[k] = splat(leg.sigma_left) * hn::Load(df, &z_[s][0][k * kN]);
      noise_r[k] = splat(leg.sigma_right) * hn::Load(df, &z_[s][1][k * kN]);
    }
    if constexpr (kGeneral) effects(leg, n, s, noise_l, noise_r);
    for (std::size_t k = 0; k < kK; ++k) step(p[k], leg, noise_l[k], noise_r[k]);
    if ((n & arc::kRenormMask) == arc::kRenormMask) renormalise(p);
  }

  /// The exact arc step on one vector; lanes outside the series bounds redo it in scalar code.
  static HWY_INLINE void step(Pose<VF>& p, const Leg& leg, VF noise_l, VF noise_r) {
    const auto c = [](double v) { return splat(v); };
    const VF eps = (noise_r - noise_l) * c(leg.inv_two_b);
    const VF ds = c(leg.center_m) + c(0.5) * (noise_l + noise_r);
    const VF e2 = eps * eps;
    const VF se = sin_taylor(eps, e2, c);
    const VF ce = cos_taylor(e2, c);
    const VF ch = c(leg.cos_half) * ce - c(leg.sin_half) * se;
    const VF sh = c(leg.sin_half) * ce + c(leg.cos_half) * se;
    const VF h = c(leg.half_rad) + eps;
    MF special = hn::Gt(hn::Abs(eps), c(arc::kEpsTaylorMax));
    VF sinc;
    if (leg.series_sinc) {
      sinc = sinc_series(h * h, c);
      special = hn::Or(special, hn::Gt(hn::Abs(h), c(arc::kSincSeriesMax)));
    } else {
      sinc = sh / h;
      special = hn::Or(special, hn::Le(hn::Abs(h), c(arc::kSincSeriesMax)));
    }
    if (HWY_LIKELY(hn::AllFalse(DF(), special))) {
      if (leg.lateral_m != 0.0) {  // this target's copies
        lanes::HWY_NAMESPACE::advance_lateral(p, ds, c(leg.lateral_m), ch, sh, sinc, h);
      } else {
        lanes::HWY_NAMESPACE::advance(p, ds, ch, sh, sinc, h);
      }
      return;
    }
    scalar_lanes(p, leg, noise_l, noise_r);
  }

 private:
  /// Rare: some lane is outside the series bounds; the vector takes the scalar step
  /// lane by lane from the pre-step state (within the bounds it is the vector formula).
  static HWY_NOINLINE void scalar_lanes(Pose<VF>& p, const Leg& leg, VF noise_l,
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
      arc::step(q, leg, v[5][j], v[6][j]);
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

  /// The noise mixes, then each effect's operations in order; noise = sigma z + extra.
  HWY_INLINE void effects(const Leg& leg, std::uint32_t n, std::uint32_t s, VF (&noise_l)[kK],
                          VF (&noise_r)[kK]) {
    const DF df;
    VF zl[kK], zr[kK], extra_l[kK], extra_r[kK];
    for (std::size_t k = 0; k < kK; ++k) {
      zl[k] = hn::Load(df, &z_[s][0][k * kN]);
      zr[k] = hn::Load(df, &z_[s][1][k * kN]);
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
      const double* values = op.per_run ? &values_[op.effect][op.index][0] : &z_[s][2 + op.index][0];
      for (std::size_t k = 0; k < kK; ++k) {
        extra[k] = extra[k] + (hn::Load(df, values + k * kN) * splat(op.a)) * splat(op.b);
      }
    }
    for (std::size_t k = 0; k < kK; ++k) {
      noise_l[k] = splat(leg.sigma_left) * zl[k] + extra_l[k];
      noise_r[k] = splat(leg.sigma_right) * zr[k] + extra_r[k];
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
  Rejects rejects_[2];  // the slow path's queue and the next attempts', in turns
  Rejects* queue_ = &rejects_[0];
  std::uint32_t n0_ = 0;  // the chunk's first sample
  alignas(64) double z_[kChunk][kSlots][kBlock];  // normals of the chunk
  alignas(64) std::uint64_t bits_[kChunk][kSlots][kBlock];  // their candidates
  std::uint8_t rejected_[kChunk][kSlots][kK];  // lanes the fast path rejected, a bit each
  static constexpr std::size_t kFlagWords = (kChunk * kSlots + 63) / 64;
  std::uint64_t flags_[kFlagWords] = {};  // (sample, slot) pairs with rejected lanes
  const std::uint32_t* tags_[kChunk] = {};                    // general: their legs' draw tags
  // The general kernel's per-run values, structure of arrays: [effect][value][lane].
  alignas(64) double values_[kGeneral ? kMaxEffects : 1][4][kBlock];
};

/// The kernel entry point (lane_plan.hpp's KernelFn): blocks of kBlock runs; the last block's
/// lanes past `count` are simulated and dropped.
inline void run_blocks(const Plan& plan, const random::Philox::key_type& key, std::uint64_t first,
                       std::size_t count, EndPose* out) {
  for (std::size_t done = 0; done < count; done += kBlock) {
    const std::size_t valid = count - done < kBlock ? count - done : kBlock;
    if (plan.general()) {
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
