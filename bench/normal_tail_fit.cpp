// Where the far-tail polynomial of src/base/normal_icdf-inl.hpp comes from. Giles' single-
// precision erfinv [Giles11] covers w = -log(1 - x^2) < 16.6 (|z| < 5.4); the generator's grid
// reaches w = 31 log 2 = 21.5 (|z| = 6.34), where Giles' tail polynomial is 4e-4 off. This program
// fits erfinv(x)/x as a polynomial in t = sqrt(w) - 4.3 over w in [16, 21.6] by least squares in
// relative error at 400 Chebyshev points of sqrt(w), in long double with Boost.Math's erfc^-1 as
// the truth (1 - x = e^-w / (1 + x), no cancellation), and prints the coefficients rounded to
// float (highest degree first) with the largest relative error of their float Horner evaluation
// over the interval. Run: normal_tail_fit [degree = 4].
#include <boost/math/special_functions/erf.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {

using Real = long double;

/// erfinv(x)/x where 1 - x^2 = e^-w.
Real target(Real w) {
  const Real e = std::exp(-w);
  const Real x = std::sqrt(1 - e);
  return boost::math::erfc_inv(e / (1 + x)) / x;
}

}  // namespace

int main(int argc, char** argv) {
  const int degree = argc > 1 ? std::atoi(argv[1]) : 4;
  const Real w0 = 16, w1 = 21.6L, center = 4.3L;
  const int points = 400;
  const int n = degree + 1;
  // Normal equations of the weighted least squares: rows t^j / f(w), right-hand side 1.
  std::vector<std::vector<Real>> a(n, std::vector<Real>(n + 1, 0));
  const Real s0 = std::sqrt(w0), s1 = std::sqrt(w1);
  for (int i = 0; i < points; ++i) {
    const Real s =
        (s0 + s1) / 2 + (s1 - s0) / 2 * std::cos(3.14159265358979323846L * (i + 0.5L) / points);
    const Real f = target(s * s), t = s - center;
    std::vector<Real> row(n);
    Real power = 1;
    for (int j = 0; j < n; ++j, power *= t) row[j] = power / f;
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) a[r][c] += row[r] * row[c];
      a[r][n] += row[r];
    }
  }
  for (int i = 0; i < n; ++i) {
    for (int r = i + 1; r < n; ++r) {
      const Real m = a[r][i] / a[i][i];
      for (int c = i; c <= n; ++c) a[r][c] -= m * a[i][c];
    }
  }
  std::vector<Real> coef(n);
  for (int i = n - 1; i >= 0; --i) {
    Real v = a[i][n];
    for (int c = i + 1; c < n; ++c) v -= a[i][c] * coef[c];
    coef[i] = v / a[i][i];
  }
  std::vector<float> rounded(n);
  for (int j = 0; j < n; ++j) rounded[j] = static_cast<float>(coef[j]);
  Real worst = 0;
  for (int i = 0; i <= 4000; ++i) {
    const Real s = s0 + (s1 - s0) * i / 4000;
    const float t = static_cast<float>(s) - static_cast<float>(center);
    float p = rounded[n - 1];
    for (int j = n - 2; j >= 0; --j) p = rounded[j] + p * t;
    const Real f = target(s * s);
    worst = std::fmax(worst, std::fabs((p - f) / f));
  }
  std::printf(
      "erfinv(x)/x ~ p(sqrt(w) - %.1Lf), w in [%.1Lf, %.1Lf], degree %d: largest relative "
      "error %.3Lg (float coefficients, float Horner)\n",
      center, w0, w1, degree, worst);
  for (int j = n - 1; j >= 0; --j)
    std::printf("  t^%d: %.9g\n", j, static_cast<double>(rounded[j]));
  return 0;
}
