#include "odomcov/engine/simulator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "effects/effect.hpp"
#include "base/random.hpp"

namespace odomcov {
namespace {

// ---------------------------------------------------------------------------------------------
// The sample step: exact constant-curvature update of the true pose.
//
// A sample with true wheel travel (L + nL, R + nR) turns by 2h, h = (R - L)/(2B) + eps with
// eps = (nR - nL)/(2B), and moves its centre by ds = (L + R)/2 + (nL + nR)/2 along the chord
//   ds sinc(h)  at heading  theta + h.
// Heading is carried as the unit vector (c, s) and advanced by rotations, so no sin/cos is
// called per sample: cos h, sin h come from the leg's precomputed cos h0, sin h0 and the
// Taylor series of cos eps, sin eps. Both series and sinc(h) are exact to rounding within
// their bounds, and a lane outside them takes the same formula with std::sin/cos instead.
// ---------------------------------------------------------------------------------------------

/// |eps| up to which the Taylor polynomials below are exact to rounding: the first omitted
/// terms are eps^10/10! < 3e-20 (cos) and eps^11/11! < 3e-22 relative (sin).
constexpr double kEpsTaylorMax = 0.05;
/// |h| up to which the sinc polynomial (through h^14) is exact: h^16/17! < 1e-20 at 0.45.
constexpr double kSincSeriesMax = 0.45;
/// Every this many samples the heading vector is renormalised (rotation rounding otherwise
/// random-walks its length by ~1e-16 per sample).
constexpr std::uint32_t kRenormMask = 1023;

constexpr double kSin1 = -1.0 / 6, kSin2 = 1.0 / 120, kSin3 = -1.0 / 5040, kSin4 = 1.0 / 362880;
constexpr double kCos1 = -1.0 / 2, kCos2 = 1.0 / 24, kCos3 = -1.0 / 720, kCos4 = 1.0 / 40320;
constexpr double kSinc1 = -1.0 / 6, kSinc2 = 1.0 / 120, kSinc3 = -1.0 / 5040,
                 kSinc4 = 1.0 / 362880, kSinc5 = -1.0 / 39916800, kSinc6 = 1.0 / 6227020800,
                 kSinc7 = -1.0 / 1307674368000;

/// A stretch of samples with one encoder increment, with everything the step needs.
struct Leg {
  std::int64_t count = 0;
  ArcSegment encoder;        // encoder increment per sample
  ArcSegment travel;         // systematic true travel per sample (effects' scales applied)
  double center_m = 0.0;   // (L + R)/2 per sample
  double half_rad = 0.0;   // h0 = (R - L)/(2B) per sample
  double cos_half = 1.0;
  double sin_half = 0.0;
  double sigma_left = 0.0;   // kL sqrt|L|
  double sigma_right = 0.0;  // kR sqrt|R|
  double inv_two_b = 0.0;
  double wheelbase_true = 0.0;
  /// Lateral slip per sample [m] (effects' Systematic::lateral x (|L| + |R|)/2): the sample
  /// moves by (ds + i lateral_m) sinc(h) at the chord's heading theta + h. Only the scalar step
  /// takes it; a path with any slip runs the general kernel (Impl::group).
  double lateral_m = 0.0;
  bool series_sinc = true;  // most lanes have |h| <= kSincSeriesMax
  effects::Motion motion;   // of the leg's first sample
  effects::Systematic sys;  // the terms the leg was built with (per-run effects' left out)
};

template <class V>
struct State {
  V x, y, c, s, theta;
};

// The polynomials, written once for scalars and vectors so both evaluate the same expression.
template <class V>
inline __attribute__((always_inline)) V sin_taylor(V eps, V e2) {
  return eps * (1.0 + e2 * (kSin1 + e2 * (kSin2 + e2 * (kSin3 + e2 * kSin4))));
}
template <class V>
inline __attribute__((always_inline)) V cos_taylor(V e2) {
  return 1.0 + e2 * (kCos1 + e2 * (kCos2 + e2 * (kCos3 + e2 * kCos4)));
}
template <class V>
inline __attribute__((always_inline)) V sinc_series(V h2) {
  return 1.0 +
         h2 * (kSinc1 +
               h2 * (kSinc2 + h2 * (kSinc3 + h2 * (kSinc4 + h2 * (kSinc5 + h2 * (kSinc6 + h2 * kSinc7))))));
}

/// The rest of the step once cos h, sin h and sinc h are known.
template <class V>
inline __attribute__((always_inline)) void advance(State<V>& p, V ds, V ch, V sh, V sinc, V h) {
  const V chord = ds * sinc;
  const V mc = p.c * ch - p.s * sh;
  const V ms = p.s * ch + p.c * sh;
  p.x += chord * mc;
  p.y += chord * ms;
  p.c = mc * ch - ms * sh;
  p.s = ms * ch + mc * sh;
  p.theta += h + h;
}

/// Scalar step: the reference, also used for vector lanes outside the series bounds (whose legs
/// have no lateral slip).
inline void step(State<double>& p, const Leg& leg, double noise_l, double noise_r) {
  const double eps = (noise_r - noise_l) * leg.inv_two_b;
  const double ds = leg.center_m + 0.5 * (noise_l + noise_r);
  double ce, se;
  if (std::abs(eps) <= kEpsTaylorMax) {
    const double e2 = eps * eps;
    se = sin_taylor(eps, e2);
    ce = cos_taylor(e2);
  } else {
    se = std::sin(eps);
    ce = std::cos(eps);
  }
  const double ch = leg.cos_half * ce - leg.sin_half * se;
  const double sh = leg.sin_half * ce + leg.cos_half * se;
  const double h = leg.half_rad + eps;
  const double sinc = std::abs(h) <= kSincSeriesMax ? sinc_series(h * h) : sh / h;
  if (leg.lateral_m != 0.0) {
    // The lateral slip, spread along the arc as the travel is: lateral_m sinc(h) to the left of
    // the chord's heading, (p.c, p.s) rotated by h (effects' Systematic, "lateral").
    const double side = leg.lateral_m * sinc;
    p.x -= side * (p.s * ch + p.c * sh);
    p.y += side * (p.c * ch - p.s * sh);
  }
  advance(p, ds, ch, sh, sinc, h);
}

inline void renormalise(State<double>& p) {
  const double norm = std::sqrt(p.c * p.c + p.s * p.s);
  p.c /= norm;
  p.s /= norm;
}

// ---------------------------------------------------------------------------------------------
// The vectorised kernel: kLanes runs in lock step, in GCC vector types that the compiler lowers
// to AVX-512, AVX2 or SSE2 (one clone each, chosen at load time). Lane j of a group simulates
// run first + j with exactly the scalar arithmetic (no FMA contraction: -ffp-contract=off).
// ---------------------------------------------------------------------------------------------
constexpr int kLanes = 8;
typedef double VecD __attribute__((vector_size(kLanes * sizeof(double))));
typedef std::uint64_t VecU __attribute__((vector_size(kLanes * sizeof(std::uint64_t))));
typedef std::int64_t VecI __attribute__((vector_size(kLanes * sizeof(std::int64_t))));

inline __attribute__((always_inline)) VecD as_double(VecU u) {
  VecD d;
  std::memcpy(&d, &u, sizeof d);
  return d;
}
inline __attribute__((always_inline)) VecU as_bits(VecD d) {
  VecU u;
  std::memcpy(&u, &d, sizeof u);
  return u;
}
inline __attribute__((always_inline)) VecD vabs(VecD x) {
  return as_double(as_bits(x) & 0x7FFFFFFFFFFFFFFFull);
}

/// Philox4x32-10 on kLanes counters at once; words are held zero-extended in 64-bit lanes.
/// Same rounds and key schedule as Random123's philox4x32 (tested bit for bit).
inline __attribute__((always_inline)) void philox_lanes(VecU& w0, VecU& w1, VecU& w2, VecU& w3,
                                                        std::uint32_t k0, std::uint32_t k1) {
  constexpr std::uint64_t kM0 = 0xD2511F53u, kM1 = 0xCD9E8D57u, kLow = 0xFFFFFFFFu;
  for (int round = 0; round < 10; ++round) {
    const VecU p0 = w0 * kM0;
    const VecU p1 = w2 * kM1;
    const VecU n0 = (p1 >> 32) ^ w1 ^ std::uint64_t{k0};
    const VecU n2 = (p0 >> 32) ^ w3 ^ std::uint64_t{k1};
    w1 = p1 & kLow;
    w3 = p0 & kLow;
    w0 = n0;
    w2 = n2;
    k0 += 0x9E3779B9u;
    k1 += 0xBB67AE85u;
  }
}

/// Standard normals from kLanes 64-bit candidates: the ziggurat fast path in vectors, the rare
/// rejected lanes by the scalar method (same streams as the scalar kernel).
inline __attribute__((always_inline)) VecD normals(VecU bits, const VecU& run,
                                                   const random::Philox::key_type& key,
                                                   std::uint32_t sample, std::uint32_t wheel) {
  const random::ZigguratTables& zig = random::kZiggurat;
  const VecU index = bits & 0xFFu;
  const VecD u = as_double((bits >> 12) | 0x3FF0000000000000ull) - 1.0;
  const VecD sign = as_double(((bits & 0x100u) << 55) | 0x3FF0000000000000ull);
  VecD width, ratio;
  for (int j = 0; j < kLanes; ++j) {
    width[j] = zig.x[index[j]];
    ratio[j] = zig.ratio[index[j]];
  }
  VecD z = sign * u * width;
  const VecI rejected = u >= ratio;
  bool any = false;
  for (int j = 0; j < kLanes; ++j) any |= rejected[j] != 0;
  if (__builtin_expect(any, 0)) {
    for (int j = 0; j < kLanes; ++j) {
      if (rejected[j]) z[j] = random::zig_slow(bits[j], key, run[j], sample, random::kTagWheelRetry + wheel);
    }
  }
  return z;
}

/// The vector kernel's rare fallback: the lanes marked in `special` (outside the series
/// bounds) redo the sample with the scalar step from their pre-step state `before`, with the
/// same wheel noise [m]; the other lanes keep the vector step's result in `p`.
inline __attribute__((always_inline)) void scalar_step_lanes(State<VecD>& p, const State<VecD>& before,
                                                             const VecI& special, const Leg& leg,
                                                             const VecD& noise_l, const VecD& noise_r) {
  for (int j = 0; j < kLanes; ++j) {
    if (!special[j]) continue;
    State<double> q{before.x[j], before.y[j], before.c[j], before.s[j], before.theta[j]};
    step(q, leg, noise_l[j], noise_r[j]);
    p.x[j] = q.x, p.y[j] = q.y, p.c[j] = q.c, p.s[j] = q.s, p.theta[j] = q.theta;
  }
}

/// renormalise, lane by lane: each heading vector (c, s) back to unit length.
inline __attribute__((always_inline)) void renormalise_lanes(State<VecD>& p) {
  for (int j = 0; j < kLanes; ++j) {
    const double norm = std::sqrt(p.c[j] * p.c[j] + p.s[j] * p.s[j]);
    p.c[j] /= norm;
    p.s[j] /= norm;
  }
}

}  // namespace

struct Simulator::Impl {
  Robot robot;
  std::vector<Leg> legs;           // the true motion: systematic effects folded in
  std::vector<std::unique_ptr<effects::Effect>> effects;
  std::vector<std::uint32_t> random_effects;  // indices of the effects with per-run/sample hooks
  /// Positions in random_effects of the effects whose systematic terms depend on the run's
  /// draws (Effect::per_run_systematic): left out of `legs`, composed per leg and run.
  std::vector<std::uint32_t> per_run_terms;
  std::vector<const effects::Effect*> measuring;  // effects with a measurement hook
  std::int64_t samples = 0;
  bool lateral = false;  // some leg slips sideways
  Vector3 odometry_pose = Vector3::Zero();

  static Leg make_leg(std::int64_t count, const ArcSegment& increment, const effects::Motion& motion,
                      const effects::Systematic& sys, const Robot& robot) {
    Leg leg;
    leg.count = count;
    leg.encoder = increment;
    leg.motion = motion;
    leg.sys = sys;
    leg.travel = sys.travel(increment.left_m, increment.right_m);
    leg.wheelbase_true = sys.wheelbase_factor * robot.wheelbase_m;
    leg.center_m = leg.travel.center_m();
    leg.half_rad = 0.5 * leg.travel.heading_change_rad(leg.wheelbase_true);
    leg.cos_half = std::cos(leg.half_rad);
    leg.sin_half = std::sin(leg.half_rad);
    // the white noise variance k^2 |increment| times the effects' noise factor
    const Eigen::Vector2d variance = wheel_variances(increment, robot.noise) * sys.noise_factor;
    leg.sigma_left = std::sqrt(variance.x());
    leg.sigma_right = std::sqrt(variance.y());
    leg.inv_two_b = 1.0 / (2.0 * leg.wheelbase_true);
    leg.lateral_m = sys.lateral * 0.5 * (std::abs(increment.left_m) + std::abs(increment.right_m));
    leg.series_sinc = std::abs(leg.half_rad) <= kSincSeriesMax;
    return leg;
  }

  /// The legs of the true motion: each sample's systematic factors from its Motion, once per
  /// leg of equal samples when no effect depends on the history, else sample by sample with
  /// equal neighbours merged (a leg of a planned path then splits only where the factors
  /// change, e.g. while backlash is taken up). Effects whose terms depend on the run's draws
  /// are left out here (run_leg composes them); when one of them depends on the history, no
  /// two samples merge (their terms may differ in another run). Built once per path, never per
  /// run. `heading0_rad` starts the motion's absolute heading.
  static std::vector<Leg> make_legs(const std::vector<SampleRun>& schedule, const Robot& robot,
                                    const std::vector<std::unique_ptr<effects::Effect>>& list,
                                    double heading0_rad) {
    effects::Dependence dependence = effects::Dependence::none;
    bool merge = true;
    for (const auto& e : list) {
      dependence = std::max(dependence, e->dependence());
      merge = merge && !(e->per_run_systematic() && e->dependence() == effects::Dependence::history);
    }
    const bool per_sample = dependence == effects::Dependence::history;
    auto factors = [&](const effects::Motion& m) {
      effects::Systematic sys;
      for (const auto& e : list) {
        if (!e->per_run_systematic()) e->systematic(m, sys);
      }
      return sys;
    };
    effects::MotionTracker tracker(robot.wheelbase_m, heading0_rad);
    std::vector<Leg> out;
    effects::Systematic last;
    for (const SampleRun& run : schedule) {
      const ArcSegment& inc = run.increment;
      if (!per_sample) {
        const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s, run.count);
        out.push_back(make_leg(run.count, inc, m, factors(m), robot));
        continue;
      }
      for (std::int64_t i = 0; i < run.count; ++i) {
        const effects::Motion m = tracker.next(inc.left_m, inc.right_m, run.duration_s);
        const effects::Systematic sys = factors(m);
        if (merge && i > 0 && sys == last) {
          ++out.back().count;
        } else {
          out.push_back(make_leg(1, inc, m, sys, robot));
        }
        last = sys;
      }
    }
    return out;
  }

  /// A leg as this run sees it: the leg's own terms composed with those of the effects whose
  /// terms depend on the run's draws (`states` from their begin_run).
  Leg run_leg(const Leg& leg, const std::array<effects::RunState, kMaxEffects>& states) const {
    effects::Systematic sys = leg.sys;
    for (const std::uint32_t r : per_run_terms) {
      effects[random_effects[r]]->run_systematic(leg.motion, states[r], sys);
    }
    return make_leg(leg.count, leg.encoder, leg.motion, sys, robot);
  }

  Impl(const Robot& r, const std::vector<SampleRun>& schedule, const EffectList& effect_list,
       double heading0_rad)
      : robot(r), effects(effects::instantiate(effect_list)) {
    for (std::size_t e = 0; e < effects.size(); ++e) {
      if (effects[e]->stochastic()) {
        if (effects[e]->per_run_systematic()) per_run_terms.push_back(static_cast<std::uint32_t>(random_effects.size()));
        random_effects.push_back(static_cast<std::uint32_t>(e));
      }
      if (effects[e]->measures()) measuring.push_back(effects[e].get());
    }
    legs = make_legs(schedule, robot, effects, heading0_rad);
    double max_travel = 0.0;
    for (const Leg& leg : legs) {
      samples += leg.count;
      max_travel = std::max(max_travel, 0.5 * (std::abs(leg.encoder.left_m) + std::abs(leg.encoder.right_m)));
      lateral = lateral || leg.lateral_m != 0.0;
    }
    for (std::size_t e = 0; e < effects.size(); ++e) {
      if (const std::string why = effects[e]->check_samples(max_travel); !why.empty()) {
        throw EffectError("effects[" + std::to_string(e) + "]." + effect_list[e].name, why);
      }
    }
    // The odometry: the nominal motion through the same integrator with zero noise, so with
    // no effects and k = 0 the error is exactly zero.
    State<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
    std::uint32_t n = 0;
    for (const Leg& leg : make_legs(schedule, robot, {}, 0.0)) {
      for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
        step(p, leg, 0.0, 0.0);
        if ((n & kRenormMask) == kRenormMask) renormalise(p);
      }
    }
    odometry_pose = {p.x, p.y, p.theta};
  }

  /// The error the external reference sees: the true end pose through the measurement hooks,
  /// minus the odometry.
  Vector3 error_of(double x, double y, double theta) const {
    Vector3 pose(x, y, theta);
    for (const effects::Effect* e : measuring) e->measure(pose);
    return pose_error(pose, odometry_pose);
  }

  /// The scalar kernel: the reference for the vectorised one and, with stochastic effects or a
  /// lateral slip, the general kernel. The stochastic effects see each sample after the wheel
  /// normals are drawn; each draws from its own slot, its index in the effect list. Effects whose
  /// systematic terms depend on the run's draws rebuild each leg for the run (run_leg: one sin
  /// and cos per leg and run, nothing allocated).
  Vector3 scalar_run(const random::Philox::key_type& key, std::uint64_t run) const {
    State<double> p{0.0, 0.0, 1.0, 0.0, 0.0};
    const bool stochastic = !random_effects.empty();
    // Fixed-size per-run state (at most kMaxEffects effects): nothing is allocated per run.
    std::array<effects::Draws, kMaxEffects> draws;
    std::array<effects::RunState, kMaxEffects> states{};
    for (std::size_t i = 0; i < random_effects.size(); ++i) {
      draws[i] = effects::Draws(key, run, random_effects[i]);
      effects[random_effects[i]]->begin_run(states[i], draws[i]);
    }
    std::uint32_t n = 0;
    Leg this_run;  // a leg rebuilt for this run's draws
    for (const Leg& path_leg : legs) {
      if (!per_run_terms.empty()) this_run = run_leg(path_leg, states);
      const Leg& leg = per_run_terms.empty() ? path_leg : this_run;
      for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
        const random::Bits128 b = random::draw(key, run, n, random::kTagWheelNoise);
        double zl = random::normal(b.lo, key, run, n, random::kTagWheelRetry + 0);
        double zr = random::normal(b.hi, key, run, n, random::kTagWheelRetry + 1);
        double noise_l, noise_r;
        if (stochastic) {
          for (std::uint32_t e : random_effects) effects[e]->shape_noise(zl, zr);
          effects::WorldSample ws;
          ws.index = n;
          ws.encoder_left = leg.encoder.left_m;
          ws.encoder_right = leg.encoder.right_m;
          ws.wheelbase_nominal = robot.wheelbase_m;
          ws.travel_left = leg.travel.left_m;
          ws.travel_right = leg.travel.right_m;
          ws.wheelbase = leg.wheelbase_true;
          for (std::size_t r = 0; r < random_effects.size(); ++r) {
            effects[random_effects[r]]->perturb(ws, states[r], draws[r]);
          }
          noise_l = leg.sigma_left * zl + ws.extra_left;
          noise_r = leg.sigma_right * zr + ws.extra_right;
        } else {
          noise_l = leg.sigma_left * zl;
          noise_r = leg.sigma_right * zr;
        }
        step(p, leg, noise_l, noise_r);
        if ((n & kRenormMask) == kRenormMask) renormalise(p);
      }
    }
    return error_of(p.x, p.y, p.theta);
  }

  /// Runs first .. first+kLanes-1: vectorised, or the general kernel run by run (stochastic
  /// effects, or a lateral slip, which the vector kernel does not take).
  void group(const random::Philox::key_type& key, std::uint64_t first, Vector3* out) const {
    if (random_effects.empty() && !lateral) return vector_group(key, first, out);
    for (int j = 0; j < kLanes; ++j) out[j] = scalar_run(key, first + static_cast<std::uint64_t>(j));
  }

  void vector_group(const random::Philox::key_type& key, std::uint64_t first,
                    Vector3* out) const;
};

// The clones: AVX-512 (x86-64-v4), AVX2 (v3) and baseline SSE2, picked by the loader. They need
// GCC on x86-64 (clang 14 rejects these target strings); any other compiler or architecture
// builds the same vector-extension code once, for the target's baseline (ODOMCOV_SIMD_CLONES).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define ODOMCOV_SIMD_CLONES 1
__attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define ODOMCOV_SIMD_CLONES 0
#endif
void
Simulator::Impl::vector_group(const random::Philox::key_type& key, std::uint64_t first,
                              Vector3* out) const {
  VecU run;
  for (int j = 0; j < kLanes; ++j) run[j] = first + static_cast<std::uint64_t>(j);
  const VecU run_lo = run & 0xFFFFFFFFull;
  const VecU run_hi = run >> 32;
  State<VecD> p{VecD{} + 0.0, VecD{} + 0.0, VecD{} + 1.0, VecD{} + 0.0, VecD{} + 0.0};
  std::uint32_t n = 0;
  for (const Leg& leg : legs) {
    for (std::int64_t i = 0; i < leg.count; ++i, ++n) {
      VecU w0 = VecU{} + std::uint64_t{n};
      VecU w1 = VecU{} + std::uint64_t{random::kTagWheelNoise};
      VecU w2 = run_lo, w3 = run_hi;
      philox_lanes(w0, w1, w2, w3, key[0], key[1]);
      const VecD zl = normals(w0 | (w1 << 32), run, key, n, 0);
      const VecD zr = normals(w2 | (w3 << 32), run, key, n, 1);
      const VecD noise_l = leg.sigma_left * zl;
      const VecD noise_r = leg.sigma_right * zr;

      const VecD eps = (noise_r - noise_l) * leg.inv_two_b;
      const VecD ds = leg.center_m + 0.5 * (noise_l + noise_r);
      const VecD e2 = eps * eps;
      const VecD se = sin_taylor(eps, e2);
      const VecD ce = cos_taylor(e2);
      const VecD ch = leg.cos_half * ce - leg.sin_half * se;
      const VecD sh = leg.sin_half * ce + leg.cos_half * se;
      const VecD h = leg.half_rad + eps;
      VecI special = vabs(eps) > kEpsTaylorMax;
      VecD sinc;
      if (leg.series_sinc) {
        sinc = sinc_series(h * h);
        special |= vabs(h) > kSincSeriesMax;
      } else {
        sinc = sh / h;
        special |= vabs(h) <= kSincSeriesMax;
      }
      bool any = false;
      for (int j = 0; j < kLanes; ++j) any |= special[j] != 0;
      if (__builtin_expect(!any, 1)) {
        advance(p, ds, ch, sh, sinc, h);
      } else {
        // Rare: lanes outside the series bounds take the scalar step from the pre-step state.
        const State<VecD> before = p;
        advance(p, ds, ch, sh, sinc, h);
        scalar_step_lanes(p, before, special, leg, noise_l, noise_r);
      }
      if ((n & kRenormMask) == kRenormMask) renormalise_lanes(p);
    }
  }
  for (int j = 0; j < kLanes; ++j) out[j] = error_of(p.x[j], p.y[j], p.theta[j]);
}

Simulator::Simulator(const Robot& robot, const Path& path, const EffectList& effects, double heading0_rad)
    : impl_(std::make_unique<Impl>(robot, sample_schedule(path), effects, heading0_rad)) {}

namespace {

/// A logged run's schedule: one sample per encoder piece, of the piece's duration.
std::vector<SampleRun> piece_schedule(const std::vector<ArcSegment>& pieces,
                                      const std::vector<double>& durations_s) {
  if (!durations_s.empty() && durations_s.size() != pieces.size()) {
    throw std::invalid_argument("Simulator: " + std::to_string(durations_s.size()) +
                                " durations for " + std::to_string(pieces.size()) + " pieces");
  }
  std::vector<SampleRun> schedule;
  schedule.reserve(pieces.size());
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const double dt = durations_s.empty() ? std::numeric_limits<double>::quiet_NaN() : durations_s[i];
    schedule.push_back({1, pieces[i], dt});
  }
  return schedule;
}

}  // namespace

Simulator::Simulator(const Robot& robot, const std::vector<ArcSegment>& pieces,
                     const std::vector<double>& durations_s, const EffectList& effects,
                     double heading0_rad)
    : impl_(std::make_unique<Impl>(robot, piece_schedule(pieces, durations_s), effects, heading0_rad)) {}
Simulator::~Simulator() = default;
Simulator::Simulator(Simulator&&) noexcept = default;
Simulator& Simulator::operator=(Simulator&&) noexcept = default;

Vector3 Simulator::odometry_end_pose() const { return impl_->odometry_pose; }
std::int64_t Simulator::samples_per_run() const { return impl_->samples; }

Vector3 Simulator::reference_error(std::uint64_t seed, std::int64_t run) const {
  return impl_->scalar_run(random::key_from_seed(seed), static_cast<std::uint64_t>(run));
}

namespace {

/// Lane groups per leaf of the reduction tree: about 2^20 sample steps, a function of the path
/// only, so the tree (and therefore every rounding) is the same for any thread count.
std::int64_t groups_per_leaf(std::int64_t samples_per_run) {
  const std::int64_t steps_per_group = std::max<std::int64_t>(1, samples_per_run * kLanes);
  return std::clamp<std::int64_t>((std::int64_t{1} << 20) / steps_per_group, 1, 64);
}

template <class F>
auto in_arena(int threads, F&& f) {
  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  return arena.execute(std::forward<F>(f));
}

}  // namespace

MomentAccumulator Simulator::simulate(std::int64_t runs, std::uint64_t seed, int threads,
                                      Progress* progress) const {
  const auto key = random::key_from_seed(seed);
  const std::int64_t groups = (runs + kLanes - 1) / kLanes;
  const tbb::blocked_range<std::int64_t> range(0, groups, groups_per_leaf(impl_->samples));
  return in_arena(threads, [&] {
    return tbb::parallel_deterministic_reduce(
        range, MomentAccumulator{},
        [&](const tbb::blocked_range<std::int64_t>& r, MomentAccumulator acc) {
          Vector3 errors[kLanes];
          for (std::int64_t g = r.begin(); g != r.end(); ++g) {
            if (progress && progress->cancel.load(std::memory_order_relaxed)) break;
            const std::int64_t first = g * kLanes;
            impl_->group(key, static_cast<std::uint64_t>(first), errors);
            const std::int64_t valid = std::min<std::int64_t>(kLanes, runs - first);
            for (std::int64_t j = 0; j < valid; ++j) acc.add(errors[j]);
            if (progress) progress->runs_done.fetch_add(valid, std::memory_order_relaxed);
          }
          return acc;
        },
        [](MomentAccumulator left, const MomentAccumulator& right) {
          left.merge(right);
          return left;
        });
  });
}

std::vector<Vector3> Simulator::errors(std::uint64_t seed, std::int64_t first, std::int64_t count,
                                       int threads) const {
  const auto key = random::key_from_seed(seed);
  std::vector<Vector3> out(static_cast<std::size_t>(count));
  const std::int64_t groups = (count + kLanes - 1) / kLanes;
  in_arena(threads, [&] {
    tbb::parallel_for(tbb::blocked_range<std::int64_t>(0, groups),
                      [&](const tbb::blocked_range<std::int64_t>& r) {
                        Vector3 errors[kLanes];
                        for (std::int64_t g = r.begin(); g != r.end(); ++g) {
                          const std::int64_t offset = g * kLanes;
                          impl_->group(key, static_cast<std::uint64_t>(first + offset), errors);
                          const std::int64_t valid = std::min<std::int64_t>(kLanes, count - offset);
                          for (std::int64_t j = 0; j < valid; ++j) {
                            out[static_cast<std::size_t>(offset + j)] = errors[j];
                          }
                        }
                      });
  });
  return out;
}

const char* Simulator::kernel_isa() {
#if ODOMCOV_SIMD_CLONES
  __builtin_cpu_init();
  if (__builtin_cpu_supports("x86-64-v4")) return "AVX-512 (x86-64-v4)";
  if (__builtin_cpu_supports("x86-64-v3")) return "AVX2 (x86-64-v3)";
  return "SSE2 (x86-64)";
#else
  return "portable (vector extensions, no clones)";
#endif
}

}  // namespace odomcov
