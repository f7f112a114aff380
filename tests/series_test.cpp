// The series kernels against a quad-precision evaluation of their closed forms: __float128 with
// libquadmath on x86-64, long double where it is IEEE binary128 (aarch64 Linux).
// The reference's own error is at most ~80 * 1e-34 / x^4 (a4) relative, below 1e-19 for the
// x >= 1e-3 used here; below that, the exact Taylor polynomial to x^4 (error < x^6 terms, i.e.
// < 1e-18 relative) is the reference.
#include <gtest/gtest.h>

#include <cfloat>
#include <cmath>
#if LDBL_MANT_DIG != 113
#include <quadmath.h>
#endif
#include <limits>
#include <vector>

#include "base/series.hpp"

namespace odomcov::series {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

#if LDBL_MANT_DIG == 113
using Quad = long double;  // IEEE binary128 (aarch64)
Quad sin_quad(Quad x) { return std::sin(x); }
Quad abs_quad(Quad x) { return std::fabs(x); }
#else
using Quad = __float128;
Quad sin_quad(Quad x) { return sinq(x); }
Quad abs_quad(Quad x) { return fabsq(x); }
#endif

Quad u3_quad(Quad y) { return (y - sin_quad(y)) / (y * y * y); }
Quad sinc_quad(Quad x) { return sin_quad(x) / x; }
Quad a4_quad(Quad x) {
  return (Quad(1.5) - 2 * sinc_quad(x) + sinc_quad(2 * x) / 2) / (x * x * x * x);
}

double rel_err(double got, Quad want) {
  return static_cast<double>(abs_quad((static_cast<Quad>(got) - want) / want));
}

/// Arguments log-spaced over [1e-3, 60], both signs, plus points just either side of each switch.
std::vector<double> arguments() {
  std::vector<double> xs;
  for (int i = 0; i <= 4000; ++i) {
    const double x = std::pow(10.0, -3.0 + 4.78 * i / 4000.0);
    xs.push_back(x);
    xs.push_back(-x);
  }
  for (double t : {kSincSeriesBelow, kU3SeriesBelow, kA4SeriesBelow}) {
    for (double f : {1.0 - 4 * kEps, 1.0 - kEps, 1.0, 1.0 + kEps, 1.0 + 4 * kEps}) {
      if (t * f >= 1e-3) xs.push_back(t * f);
    }
  }
  return xs;
}

// The error bounds below are the ones derived in series.hpp: u3's worst branch is the closed
// form at the switch (2.7 eps) plus sin's own rounding; a4 adds u3's error twice to its 6 eps.
TEST(Series, U3MatchesQuadPrecision) {
  double worst = 0.0;
  for (double y : arguments()) worst = std::max(worst, rel_err(u3(y), u3_quad(y)));
  EXPECT_LE(worst, 8 * kEps) << "worst relative error " << worst / kEps << " ulp";
}

TEST(Series, A4MatchesQuadPrecision) {
  double worst = 0.0;
  for (double x : arguments()) worst = std::max(worst, rel_err(a4(x), a4_quad(x)));
  EXPECT_LE(worst, 16 * kEps) << "worst relative error " << worst / kEps << " ulp";
}

TEST(Series, SincMatchesQuadPrecision) {
  double worst = 0.0;
  for (double x : arguments()) worst = std::max(worst, rel_err(sinc(x), sinc_quad(x)));
  EXPECT_LE(worst, 2 * kEps);
}

TEST(Series, TinyArgumentsMatchTaylor) {
  // Exact Taylor polynomials through x^4; the omitted x^6 terms are below 1e-18 relative here.
  for (double x : {1e-300, 1e-30, 1e-12, 1e-8, 1e-6, 1e-4, 9e-4, -1e-7}) {
    const double x2 = x * x;
    EXPECT_NEAR(u3(x), 1.0 / 6 - x2 / 120 + x2 * x2 / 5040, 2 * kEps / 6);
    EXPECT_NEAR(a4(x), 1.0 / 20 - 30.0 * x2 / 5040 + 126.0 * x2 * x2 / 362880, 2 * kEps / 20);
    EXPECT_NEAR(sinc(x), 1.0 - x2 / 6 + x2 * x2 / 120, kEps);
  }
  EXPECT_EQ(u3(0.0), 1.0 / 6);
  EXPECT_EQ(a4(0.0), 1.0 / 20);
  EXPECT_EQ(sinc(0.0), 1.0);
}

TEST(Series, NoJumpAtTheSwitches) {
  // Either side of each threshold the two branches agree to rounding: the step across the
  // switch is no larger than the function's own change over 2 ulp of argument plus 8 ulp.
  struct Case { double (*f)(double); double t; };
  for (const Case c : {Case{u3, kU3SeriesBelow}, Case{a4, kA4SeriesBelow},
                       Case{sinc, kSincSeriesBelow}}) {
    const double below = c.f(std::nextafter(c.t, 0.0));
    const double above = c.f(c.t);
    EXPECT_LE(std::abs(above - below), 8 * kEps * std::abs(above)) << "threshold " << c.t;
  }
}

TEST(Series, EvenFunctions) {
  for (double x : {0.3, 1.7, 2.5, 11.0}) {
    EXPECT_EQ(u3(x), u3(-x));
    EXPECT_EQ(a4(x), a4(-x));
    EXPECT_EQ(sinc(x), sinc(-x));
  }
}

}  // namespace
}  // namespace odomcov::series
