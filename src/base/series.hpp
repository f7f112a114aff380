// Cancellation-free scalar kernels for the closed-form arc covariance.
//
// The arc integrals of [Kleeman95, eq. (41)] contain differences such as
// 6a - 8 sin a + sin 2a = O(a^5) that lose every significant digit as a -> 0 (the line limit,
// R -> infinity at fixed length). Every such difference reduces to the two entire functions
//
//   u3(y) = (y - sin y) / y^3                     -> 1/6  as y -> 0
//   a4(x) = (3/2 - 2 sinc x + sinc(2x)/2) / x^4   -> 1/20 as x -> 0
//
// plus products of sinc, which need no care. Each function uses its Taylor series below a named
// threshold and the closed form above it. The thresholds are where the closed form's rounding
// error has fallen to a few ulp; the series keeps enough terms that its truncation error at the
// threshold is below 1e-17 relative, so the two branches agree to rounding at the switch (there
// is no jump, tested in series_test.cpp against a quad-precision reference).
#pragma once

#include <cmath>

namespace odomcov::series {

/// sinc(x) = sin(x)/x. sin(x)/x is accurate to an ulp for every x != 0; the series below
/// kSincSeriesBelow only avoids 0/0. Truncation after x^6: |x|^8/9! < 1e-37 at the threshold.
inline constexpr double kSincSeriesBelow = 1e-4;

/// Between kSincSeriesBelow and kSincLongSeriesBelow a longer series (through x^14; the first
/// omitted term, 0.125^16/17!, is below 1e-28) replaces the sine, which is the costly part of
/// the per-sample pieces of logged runs.
inline constexpr double kSincLongSeriesBelow = 0.125;
inline double sinc(double x) {
  const double x2 = x * x;
  if (std::abs(x) < kSincSeriesBelow) return 1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0));
  if (std::abs(x) < kSincLongSeriesBelow) {
    // Horner on x^2: 1 - x^2/3! (1 - x^2/(4 5) (1 - x^2/(6 7) (... (1 - x^2/(14 15)))))
    double sum = 1.0;
    for (int k = 7; k >= 1; --k) sum = 1.0 - x2 / ((2.0 * k) * (2.0 * k + 1.0)) * sum;
    return sum;
  }
  return std::sin(x) / x;
}

/// u3(y) = (y - sin y)/y^3 = sum_{k>=0} (-1)^k y^(2k) / (2k+3)!.
/// Closed form: relative error ~ eps (|y| + |sin y|)/|y - sin y|, 2.7 eps at y = 2.
/// Series: 13 terms (through y^24); the first omitted term at y = 2 is 2^26/29! = 7e-24.
inline constexpr double kU3SeriesBelow = 2.0;
inline constexpr int kU3SeriesTerms = 13;

inline double u3(double y) {
  if (std::abs(y) >= kU3SeriesBelow) return (y - std::sin(y)) / (y * y * y);
  // Horner on y^2 with coefficients c_k = (-1)^k/(2k+3)!, built as ratios of successive terms:
  // c_{k+1}/c_k = -1/((2k+4)(2k+5)).
  // Below 0.25, 7 terms suffice (first omitted term 0.25^14/17! < 1e-22).
  const int terms = std::abs(y) < 0.25 ? 7 : kU3SeriesTerms;
  const double y2 = y * y;
  double sum = 1.0;
  for (int k = terms - 2; k >= 0; --k) {
    sum = 1.0 - y2 / ((2.0 * k + 4.0) * (2.0 * k + 5.0)) * sum;
  }
  return sum / 6.0;
}

/// a4(x) = (3/2 - 2 sinc x + sinc(2x)/2)/x^4 = 2 (u3(x) - u3(2x)) / x^2
///       = sum_{n>=2} (-1)^n (2^(2n-1) - 2) x^(2n-4) / (2n+1)!.
/// Above the threshold the u3 difference has no cancellation (u3(x) ~ 1/x^2 > u3(2x) ~ 1/(4x^2));
/// its relative error is ~ 6 eps at x = 2. Series: 18 terms (n = 2..19); the first omitted term
/// at x = 2 is 2^(4*20-5)/41! < 1e-26.
inline constexpr double kA4SeriesBelow = 2.0;
inline constexpr int kA4SeriesTerms = 18;

inline double a4(double x) {
  if (std::abs(x) >= kA4SeriesBelow) return 2.0 * (u3(x) - u3(2.0 * x)) / (x * x);
  // Terms t_n = (-1)^n (2^(2n-1) - 2) x^(2n-4)/(2n+1)!, summed smallest first.
  const double x2 = x * x;
  // Below 0.125, 7 terms suffice (first omitted term 2^15 0.125^14/17! < 1e-22).
  const int count = std::abs(x) < 0.125 ? 7 : kA4SeriesTerms;
  double terms[kA4SeriesTerms];
  double factorial = 120.0;  // (2n+1)! at n = 2
  double pow2 = 8.0;         // 2^(2n-1) at n = 2
  double xpow = 1.0;         // x^(2n-4) at n = 2
  for (int i = 0; i < count; ++i) {
    const int n = i + 2;
    const double sign = (n % 2 == 0) ? 1.0 : -1.0;
    terms[i] = sign * (pow2 - 2.0) * xpow / factorial;
    factorial *= (2.0 * n + 2.0) * (2.0 * n + 3.0);
    pow2 *= 4.0;
    xpow *= x2;
  }
  double sum = 0.0;
  for (int i = count - 1; i >= 0; --i) sum += terms[i];
  return sum;
}

/// expm1(x); below kExpm1SeriesBelow in size (heading variances along a run) its Taylor series
/// through x^5, whose first term left out, x^6/720, is below 1.4e-18 of x; libm above.
inline constexpr double kExpm1SeriesBelow = 1e-3;
inline double expm1_small(double x) {
  if (std::abs(x) < kExpm1SeriesBelow) {
    return x * (1.0 + x * (1.0 / 2.0 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0)))));
  }
  return std::expm1(x);
}

}  // namespace odomcov::series
