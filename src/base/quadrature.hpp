// Gauss-Legendre quadrature on [0, 1], for the engine's damped integrals and the tests' oracle.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <utility>

namespace odomcov {

/// Nodes and weights of the n-point Gauss-Legendre rule on [0, 1], by Newton iteration on P_n
/// from Tricomi's initial guesses (Golub-Welsch is not needed at these n).
template <int n>
std::array<std::pair<double, double>, n> gauss_legendre_01() {
  std::array<std::pair<double, double>, n> xw{};
  for (int i = 0; i < n; ++i) {
    double z = std::cos(M_PI * (i + 0.75) / (n + 0.5));
    double dp = 0.0;
    for (int it = 0; it < 100; ++it) {
      double p0 = 1.0, p1 = z;
      for (int k = 2; k <= n; ++k) {
        const double p2 = ((2.0 * k - 1.0) * z * p1 - (k - 1.0) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      dp = n * (z * p1 - p0) / (z * z - 1.0);
      const double step = p1 / dp;
      z -= step;
      if (std::abs(step) < 1e-16) break;
    }
    // 2/((1 - z^2) P_n'(z)^2) on [-1, 1], halved for [0, 1].
    xw[static_cast<std::size_t>(i)] = {0.5 * (1.0 - z), 1.0 / ((1.0 - z * z) * dp * dp)};
  }
  return xw;
}

}  // namespace odomcov
