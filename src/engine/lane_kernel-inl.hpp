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
inline constexpr std::size_t kK = kN >= 4 ? 2 : 4;
inline constexpr std::size_t kBlock = kN * kK;
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

/// The lanes the fast path rejected, by the scalar method (same streams as the reference).
HWY_NOINLINE VF zig_rejected(VF z, MF accepted, VU bits, const random::Philox::key_type& key,
                             std::uint64_t first_run, std::uint32_t sample,
                             std::uint32_t retry_base) {
  const DF df;
  alignas(64) double zs[kN];
  alignas(64) std::uint64_t bs[kN];
  alignas(64) double ok[kN];
  hn::Store(z, df, zs);
  hn::Store(bits, DU(), bs);
  hn::Store(hn::IfThenElseZero(accepted, splat(1.0)), df, ok);
  for (std::size_t j = 0; j < kN; ++j) {
    if (ok[j] == 0.0) zs[j] = random::zig_slow(bs[j], key, first_run + j, sample, retry_base);
  }
  return hn::Load(df, zs);
}

// ---------------------------------------------------------------------------------------------
// The block
// ---------------------------------------------------------------------------------------------

template <bool kGeneral>
class Block {
 public:
  Block(const Plan& plan, const random::Philox::key_type& key, std::uint64_t first)
      : plan_(plan), key_(key), keys_(key), first_(first) {
    const DU du;
    for (std::size_t k = 0; k < kK; ++k) {
      const VU run = hn::Iota(du, first + k * kN);
      run_lo_[k] = hn::And(run, splat_u(0xFFFFFFFFu));
      run_hi_[k] = hn::ShiftRight<32>(run);
      p_[k] = {splat(0.0), splat(0.0), splat(1.0), splat(0.0), splat(0.0)};
    }
    if constexpr (kGeneral) begin_runs();
  }

  void run() {
    std::uint32_t n = 0;
    for (const Leg& leg : plan_.legs) {
      for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
        sample(leg, n);
        if ((n & arc::kRenormMask) == arc::kRenormMask) renormalise();
      }
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

 private:
  /// Normals at `tag` for every lane of the block (candidate = words 0, 1 of the draw), or for
  /// the wheels: both candidates of the draw at kTagWheelNoise.
  HWY_INLINE void draw(std::uint32_t n, std::uint32_t tag, Words (&w)[kK]) const {
    for (std::size_t k = 0; k < kK; ++k) {
      w[k] = {splat_u(n), splat_u(tag), run_lo_[k], run_hi_[k]};
    }
    philox(w, keys_);
  }

  HWY_INLINE VF normal(VU bits, std::size_t k, std::uint32_t n, std::uint32_t retry_base) const {
    MF accepted;
    const VF z = zig_fast(bits, accepted);
    if (HWY_LIKELY(hn::AllTrue(DF(), accepted))) return z;
    return zig_rejected(z, accepted, bits, key_, first_ + k * kN, n, retry_base);
  }

  HWY_INLINE void wheel_normals(std::uint32_t n, VF (&zl)[kK], VF (&zr)[kK]) const {
    Words w[kK];
    draw(n, random::kTagWheelNoise, w);
    for (std::size_t k = 0; k < kK; ++k) {
      zl[k] = normal(candidate(w[k].w0, w[k].w1), k, n, random::kTagWheelRetry + 0);
      zr[k] = normal(candidate(w[k].w2, w[k].w3), k, n, random::kTagWheelRetry + 1);
    }
  }

  HWY_INLINE void sample(const Leg& leg, std::uint32_t n) {
    VF zl[kK], zr[kK];
    wheel_normals(n, zl, zr);
    VF noise_l[kK], noise_r[kK];
    if constexpr (kGeneral) {
      VF extra_l[kK], extra_r[kK];
      effects(leg, n, zl, zr, extra_l, extra_r);
      for (std::size_t k = 0; k < kK; ++k) {
        noise_l[k] = splat(leg.sigma_left) * zl[k] + extra_l[k];
        noise_r[k] = splat(leg.sigma_right) * zr[k] + extra_r[k];
      }
    } else {
      for (std::size_t k = 0; k < kK; ++k) {
        noise_l[k] = splat(leg.sigma_left) * zl[k];
        noise_r[k] = splat(leg.sigma_right) * zr[k];
      }
    }
    for (std::size_t k = 0; k < kK; ++k) step(leg, k, noise_l[k], noise_r[k]);
  }

  /// The exact arc step on vector k; lanes outside the series bounds redo it in scalar code.
  HWY_INLINE void step(const Leg& leg, std::size_t k, VF noise_l, VF noise_r) {
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
      lanes::HWY_NAMESPACE::advance(p_[k], ds, ch, sh, sinc, h);  // this target's copy
      return;
    }
    scalar_lanes(leg, k, noise_l, noise_r);
  }

  /// Rare: some lane is outside the series bounds; the block's vector k takes the scalar step
  /// lane by lane from the pre-step state.
  HWY_NOINLINE void scalar_lanes(const Leg& leg, std::size_t k, VF noise_l, VF noise_r) {
    const DF df;
    alignas(64) double v[7][kN];
    hn::Store(p_[k].x, df, v[0]);
    hn::Store(p_[k].y, df, v[1]);
    hn::Store(p_[k].c, df, v[2]);
    hn::Store(p_[k].s, df, v[3]);
    hn::Store(p_[k].theta, df, v[4]);
    hn::Store(noise_l, df, v[5]);
    hn::Store(noise_r, df, v[6]);
    // Within the bounds the scalar step is the vector formula, so every lane takes it here.
    for (std::size_t j = 0; j < kN; ++j) {
      arc::Pose<double> q{v[0][j], v[1][j], v[2][j], v[3][j], v[4][j]};
      arc::step(q, leg, v[5][j], v[6][j]);
      v[0][j] = q.x, v[1][j] = q.y, v[2][j] = q.c, v[3][j] = q.s, v[4][j] = q.theta;
    }
    p_[k] = {hn::Load(df, v[0]), hn::Load(df, v[1]), hn::Load(df, v[2]), hn::Load(df, v[3]),
             hn::Load(df, v[4])};
  }

  void renormalise() {
    for (std::size_t k = 0; k < kK; ++k) {
      const VF norm = hn::Sqrt(p_[k].c * p_[k].c + p_[k].s * p_[k].s);
      p_[k].c = p_[k].c / norm;
      p_[k].s = p_[k].s / norm;
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

  HWY_INLINE void effects(const Leg& leg, std::uint32_t n, VF (&zl)[kK], VF (&zr)[kK],
                          VF (&extra_l)[kK], VF (&extra_r)[kK]) {
    for (const NoiseMix& m : plan_.mixes) {
      for (std::size_t k = 0; k < kK; ++k) {
        zr[k] = splat(m.from_left) * zl[k] + splat(m.from_right) * zr[k];
      }
    }
    VF z[kMaxDraws][kK];
    for (std::uint32_t d = leg.draws_begin; d < leg.draws_end; ++d) {
      effect_normals(n, plan_.draw_tags[d], z[d - leg.draws_begin]);
    }
    for (std::size_t k = 0; k < kK; ++k) extra_l[k] = extra_r[k] = splat(0.0);
    const DF df;
    for (std::uint32_t o = leg.ops_begin; o < leg.ops_end; ++o) {
      const LaneOp& op = plan_.ops[o];
      if (op.kind == LaneOp::kEvent) {
        events(leg, n, op.effect, extra_l, extra_r);
        continue;
      }
      VF(&extra)[kK] = op.wheel == 0 ? extra_l : extra_r;
      for (std::size_t k = 0; k < kK; ++k) {
        const VF value =
            op.per_run ? hn::Load(df, &values_[op.effect][op.index][k * kN]) : z[op.index][k];
        extra[k] = extra[k] + (value * splat(op.a)) * splat(op.b);
      }
    }
  }

  HWY_INLINE void effect_normals(std::uint32_t n, std::uint32_t tag, VF (&z)[kK]) const {
    Words w[kK];
    draw(n, tag, w);
    for (std::size_t k = 0; k < kK; ++k) z[k] = normal(candidate(w[k].w0, w[k].w1), k, n, tag);
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

  const Plan& plan_;
  const random::Philox::key_type key_;
  const RoundKeys keys_;
  const std::uint64_t first_;
  VU run_lo_[kK], run_hi_[kK];
  arc::Pose<VF> p_[kK];
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
