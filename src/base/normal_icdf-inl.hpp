// Standard normals from 32-bit random words by inversion, as a template over the arithmetic (`O`:
// the scalar ops of random.hpp, or one SIMD target's in lane_kernel-inl.hpp), so the scalar
// generator and every instruction set evaluate the same expression tree with IEEE single-precision
// + - * / and sqrt, conversions, integer and bit operations only: no C library function, no fused
// multiply-add (the build has -ffp-contract=off), hence the same bits on every instruction set and
// machine.
//
// A word's bit 31 is the sign and bits 0-30 (m) the magnitude: x = +-(1 - a) with
// a = (m + 1/2) 2^-31, so |x| lies on a grid of 2^31 points in (0, 1) and the normal is
// z = sqrt(2) erfinv(x), the inverse of the normal CDF at (1 + x)/2. a and |x| are each built from
// an integer (m and its complement), so both keep full relative precision. w = -log((1-|x|)(1+|x|))
// in [0, 21.5] then selects one of three polynomials p(w) ~ erfinv(x)/x:
//   w < 5        (|z| < 2.93, 99.63% of draws): Giles' central polynomial in w - 2.5 [Giles11];
//   5 <= w < 16  (|z| < 5.39):                  Giles' tail polynomial in sqrt(w) - 3;
//   w >= 16      (6.8e-8 of draws):             ours in sqrt(w) - 4.3, fitted by
//                                               bench/normal_tail_fit.cpp where Giles' single-
//                                               precision fit ends (it is 4e-4 off at |z| = 6.3).
// The log reduces y to 2^e m with m in [sqrt(1/2), sqrt(2)) and takes log m = 2 atanh((m-1)/(m+1))
// by a short polynomial (w needs an absolute, not a relative, accuracy). Every normal is within
// 3.5e-7 relative of the exact quantile at its grid point (bench/normal_icdf_accuracy checks all
// 2^32 words); |z| <= 6.34.
// No include guard on purpose: included once per namespace that instantiates it (a SIMD target
// must compile its own copy under its own target options).
// NOLINTBEGIN(llvm-header-guard)

/// p(w) for w >= 5 (a lane below 5 gets a value that is not used). Rare: 0.37% of draws, 5.7% of
/// vectors of 16, so out of line.
template <class O>
__attribute__((noinline)) typename O::F normal_icdf_tail(typename O::F w) {
  using F = typename O::F;
  const F s = O::sqrt(w);
  const F u = s - O::f(3.0f);
  F q = O::f(-0.000200214257f);
  q = O::f(0.000100950558f) + q * u;
  q = O::f(0.00134934322f) + q * u;
  q = O::f(-0.00367342844f) + q * u;
  q = O::f(0.00573950773f) + q * u;
  q = O::f(-0.0076224613f) + q * u;
  q = O::f(0.00943887047f) + q * u;
  q = O::f(1.00167406f) + q * u;
  q = O::f(2.83297682f) + q * u;
  const auto far = O::ge(w, O::f(16.0f));
  if (O::any(far)) {
    const F v = s - O::f(4.3f);
    F g = O::f(0.000193632746f);
    g = O::f(-0.000574445934f) + g * v;
    g = O::f(0.000625014596f) + g * v;
    g = O::f(1.01004529f) + g * v;
    g = O::f(4.14272404f) + g * v;
    q = O::select(far, g, q);
  }
  return q;
}

/// 2 atanh(s)/s as a polynomial in s^2, s in [-0.1716, 0.1716] (the log of normal_icdf).
inline constexpr float kLogQ[4] = {2.0f, 0.666668177f, 0.399748415f, 0.299245894f};

/// `O` provides: types F (float values) and I (int32 values); constants f(float), i(int32);
/// to_float(I) (int32 -> float, round to nearest), bits(F) and from_bits(I) (reinterpretation),
/// shr23(I) (arithmetic shift right by 23), shl23(I); sqrt(F); ge(F, F) -> a mask, any(mask),
/// select(mask, F yes, F no); And(I, I), Xor(I, I); and + - * on F and - on I.
///
/// Converts N values at once, each step of the polynomials applied to all N before the next: N
/// independent dependency chains, interleaved (one Horner chain at a time is latency-bound).
/// Each value's arithmetic is the same whatever N.
template <class O, int N>
inline __attribute__((always_inline)) void normal_icdf(const typename O::I (&word)[N],
                                                       typename O::F (&z)[N]) {
  using F = typename O::F;
  using I = typename O::I;
  F ax[N], y[N], p[N];
  for (int j = 0; j < N; ++j) {
    const I m = O::And(word[j], O::i(0x7FFFFFFF));
    const I mc = O::Xor(m, O::i(0x7FFFFFFF));                      // 2^31 - 1 - m
    const F a = O::to_float(m) * O::f(0x1p-31f) + O::f(0x1p-32f);  // 1 - |x|
    ax[j] = O::to_float(mc) * O::f(0x1p-31f) + O::f(0x1p-32f);     // |x|
    y[j] = a * (O::f(1.0f) + ax[j]);                               // 1 - x^2
  }
  // log y = e log 2 + 2 atanh(s), y = 2^e m, m in [sqrt(1/2), sqrt(2)) (e from the exponent of
  // y / sqrt(1/2)), s = (m - 1)/(m + 1) in [-0.1716, 0.1716], 2 atanh(s) = s Q(s^2) with Q of
  // degree 3, fitted (least squares in relative error; bench/normal_tail_fit.cpp --log) to an
  // absolute error of 3.2e-8 in float. w's absolute error moves z by under 0.3 of it relatively.
  F s[N], s2[N], fe[N];
  for (int j = 0; j < N; ++j) {
    const I b = O::bits(y[j]);
    const I e = O::shr23(b - O::i(0x3F3504F3));
    const F m = O::from_bits(b - O::shl23(e));
    s[j] = (m - O::f(1.0f)) / (m + O::f(1.0f));
    fe[j] = O::to_float(e);
    s2[j] = s[j] * s[j];
    p[j] = O::f(kLogQ[3]);
  }
  for (int c = 2; c >= 0; --c) {
    for (int j = 0; j < N; ++j) p[j] = O::f(kLogQ[c]) + p[j] * s2[j];
  }
  F w[N], t[N];
  for (int j = 0; j < N; ++j) {
    // log 2 = 0.693359375 - 2.12194440e-4, the first part exact in float; w = -log y >= 0.
    w[j] =
        O::f(0.0f) - (fe[j] * O::f(0.693359375f) + (s[j] * p[j] + fe[j] * O::f(-2.12194440e-4f)));
    t[j] = w[j] - O::f(2.5f);
    p[j] = O::f(2.81022636e-08f);
  }
  constexpr float kCentral[] = {3.43273939e-07f, -3.5233877e-06f, -4.39150654e-06f, 0.00021858087f,
                                -0.00125372503f, -0.00417768164f, 0.246640727f,     1.50140941f};
  for (const float c : kCentral) {
    for (int j = 0; j < N; ++j) p[j] = O::f(c) + p[j] * t[j];
  }
  for (int j = 0; j < N; ++j) {
    const auto tail = O::ge(w[j], O::f(5.0f));
    if (O::any(tail)) p[j] = O::select(tail, normal_icdf_tail<O>(w[j]), p[j]);
    const F v = (p[j] * ax[j]) * O::f(1.41421356237309505f);
    z[j] = O::from_bits(O::Xor(O::bits(v), O::And(word[j], O::i(INT32_MIN))));
  }
}

// NOLINTEND(llvm-header-guard)
