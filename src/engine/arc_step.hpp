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
/// The short series of a leg whose samples turn little (LegStep::short_series): sin eps through
/// eps^5 (first omitted term eps^6/7! < 5.2e-17 relative at 0.008), cos eps through eps^6
/// (eps^8/8! < 5e-22) and sinc h through h^6 (h^8/9! < 1.8e-17 at 0.04), each below half an ulp.
inline constexpr double kEpsShortMax = 0.008;
inline constexpr double kSincShortMax = 0.04;
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
  /// |h0| and the wheel noise small enough that nearly every sample is within the short series'
  /// bounds (short_series_for): a sample then takes them when |eps| <= kEpsShortMax and
  /// |h| <= kSincShortMax, else the long ones. Speed only: a sample's rule is this flag and its
  /// own eps and h, the same in the reference and every SIMD lane.
  bool short_series = false;
};

/// Whether a leg takes the short series: |h0| + 5 sd(eps) <= kSincShortMax and
/// 5 sd(eps) <= kEpsShortMax (a sample outside them, p < 6e-7, takes the long ones).
inline bool short_series_for(double half_rad, double sigma_left, double sigma_right, double inv_two_b) {
  const double sd_eps = std::sqrt(sigma_left * sigma_left + sigma_right * sigma_right) * inv_two_b;
  return std::abs(half_rad) + 5.0 * sd_eps <= kSincShortMax && 5.0 * sd_eps <= kEpsShortMax;
}

// The polynomials and the rest of the step, templates over the value type. They are in a file of
// their own because a SIMD target must compile its own copy inside its target region (Highway's
// HWY_BEFORE_NAMESPACE); the scalar copy is this one.
#include "engine/arc_series-inl.hpp"  // IWYU pragma: export

inline double identity(double v) { return v; }

/// Scalar step: the reference, also used for vector lanes outside the series bounds.
inline void step(Pose<double>& p, const LegStep& leg, double noise_l, double noise_r) {
  const double eps = (noise_r - noise_l) * leg.inv_two_b;
  const double ds = leg.center_m + 0.5 * (noise_l + noise_r);
  const double h = leg.half_rad + eps;
  const double e2 = eps * eps;
  const bool short_series =
      leg.short_series && std::abs(eps) <= kEpsShortMax && std::abs(h) <= kSincShortMax;
  double ce, se;
  if (short_series) {
    se = sin_short(eps, e2, identity);
    ce = cos_short(e2, identity);
  } else if (std::abs(eps) <= kEpsTaylorMax) {
    se = sin_taylor(eps, e2, identity);
    ce = cos_taylor(e2, identity);
  } else {
    se = std::sin(eps);
    ce = std::cos(eps);
  }
  const double ch = leg.cos_half * ce - leg.sin_half * se;
  const double sh = leg.sin_half * ce + leg.cos_half * se;
  const double sinc = short_series                   ? sinc_short(h * h, identity)
                      : std::abs(h) <= kSincSeriesMax ? sinc_series(h * h, identity)
                                                      : sh / h;
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
