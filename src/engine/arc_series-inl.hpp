// The sample step's polynomials and pose update as templates over the value type (see
// arc_step.hpp). No include guard on purpose: included once inside namespace odomcov::arc (the
// scalar reference) and once inside each Highway target's namespace (lane_kernel-inl.hpp), so
// every instruction set compiles its own copy under its own target options. The constants are
// arc_step.hpp's.
// NOLINTBEGIN(llvm-header-guard)

/// A pose as the step carries it: position, heading as a unit vector, heading angle. (Here and
/// not in arc_step.hpp, so a SIMD target's poses are built under its own target options; the
/// constructors are user-provided because GCC compiles implicit ones without them.)
template <class V>
struct Pose {
  V x, y, c, s, theta;
  inline __attribute__((always_inline)) Pose() {}
  inline __attribute__((always_inline)) Pose(V x0, V y0, V c0, V s0, V theta0)
      : x(x0), y(y0), c(c0), s(s0), theta(theta0) {}
};

/// The polynomials. `k` turns a double constant into a V (identity for scalars, a broadcast for
/// vectors), so scalars and vectors evaluate the same expression tree.
template <class V, class K>
inline __attribute__((always_inline)) V sin_taylor(V eps, V e2, K k) {
  using namespace ::odomcov::arc::constants;
  return eps * (k(1.0) + e2 * (k(kSin1) + e2 * (k(kSin2) + e2 * (k(kSin3) + e2 * k(kSin4)))));
}
template <class V, class K>
inline __attribute__((always_inline)) V cos_taylor(V e2, K k) {
  using namespace ::odomcov::arc::constants;
  return k(1.0) + e2 * (k(kCos1) + e2 * (k(kCos2) + e2 * (k(kCos3) + e2 * k(kCos4))));
}
template <class V, class K>
inline __attribute__((always_inline)) V sinc_series(V h2, K k) {
  using namespace ::odomcov::arc::constants;
  return k(1.0) +
         h2 * (k(kSinc1) +
               h2 * (k(kSinc2) +
                     h2 * (k(kSinc3) +
                           h2 * (k(kSinc4) + h2 * (k(kSinc5) + h2 * (k(kSinc6) + h2 * k(kSinc7)))))));
}

/// The short series (LegStep::short_series): the long ones' leading terms.
template <class V, class K>
inline __attribute__((always_inline)) V sin_short(V eps, V e2, K k) {
  using namespace ::odomcov::arc::constants;
  return eps * (k(1.0) + e2 * (k(kSin1) + e2 * k(kSin2)));
}
template <class V, class K>
inline __attribute__((always_inline)) V cos_short(V e2, K k) {
  using namespace ::odomcov::arc::constants;
  return k(1.0) + e2 * (k(kCos1) + e2 * (k(kCos2) + e2 * k(kCos3)));
}
template <class V, class K>
inline __attribute__((always_inline)) V sinc_short(V h2, K k) {
  using namespace ::odomcov::arc::constants;
  return k(1.0) + h2 * (k(kSinc1) + h2 * (k(kSinc2) + h2 * k(kSinc3)));
}

/// The rest of the step once cos h, sin h and sinc h are known.
template <class V>
inline __attribute__((always_inline)) void advance(Pose<V>& p, V ds, V ch, V sh, V sinc, V h) {
  const V chord = ds * sinc;
  const V mc = p.c * ch - p.s * sh;
  const V ms = p.s * ch + p.c * sh;
  p.x = p.x + chord * mc;
  p.y = p.y + chord * ms;
  p.c = mc * ch - ms * sh;
  p.s = ms * ch + mc * sh;
  p.theta = p.theta + (h + h);
}

/// The same with a lateral slip `lat` per sample, spread along the arc as the travel is: the
/// displacement is (ds + i lat) sinc(h) at heading theta + h (effects' Systematic, "lateral").
/// A leg without slip takes advance, so its bits do not depend on this formula.
template <class V>
inline __attribute__((always_inline)) void advance_lateral(Pose<V>& p, V ds, V lat, V ch, V sh,
                                                           V sinc, V h) {
  const V chord = ds * sinc;
  const V side = lat * sinc;
  const V mc = p.c * ch - p.s * sh;
  const V ms = p.s * ch + p.c * sh;
  p.x = p.x + (chord * mc - side * ms);
  p.y = p.y + (chord * ms + side * mc);
  p.c = mc * ch - ms * sh;
  p.s = ms * ch + mc * sh;
  p.theta = p.theta + (h + h);
}

// NOLINTEND(llvm-header-guard)
