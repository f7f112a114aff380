// The simulator's sample step, written once for scalars and for SIMD vectors so the scalar
// reference kernel and every vector target evaluate the same expressions in the same order (no
// FMA: the project builds with -ffp-contract=off and the vector code uses no MulAdd), and hence
// agree bit for bit.
//
// A sample with true wheel travel (L + nL, R + nR) turns by 2h, h = (R - L)/(2B) + eps with
// eps = (nR - nL)/(2B), and moves its centre by ds = (L + R)/2 + (nL + nR)/2 along the chord
//   ds sinc(h)  at heading  theta + h.
// Heading is carried as the unit vector (c, s) and advanced by rotations, so no sin/cos is
// called per sample: cos h, sin h come from the leg's precomputed cos h0, sin h0 and the
// Taylor series of cos eps, sin eps. Both series and sinc(h) are exact to rounding within
// their bounds, and a lane outside them takes the same formula with std::sin/cos instead.
#pragma once

#include <cmath>
#include <cstdint>

namespace odomcov::arc {

/// |eps| up to which the Taylor polynomials below are exact to rounding: the first omitted
/// terms are eps^10/10! < 3e-20 (cos) and eps^11/11! < 3e-22 relative (sin).
inline constexpr double kEpsTaylorMax = 0.05;
/// |h| up to which the sinc polynomial (through h^14) is exact: h^16/17! < 1e-20 at 0.45.
inline constexpr double kSincSeriesMax = 0.45;
/// Every this many samples the heading vector is renormalised (rotation rounding otherwise
/// random-walks its length by ~1e-16 per sample).
inline constexpr std::uint32_t kRenormMask = 1023;

namespace constants {
inline constexpr double kSin1 = -1.0 / 6, kSin2 = 1.0 / 120, kSin3 = -1.0 / 5040,
                        kSin4 = 1.0 / 362880;
inline constexpr double kCos1 = -1.0 / 2, kCos2 = 1.0 / 24, kCos3 = -1.0 / 720,
                        kCos4 = 1.0 / 40320;
inline constexpr double kSinc1 = -1.0 / 6, kSinc2 = 1.0 / 120, kSinc3 = -1.0 / 5040,
                        kSinc4 = 1.0 / 362880, kSinc5 = -1.0 / 39916800,
                        kSinc6 = 1.0 / 6227020800, kSinc7 = -1.0 / 1307674368000;
}  // namespace constants

/// What the step needs of a leg (a stretch of samples with one encoder increment).
struct LegStep {
  double center_m = 0.0;   // (L + R)/2 per sample, systematic true travel
  double half_rad = 0.0;   // h0 = (R - L)/(2B) per sample
  double cos_half = 1.0;
  double sin_half = 0.0;
  double inv_two_b = 0.0;  // 1/(2B), B the true wheelbase
  double lateral_m = 0.0;  // leftward slip per sample (Systematic::lateral x (|L| + |R|)/2)
  bool series_sinc = true;  // |h0| <= kSincSeriesMax: most lanes take the sinc series
};

// The polynomials and the rest of the step, templates over the value type. They are in a file of
// their own because a SIMD target must compile its own copy inside its target region (Highway's
// HWY_BEFORE_NAMESPACE); the scalar copy is this one.
#include "engine/arc_series-inl.hpp"  // IWYU pragma: export

inline double identity(double v) { return v; }

/// Scalar step: the reference, also used for vector lanes outside the series bounds.
inline void step(Pose<double>& p, const LegStep& leg, double noise_l, double noise_r) {
  const double eps = (noise_r - noise_l) * leg.inv_two_b;
  const double ds = leg.center_m + 0.5 * (noise_l + noise_r);
  double ce, se;
  if (std::abs(eps) <= kEpsTaylorMax) {
    const double e2 = eps * eps;
    se = sin_taylor(eps, e2, identity);
    ce = cos_taylor(e2, identity);
  } else {
    se = std::sin(eps);
    ce = std::cos(eps);
  }
  const double ch = leg.cos_half * ce - leg.sin_half * se;
  const double sh = leg.sin_half * ce + leg.cos_half * se;
  const double h = leg.half_rad + eps;
  const double sinc = std::abs(h) <= kSincSeriesMax ? sinc_series(h * h, identity) : sh / h;
  if (leg.lateral_m != 0.0) {
    advance_lateral(p, ds, leg.lateral_m, ch, sh, sinc, h);
  } else {
    advance(p, ds, ch, sh, sinc, h);
  }
}

inline void renormalise(Pose<double>& p) {
  const double norm = std::sqrt(p.c * p.c + p.s * p.s);
  p.c = p.c / norm;
  p.s = p.s / norm;
}

}  // namespace odomcov::arc
