// exp(a) for the ziggurat's wedge test, |a| <= 0.73 (the widest block, i = 1: see random.cpp),
// as a template over the value type: the scalar ziggurat (random.cpp) and each SIMD target of the
// simulator's kernel (src/engine/lane_kernel-inl.hpp) compile the same evaluation of the Taylor
// polynomial through a^17 (the first omitted term is < 5e-19 at |a| = 0.73; Estrin's scheme, a
// short dependency chain, rounding within a few ulp), with IEEE + and * only, so every
// instruction set and every machine decides the wedge test the same way.
// No include guard on purpose: included once per namespace that instantiates it (a SIMD target
// must compile its own copy under its own target options).
// NOLINTBEGIN(llvm-header-guard)

/// `k` turns a double constant into a V (identity for scalars, a broadcast for vectors).
template <class V, class K>
inline __attribute__((always_inline)) V wedge_exp(V a, K k) {
  // 1/j! for j = 0..17, each correctly rounded (j! is exact in a double up to 22!).
  constexpr double kInvFactorial[18] = {
      1.0,           1.0,           1.0 / 2,       1.0 / 6,        1.0 / 24,       1.0 / 120,
      1.0 / 720,     1.0 / 5040,    1.0 / 40320,   1.0 / 362880,   1.0 / 3628800,  1.0 / 39916800,
      1.0 / 479001600, 1.0 / 6227020800, 1.0 / 87178291200, 1.0 / 1307674368000,
      1.0 / 20922789888000, 1.0 / 355687428096000};
  const V a2 = a * a;
  const V a4 = a2 * a2;
  const V a8 = a4 * a4;
  V q[9];
  for (int j = 0; j < 9; ++j) q[j] = k(kInvFactorial[2 * j]) + a * k(kInvFactorial[2 * j + 1]);
  const V r0 = q[0] + a2 * q[1], r1 = q[2] + a2 * q[3], r2 = q[4] + a2 * q[5],
          r3 = q[6] + a2 * q[7];
  const V s0 = r0 + a4 * r1, s1 = r2 + a4 * r3;
  return (s0 + a8 * s1) + (a8 * a8) * q[8];
}

// NOLINTEND(llvm-header-guard)
