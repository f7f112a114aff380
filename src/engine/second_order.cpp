// The order-2 model: the exact mean and covariance of the end-pose error for Gaussian noise
// (include/odomcov/engine/second_order.hpp; derivation in docs/orders.md).
//
// Notation. The path is a chain of constant-curvature pieces k = 0..K-1 (after effects::resolve:
// true centre travel d_k, true heading change a_k). A global parameter t runs over [k, k+1] on
// piece k, u = t - k. Along the true (systematic) path the heading is theta_bar(t) =
// theta_bar_k + a_k u and the noise-free centre travel is d_k dt. The noise of piece k is
//   * white: (dw_theta, dw_d) with intensity I_k (2x2 = resolved intensity: the covariance of
//     (e_dtheta, e_d) accumulated over the piece), spread uniformly in u;
//   * per-run: c ~ N(0, I_m), entering (e_dtheta, e_d) through the columns G_k (2 x m) per unit t.
// The heading error and the along-track noise are then
//   phi(t) = int_0^t dw_theta + g(t).c,   g(t) = sum_{j<k} G_k^theta + G_k^theta u   (m-vector)
//   dn(t)  = dw_d(t) + (G_k^d . c) dt,
// all jointly Gaussian with zero mean, and in complex notation (z = x + i y, world frame)
//   p = int exp(i theta_bar(t) + i phi(t)) (d(t) dt + dn(t))                        (1)
// (Stratonovich: the simulator's arc update uses the mid-sample heading). Define
//   W(t) = int_0^t I_tt,  V(t) = Var phi(t) = W(t) + |g(t)|^2,
//   C(s,t) = Cov(phi(s), phi(t)) = W(min(s,t)) + g(s).g(t),
//   Cov(phi(r), dn(s))/ds = I_td(s) H(r - s) + g(r).G^d(s),   H(0) = 1/2 (mid-sample),
//   Cov(dn(s), dn(t)) = I_dd(s) delta(s - t) ds + G^d(s).G^d(t) ds dt.
// Two Gaussian facts do everything: for zero-mean jointly Gaussian psi, X, Y,
//   E[exp(i psi)] = exp(-Var psi / 2),
//   E[X f(psi)] = Cov(X, psi) E[f'(psi)],
//   E[X Y f(psi)] = Cov(X, Y) E[f(psi)] + Cov(X, psi) Cov(Y, psi) E[f''(psi)]   (Stein's lemma).
//
// Mean (A(t) = exp(i theta_bar(t)), m(t) = Cov(phi(t), dn(t))/dt = I_td/2 + g(t).G^d):
//   E[p] = int A e^{-V/2} (d + i m) dt,
//   E[p] - p_bar = int A [expm1(-V/2) (d + i m) + i m] dt                               (2)
// with p_bar the noise-free true path's end, composed exactly (arc_displacement).
//
// Second moments. For s < t let psi_-+ = phi(s) -+ phi(t); Var psi_-+ = V(s) + V(t) -+ 2 C(s,t).
//   kappa_s = Cov(psi_-, dn(s))/ds = -I_td(s)/2 + (g(s) - g(t)).G^d(s)
//   kappa_t = Cov(psi_-, dn(t))/dt = -I_td(t)/2 + (g(s) - g(t)).G^d(t)
//   lambda_s = Cov(psi_+, dn(s))/ds = 3 I_td(s)/2 + (g(s) + g(t)).G^d(s)
//   lambda_t = Cov(psi_+, dn(t))/dt =   I_td(t)/2 + (g(s) + g(t)).G^d(t)
// and with Gdd = G^d(s).G^d(t),
//   X_- = d_s d_t + i d_t kappa_s + i d_s kappa_t + Gdd - kappa_s kappa_t,
//   X_+ = d_s d_t + i d_t lambda_s + i d_s lambda_t + Gdd - lambda_s lambda_t,
//   Y_-+ = (d_s + i m_s)(d_t -+ i m_t)       (the product of the means' integrands).
// Then, with E_st = exp(-(V(s) + V(t))/2) and C = C(s,t),
//   Cov(p, conj p) = 2 Re int_{s<t} A_s conj(A_t) E_st [expm1(C) X_- + (X_- - Y_-)]
//                    + int I_dd dt                                                      (3)
//   Cov(p, p)      = 2 int_{s<t} A_s A_t E_st [expm1(-C) X_+ + (X_+ - Y_+)]
//                    + int A^2 exp(-2V) I_dd dt                                         (4)
// (the (t, s) half is the conjugate resp. the same; the delta terms are the single integrals),
// where the differences are formed symbolically so that nothing cancels at small noise:
//   X_- - Y_- = i d_t (-I_td(s) - g(t).G^d(s)) + i d_s g(s).G^d(t) + Gdd - kappa_s kappa_t - m_s m_t
//   X_+ - Y_+ = i d_t ( I_td(s) + g(t).G^d(s)) + i d_s g(s).G^d(t) + Gdd - lambda_s lambda_t + m_s m_t
// Heading: theta_end - theta_bar_end = phi(T), so Var = V(T) and
//   Cov(p, phi(T)) = int A e^{-V/2} [i d C(T,s) + I_td + g(T).G^d - C(T,s) m] ds.          (5)
// World covariance: x = Re p, y = Im p:
//   Cov(x,x) = (Cov(p,conj p) + Re Cov(p,p))/2, Cov(y,y) = (Cov(p,conj p) - Re Cov(p,p))/2,
//   Cov(x,y) = Im Cov(p,p)/2, Cov(x,theta) + i Cov(y,theta) = Cov(p, phi(T)).
// Linearising (expm1(C) -> C, exp(-V/2) -> 1, dropping products of noise terms) gives back the
// first-order engine's covariance (tested), so order 2 reduces to order 1 as the noise -> 0.
//
// Lateral slip (effects' Systematic::lateral). A piece that slips l to the left per unit t moves
// by (d + i l) dt, and a per-run constant may move the slip too (the lateral row of its columns,
// G^l). Everything above holds with complex values: D = d + i l for d, the complex along-track
// noise dN = dn + i (G^l.c) dt for dn (Stein's lemma is linear in X, Y), so with
// G^d -> G^d + i G^l, m = Cov(phi, dN)/dt and kappa, lambda complex, and in (3) the conjugate
// factor's terms conjugated:
//   X_- = D_s conj(D_t) + i conj(D_t) kappa_s + i D_s kappa~_t + G^d(s).conj(G^d(t)) - kappa_s kappa~_t,
//   kappa~_t = conj(-I_td(t)/2 + (g(s) - g(t)).G^d(t)),
//   X_- - Y_- = i conj(D_t) (-I_td(s) - g(t).G^d(s)) + i D_s conj(g(s).G^d(t))
//               + G^d(s).conj(G^d(t)) - kappa_s kappa~_t - m_s conj(m_t),
//   X_+ = D_s D_t + i D_t lambda_s + i D_s lambda_t + G^d(s).G^d(t) - lambda_s lambda_t,
//   X_+ - Y_+ = i D_t (I_td(s) + g(t).G^d(s)) + i D_s g(s).G^d(t) + G^d(s).G^d(t) - lambda_s lambda_t
//               + m_s m_t,
// the mean's integrand A e^{-V/2} (D + i m) and (5)'s A e^{-V/2} [i D C + I_td + g(T).G^d - C m]. The
// white I_dd terms are unchanged (the slip has no white part). Without any slip the real
// formulas above are used as they are (add_pair, add_separable_pairs); with one, their complex
// forms (add_pair_lateral, add_separable_pairs_lateral).
//
// Quadrature: Q Gauss-Legendre nodes per piece in t. Off-diagonal blocks (s in an earlier piece
// than t) are smooth tensor products. On a diagonal block the integrand has a kink at s = t
// (min, H), so the triangle s < t is mapped to the square, t = k + v, s = k + v w, ds dt = v dv dw,
// where it is smooth. Cost: (QK)^2/2 + K Q^2 pair evaluations.
#include "odomcov/engine/second_order.hpp"

#include "odomcov/closed_form/limits.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <stdexcept>
#include <complex>

#include "effects/effect.hpp"
#include "closed_form/arc_functions.hpp"
#include "base/quadrature.hpp"
#include "base/series.hpp"

namespace odomcov {
namespace {

using Complex = std::complex<double>;
constexpr int kQ = kSecondOrderNodes;

/// One resolved piece in the form the integrals use.
struct Piece {
  double heading0 = 0.0;  // theta_bar at the piece start
  Complex rotation0 = 1.0;  // exp(i heading0)
  double a = 0.0;         // true heading change
  double d = 0.0;         // true centre travel (per unit t)
  double l = 0.0;         // true lateral slip (per unit t)
  double w0 = 0.0;        // W at the piece start
  double i_tt = 0.0, i_td = 0.0, i_dd = 0.0;
  int g0 = 0;  // offset of g at the piece start in `g_start`, of G^theta, G^d in the column arrays
};

/// The state at one quadrature point.
struct Node {
  Complex A;          // exp(i theta_bar)
  double d = 0.0;
  double W = 0.0;     // white heading variance
  double V = 0.0;     // total heading variance
  double i_td = 0.0;
  double m = 0.0;     // I_td/2 + g.G^d
  double g_gd = 0.0;  // g.G^d (own piece)
  double weight = 0.0;
  double half_damping = 0.0;  // exp(-V/2)
  double expm1_W = 0.0;       // expm1(W): C(s, t) for s < t when there are no per-run constants
  const double* g = nullptr;   // m entries
  const double* gd = nullptr;  // m entries, G^d of the node's piece
  // The lateral slip's parts (zero without one): l, G^l and g.G^l, so that the complex forms
  // are D = d + i l, G^d + i G^l, m + i g_gl.
  double l = 0.0;
  double g_gl = 0.0;
  const double* gl = nullptr;  // m entries, G^l of the node's piece
};

struct Model {
  std::vector<Piece> pieces;
  int m = 0;                     // per-run constants
  std::vector<double> g_start;   // K x m: g at each piece start, then g(T) at index K
  std::vector<double> g_theta;   // K x m
  std::vector<double> g_d;       // K x m
  std::vector<double> g_l;       // K x m
  double w_end = 0.0;            // W(T)
  bool lateral = false;          // some piece slips or some column moves the slip
  Vector3 true_end_pose = Vector3::Zero();  // of the systematic path
  Vector3 odometry_end_pose = Vector3::Zero();
  double i_dd_total = 0.0;       // sum of the pieces' I_dd
};

double dot(const double* x, const double* y, int m) {
  double s = 0.0;
  for (int i = 0; i < m; ++i) s += x[i] * y[i];
  return s;
}

/// Fills `node` at fraction u of piece k; `g_buffer` receives g(t) (m entries). Inlined: it
/// runs Q^2 times per piece in the diagonal blocks.
inline __attribute__((always_inline)) void make_node(const Model& model, std::size_t k, double u,
                                                     double weight, double* g_buffer, Node& node) {
  const Piece& p = model.pieces[k];
  const int m = model.m;
  const double* g0 = model.g_start.data() + k * static_cast<std::size_t>(m);
  const double* gt = model.g_theta.data() + k * static_cast<std::size_t>(m);
  for (int i = 0; i < m; ++i) g_buffer[i] = g0[i] + gt[i] * u;
  node.A = detail::times(p.rotation0, detail::unit_complex(p.a * u));
  node.d = p.d;
  node.W = p.w0 + p.i_tt * u;
  node.V = node.W + dot(g_buffer, g_buffer, m);
  node.i_td = p.i_td;
  node.gd = model.g_d.data() + k * static_cast<std::size_t>(m);
  node.g = g_buffer;
  node.g_gd = dot(g_buffer, node.gd, m);
  node.m = 0.5 * p.i_td + node.g_gd;
  node.l = p.l;
  node.gl = model.g_l.data() + k * static_cast<std::size_t>(m);
  node.g_gl = dot(g_buffer, node.gl, m);
  node.weight = weight;
  node.half_damping = 1.0 + series::expm1_small(-0.5 * node.V);
  node.expm1_W = series::expm1_small(node.W);
}

/// Adds the integrands of (3) and (4) for one pair s < t, times `weight`.
inline void add_pair(const Node& s, const Node& t, int m, double weight, Complex& sum_conj,
                     Complex& sum_plain) {
  double gs_gt = 0.0, gt_gds = 0.0, gs_gdt = 0.0, gds_gdt = 0.0;
  for (int i = 0; i < m; ++i) {
    gs_gt += s.g[i] * t.g[i];
    gt_gds += t.g[i] * s.gd[i];
    gs_gdt += s.g[i] * t.gd[i];
    gds_gdt += s.gd[i] * t.gd[i];
  }
  // C(s, t) = W(s) + g(s).g(t) for s < t: without per-run constants a property of s alone.
  // expm1(-C) = -expm1(C) / (1 + expm1(C)), exact and as accurate at small C.
  const double em = m == 0 ? s.expm1_W : std::expm1(s.W + gs_gt);
  const double em_minus = -em / (1.0 + em);
  const double e = weight * s.half_damping * t.half_damping;
  const double kappa_s = -0.5 * s.i_td + s.g_gd - gt_gds;
  const double kappa_t = -0.5 * t.i_td + gs_gdt - t.g_gd;
  const double lambda_s = 1.5 * s.i_td + s.g_gd + gt_gds;
  const double lambda_t = 0.5 * t.i_td + gs_gdt + t.g_gd;
  const double dd = s.d * t.d;
  const Complex x_minus(dd + gds_gdt - kappa_s * kappa_t, t.d * kappa_s + s.d * kappa_t);
  const Complex x_plus(dd + gds_gdt - lambda_s * lambda_t, t.d * lambda_s + s.d * lambda_t);
  const double imag_common = s.d * gs_gdt;
  const Complex diff_minus(gds_gdt - kappa_s * kappa_t - s.m * t.m,
                           t.d * (-s.i_td - gt_gds) + imag_common);
  const Complex diff_plus(gds_gdt - lambda_s * lambda_t + s.m * t.m,
                          t.d * (s.i_td + gt_gds) + imag_common);
  sum_conj += detail::times(detail::times(s.A, std::conj(t.A)), e * (em * x_minus + diff_minus));
  sum_plain += detail::times(detail::times(s.A, t.A), e * (em_minus * x_plus + diff_plus));
}

/// add_pair summed over every pair of nodes in different pieces (s in the earlier one), when
/// there are no per-run constants (m = 0). Then C(s, t) = W(s) and every factor of the
/// integrands is a product of a function of s and one of t: with i_s = I_td(s), i_t = I_td(t),
///   (3): conj(A_t) e_t [ d_t S1 + (i_t/2) S2 ],  S1 = sum_s A_s e_s w_s (em d_s - i em i_s/2 - i i_s),
///                                                S2 = sum_s A_s e_s w_s (-i em d_s - em i_s/2 - i_s),
///   (4): A_t e_t [ d_t T1 + (i_t/2) T2 ],        T1 = sum_s A_s e_s w_s (emm d_s + 3i emm i_s/2 + i i_s),
///                                                T2 = sum_s A_s e_s w_s (i emm d_s - 3 emm i_s/2 - i_s)
/// (em = expm1(W_s), emm = expm1(-W_s), e = exp(-V/2), w the weights), with S, T summed over
/// the earlier pieces: O(nodes) instead of O(nodes^2), the same sums regrouped.
void add_separable_pairs(const std::vector<Node>& nodes, Complex& sum_conj, Complex& sum_plain) {
  Complex S1 = 0.0, S2 = 0.0, T1 = 0.0, T2 = 0.0;
  for (std::size_t first = 0; first < nodes.size(); first += kQ) {
    for (std::size_t b = first; b < first + kQ; ++b) {
      const Node& t = nodes[b];
      const double et = t.weight * t.half_damping;
      sum_conj += detail::times(std::conj(t.A) * et, t.d * S1 + 0.5 * t.i_td * S2);
      sum_plain += detail::times(t.A * et, t.d * T1 + 0.5 * t.i_td * T2);
    }
    for (std::size_t a = first; a < first + kQ; ++a) {
      const Node& s = nodes[a];
      const Complex p = s.A * (s.weight * s.half_damping);
      const double em = s.expm1_W, emm = -em / (1.0 + em), is = s.i_td;
      S1 += detail::times(p, Complex(em * s.d, -0.5 * em * is - is));
      S2 += detail::times(p, Complex(-0.5 * em * is - is, -em * s.d));
      T1 += detail::times(p, Complex(emm * s.d, 1.5 * emm * is + is));
      T2 += detail::times(p, Complex(-1.5 * emm * is - is, emm * s.d));
    }
  }
}

constexpr Complex kI(0.0, 1.0);

/// add_pair with a lateral slip: the complex forms of the header's formulas.
void add_pair_lateral(const Node& s, const Node& t, int m, double weight, Complex& sum_conj,
                      Complex& sum_plain) {
  double gs_gt = 0.0;
  Complex gt_gds = 0.0, gs_gdt = 0.0, hermitian = 0.0, plain = 0.0;
  for (int i = 0; i < m; ++i) {
    const Complex gds(s.gd[i], s.gl[i]), gdt(t.gd[i], t.gl[i]);
    gs_gt += s.g[i] * t.g[i];
    gt_gds += t.g[i] * gds;
    gs_gdt += s.g[i] * gdt;
    hermitian += gds * std::conj(gdt);
    plain += gds * gdt;
  }
  const double em = m == 0 ? s.expm1_W : std::expm1(s.W + gs_gt);
  const double em_minus = -em / (1.0 + em);
  const double e = weight * s.half_damping * t.half_damping;
  const Complex s_ggd(s.g_gd, s.g_gl), t_ggd(t.g_gd, t.g_gl);
  const Complex Ds(s.d, s.l), Dt(t.d, t.l);
  const Complex ms(s.m, s.g_gl), mt(t.m, t.g_gl);
  const Complex kappa_s = -0.5 * s.i_td + s_ggd - gt_gds;
  const Complex kappa_t = std::conj(-0.5 * t.i_td + gs_gdt - t_ggd);
  const Complex lambda_s = 1.5 * s.i_td + s_ggd + gt_gds;
  const Complex lambda_t = 0.5 * t.i_td + gs_gdt + t_ggd;
  const Complex x_minus = Ds * std::conj(Dt) + kI * std::conj(Dt) * kappa_s + kI * Ds * kappa_t + hermitian -
                          kappa_s * kappa_t;
  const Complex diff_minus = kI * std::conj(Dt) * (-s.i_td - gt_gds) + kI * Ds * std::conj(gs_gdt) + hermitian -
                             kappa_s * kappa_t - ms * std::conj(mt);
  const Complex x_plus = Ds * Dt + kI * Dt * lambda_s + kI * Ds * lambda_t + plain - lambda_s * lambda_t;
  const Complex diff_plus =
      kI * Dt * (s.i_td + gt_gds) + kI * Ds * gs_gdt + plain - lambda_s * lambda_t + ms * mt;
  sum_conj += detail::times(detail::times(s.A, std::conj(t.A)), e * (em * x_minus + diff_minus));
  sum_plain += detail::times(detail::times(s.A, t.A), e * (em_minus * x_plus + diff_plus));
}

/// add_separable_pairs with a lateral slip (no per-run constants): D_s = d_s + i l_s for d_s,
/// conj(D_t) for d_t in (3), D_t in (4).
void add_separable_pairs_lateral(const std::vector<Node>& nodes, Complex& sum_conj, Complex& sum_plain) {
  Complex S1 = 0.0, S2 = 0.0, T1 = 0.0, T2 = 0.0;
  for (std::size_t first = 0; first < nodes.size(); first += kQ) {
    for (std::size_t b = first; b < first + kQ; ++b) {
      const Node& t = nodes[b];
      const double et = t.weight * t.half_damping;
      const Complex Dt(t.d, t.l);
      sum_conj += std::conj(t.A) * et * (std::conj(Dt) * S1 + 0.5 * t.i_td * S2);
      sum_plain += t.A * et * (Dt * T1 + 0.5 * t.i_td * T2);
    }
    for (std::size_t a = first; a < first + kQ; ++a) {
      const Node& s = nodes[a];
      const Complex p = s.A * (s.weight * s.half_damping), Ds(s.d, s.l);
      const double em = s.expm1_W, emm = -em / (1.0 + em), is = s.i_td;
      S1 += p * (em * Ds + kI * (-0.5 * em * is - is));
      S2 += p * (-kI * em * Ds + (-0.5 * em * is - is));
      T1 += p * (emm * Ds + kI * (1.5 * emm * is + is));
      T2 += p * (kI * emm * Ds + (-1.5 * emm * is - is));
    }
  }
}

/// The pieces of the order-2 quadrature: runs of identical consecutive pieces (model_pieces
/// cuts each interval into equal parts) are merged, which is exact, and every piece is cut into
/// equal parts (also exact) so that none turns more than kPieceMaxAngle or travels more than
/// kSecondOrderMaxTravel. The integrand varies along a piece as exp(i a u) and exp(-V(u)/2)
/// with V linear, so a travel of 1 m (heading variance 2 k^2/B^2 per metre) keeps the
/// 4-point rule at ~1e-9 relative up to k ~ 0.3 m^1/2.
constexpr double kSecondOrderMaxTravel = 1.0;  // m

/// The mean wheel speed of piece i (NaN without durations).
double speed_of(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s, std::size_t i) {
  const double dt = durations_s.empty() ? std::nan("") : durations_s[i];
  return 0.5 * (std::abs(pieces[i].left_m) + std::abs(pieces[i].right_m)) / dt;
}

std::vector<ArcSegment> refine(const std::vector<ArcSegment>& pieces,
                               const std::vector<double>& durations_s, double wheelbase_m,
                               bool acceleration, std::vector<double>& refined_durations_s) {
  // Durations (when given) follow the pieces: summed where pieces merge, split where they are cut.
  // Pieces merge only at equal durations too, so a piece keeps its speed (a custom effect's v).
  // When an effect uses the acceleration (a piece's speed against the previous piece's), a piece
  // whose speed differs from its predecessor's takes no equal followers: merging would spread
  // its acceleration over them (sample_model_pieces sets such pieces apart).
  const bool timed = !durations_s.empty();
  std::vector<ArcSegment> merged;
  std::vector<double> merged_durations;
  merged.reserve(pieces.size());
  for (std::size_t i = 0; i < pieces.size();) {
    std::size_t j = i + 1;
    const bool merge = !acceleration || (i > 0 && speed_of(pieces, durations_s, i) == speed_of(pieces, durations_s, i - 1));
    while (merge && j < pieces.size() && pieces[j].left_m == pieces[i].left_m &&
           pieces[j].right_m == pieces[i].right_m && (!timed || durations_s[j] == durations_s[i])) {
      ++j;
    }
    const double count = static_cast<double>(j - i);
    merged.push_back({pieces[i].left_m * count, pieces[i].right_m * count});
    if (timed) {
      double span = 0.0;
      for (std::size_t k = i; k < j; ++k) span += durations_s[k];
      merged_durations.push_back(span);
    }
    i = j;
  }
  std::vector<ArcSegment> out;
  out.reserve(merged.size());
  refined_durations_s.clear();
  for (std::size_t m = 0; m < merged.size(); ++m) {
    const ArcSegment& seg = merged[m];
    const double cuts =
        std::max({1.0, std::ceil(std::abs(seg.heading_change_rad(wheelbase_m)) / kPieceMaxAngle),
                  std::ceil(std::abs(seg.center_m()) / kSecondOrderMaxTravel)});
    const int n = static_cast<int>(cuts);
    for (int k = 0; k < n; ++k) {
      out.push_back({seg.left_m / n, seg.right_m / n});
      if (timed) refined_durations_s.push_back(merged_durations[m] / n);
    }
  }
  return out;
}

/// The integrals' model of the resolved pieces: the systematic path's pieces, the white
/// variance accumulated along them, the per-run constants' columns (g at each piece start,
/// G^theta, G^d and G^l per piece), and the true and odometry end poses (nominal wheelbase B).
Model build_model(const effects::ResolvedPath& resolved, double B) {
  const std::size_t K = resolved.pieces.size();
  Model model;
  model.m = resolved.run_constants;
  const std::size_t mm = static_cast<std::size_t>(model.m);
  model.pieces.resize(K);
  model.g_start.assign((K + 1) * mm, 0.0);
  model.g_theta.assign(K * mm, 0.0);
  model.g_d.assign(K * mm, 0.0);
  model.g_l.assign(K * mm, 0.0);
  Vector3 true_pose = Vector3::Zero();
  double w = 0.0;
  for (std::size_t k = 0; k < K; ++k) {
    const effects::ResolvedPiece& r = resolved.pieces[k];
    Piece& p = model.pieces[k];
    p.heading0 = true_pose.z();
    p.rotation0 = std::polar(1.0, p.heading0);
    p.a = r.angle_rad;
    p.d = r.center_m;
    p.l = r.lateral_m;
    p.w0 = w;
    p.i_tt = r.intensity(0, 0);
    p.i_td = r.intensity(0, 1);
    p.i_dd = r.intensity(1, 1);
    model.lateral = model.lateral || p.l != 0.0;
    const auto columns = resolved.columns(k);
    for (std::size_t i = 0; i < mm; ++i) {
      const Eigen::Index col = static_cast<Eigen::Index>(i);
      model.g_theta[k * mm + i] = columns(0, col);
      model.g_d[k * mm + i] = columns(1, col);
      model.g_l[k * mm + i] = columns(2, col);
      model.lateral = model.lateral || columns(2, col) != 0.0;
      model.g_start[(k + 1) * mm + i] = model.g_start[k * mm + i] + columns(0, col);
    }
    w += p.i_tt;
    model.i_dd_total += p.i_dd;
    true_pose = compose(true_pose, detail::arc_displacement(r.center_m, r.lateral_m, detail::ArcStep(r.angle_rad)));
    model.odometry_end_pose = drive(model.odometry_end_pose, r.encoder, B);
  }
  model.w_end = w;
  model.true_end_pose = true_pose;
  return model;
}

/// The single integrals at one node: the mean (2), Cov(p, phi(T)) (5) and the delta part of
/// (4); `g_end` is g(T), `c_end` C(T, s) at the node.
inline __attribute__((always_inline)) void add_single(const Model& model, const Node& x, const double* g_end, double c_end, double i_dd,
                Complex& noise_mean, Complex& cov_p_theta, Complex& diag_plain) {
  const int m = model.m;
  diag_plain += x.weight * x.A * x.A * (1.0 + series::expm1_small(-2.0 * x.V)) * i_dd;
  if (!model.lateral) {
    noise_mean += x.weight * x.A * (series::expm1_small(-0.5 * x.V) * Complex(x.d, x.m) + Complex(0.0, x.m));
    cov_p_theta += x.weight * x.A * x.half_damping *
                   Complex(x.i_td + dot(g_end, x.gd, m) - c_end * x.m, x.d * c_end);
    return;
  }
  const Complex D(x.d, x.l), mean_m(x.m, x.g_gl);
  noise_mean += x.weight * x.A * (series::expm1_small(-0.5 * x.V) * (D + kI * mean_m) + kI * mean_m);
  cov_p_theta += x.weight * x.A * x.half_damping *
                 (Complex(x.i_td + dot(g_end, x.gd, m), dot(g_end, x.gl, m)) - c_end * mean_m + kI * D * c_end);
}

/// The double integrals (3), (4) over s < t: pairs of nodes in different pieces (separable
/// without per-run constants), then each piece's own triangle mapped to the square (header).
/// A template, so that the pair's integrand inlines into the O(nodes^2) loop.
template <bool Lateral>
void add_pairs(const Model& model, const std::vector<Node>& nodes, Complex& sum_conj, Complex& sum_plain) {
  static const auto gl = gauss_legendre_01<kQ>();
  const int m = model.m;
  auto pair = [](const Node& s, const Node& t, int n, double w, Complex& conj, Complex& plain) {
    if constexpr (Lateral) {
      add_pair_lateral(s, t, n, w, conj, plain);
    } else {
      add_pair(s, t, n, w, conj, plain);
    }
  };
  if (m == 0) {
    (Lateral ? add_separable_pairs_lateral : add_separable_pairs)(nodes, sum_conj, sum_plain);
  } else {
    for (std::size_t b = 0; b < nodes.size(); ++b) {
      const Node& t = nodes[b];
      const std::size_t first_of_piece = (b / kQ) * kQ;
      for (std::size_t a = 0; a < first_of_piece; ++a) {
        pair(nodes[a], t, m, nodes[a].weight * t.weight, sum_conj, sum_plain);
      }
    }
  }
  std::vector<double> g_sub(static_cast<std::size_t>(m) + 1);
  for (std::size_t k = 0; k < model.pieces.size(); ++k) {
    for (int q = 0; q < kQ; ++q) {
      const Node& t = nodes[k * kQ + static_cast<std::size_t>(q)];
      const double v = gl[q].first;
      for (int r = 0; r < kQ; ++r) {
        Node s;
        make_node(model, k, v * gl[r].first, 1.0, g_sub.data(), s);
        pair(s, t, m, gl[q].second * gl[r].second * v, sum_conj, sum_plain);
      }
    }
  }
}

}  // namespace

std::size_t second_order_piece_count(const std::vector<ArcSegment>& pieces, double wheelbase_m) {
  std::vector<double> unused;
  return refine(pieces, {}, wheelbase_m, false, unused).size();
}

std::size_t second_order_piece_count(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                                     double wheelbase_m, const EffectList& effects) {
  std::vector<double> unused;
  return refine(pieces, durations_s, wheelbase_m, effect_needs(effects).sample_pieces, unused).size();
}

namespace {

/// Order 2's cost is quadratic in its pieces (with per-run constants; linear without, the pairs
/// being separable): beyond kMaxSecondOrderPieces, or kMaxModelPieces when linear, it is bad
/// input.
void check_second_order_pieces(std::size_t pieces, const char* which, bool quadratic) {
  const double limit = quadratic ? static_cast<double>(kMaxSecondOrderPieces) : kMaxModelPieces;
  if (static_cast<double>(pieces) <= limit) return;
  throw InputError("", 0, "order 2",
                   std::to_string(pieces) + " " + which + " quadrature pieces, above the limit " +
                       format_number(limit) + (quadratic ? " (its cost is quadratic)" : "") + "; use --order 1");
}

}  // namespace

Prediction predict_second_order(const std::vector<ArcSegment>& encoder_pieces,
                                const std::vector<double>& durations_s, const Robot& robot,
                                const EffectList& effects, double heading0_rad) {
  const double B = robot.wheelbase_m;
  std::vector<double> refined_durations;
  const std::vector<ArcSegment> refined =
      refine(encoder_pieces, durations_s, B, effect_needs(effects).sample_pieces, refined_durations);
  check_second_order_pieces(refined.size(), "planned", true);
  const effects::ResolvedPath resolved =
      effects::resolve(refined, refined_durations, robot, effects, heading0_rad);
  // The effects may cut pieces further (a smooth history term, backlash taken up).
  check_second_order_pieces(resolved.pieces.size(), "resolved", resolved.run_constants > 0);
  const std::size_t K = resolved.pieces.size();
  const Model model = build_model(resolved, B);
  const int m = model.m;
  const std::size_t mm = static_cast<std::size_t>(m);
  const Vector3& true_pose = model.true_end_pose;
  const Vector3& odometry = model.odometry_end_pose;
  // data() + offset, not &v[i]: with no run constants (m = 0) the vectors are empty and v[0]
  // would bind a reference to null (UBSan, found by the fuzz targets).
  const double* g_end = model.g_start.data() + K * mm;
  const double v_end = model.w_end + dot(g_end, g_end, m);

  // Regular nodes: Q per piece, with the single integrals.
  static const auto gl = gauss_legendre_01<kQ>();
  std::vector<Node> nodes(K * kQ);
  std::vector<double> g_nodes(K * kQ * mm + 1);
  Complex noise_mean = 0.0, cov_p_theta = 0.0, diag_plain = 0.0;
  for (std::size_t k = 0; k < K; ++k) {
    for (int q = 0; q < kQ; ++q) {
      const std::size_t n = k * kQ + static_cast<std::size_t>(q);
      make_node(model, k, gl[q].first, gl[q].second, g_nodes.data() + n * mm, nodes[n]);
      const Node& x = nodes[n];
      add_single(model, x, g_end, x.W + dot(g_end, x.g, m), model.pieces[k].i_dd, noise_mean, cov_p_theta,
                 diag_plain);
    }
  }
  Complex sum_conj = 0.0, sum_plain = 0.0;
  (model.lateral ? add_pairs<true> : add_pairs<false>)(model, nodes, sum_conj, sum_plain);
  const double cov_conj = 2.0 * sum_conj.real() + model.i_dd_total;
  const Complex cov_plain = 2.0 * sum_plain + diag_plain;

  Prediction out;
  out.odometry_end_pose = odometry;
  out.true_end_pose = true_pose;
  out.noise_mean = {noise_mean.real(), noise_mean.imag(), 0.0};
  Matrix3& P = out.cov;
  P(0, 0) = 0.5 * (cov_conj + cov_plain.real());
  P(1, 1) = 0.5 * (cov_conj - cov_plain.real());
  P(0, 1) = P(1, 0) = 0.5 * cov_plain.imag();
  P(0, 2) = P(2, 0) = cov_p_theta.real();
  P(1, 2) = P(2, 1) = cov_p_theta.imag();
  P(2, 2) = v_end;
  // What the external reference sees (reference_offset), as in predict: first order in the
  // hook's Jacobian about the mean true pose.
  Vector3 measured = true_pose;
  resolved.measure(measured, out.cov);
  out.mean = pose_error(measured, odometry);
  return out;
}

std::vector<ArcSegment> coarsen_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m) {
  return coarsen_pieces(pieces, wheelbase_m, {}, nullptr);
}

std::vector<ArcSegment> coarsen_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m,
                                       const std::vector<double>& durations_s,
                                       std::vector<double>* coarse_durations_s) {
  const bool timed = !durations_s.empty() && coarse_durations_s;
  if (coarse_durations_s) coarse_durations_s->clear();
  std::vector<ArcSegment> out;
  double span = 0.0;
  auto same_sense = [](double x, double y) { return x == 0.0 || y == 0.0 || (x > 0) == (y > 0); };
  ArcSegment current;
  bool open = false;
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    const ArcSegment& p = pieces[i];
    if (open) {
      const ArcSegment merged{current.left_m + p.left_m, current.right_m + p.right_m};
      if (same_sense(current.left_m, p.left_m) && same_sense(current.right_m, p.right_m) &&
          std::abs(merged.heading_change_rad(wheelbase_m)) <= kPieceMaxAngle &&
          std::abs(merged.center_m()) <= kPieceMaxTravel) {
        current = merged;
        if (timed) span += durations_s[i];
        continue;
      }
      out.push_back(current);
      if (timed) coarse_durations_s->push_back(span);
    }
    current = p;
    if (timed) span = durations_s[i];
    open = true;
  }
  if (open) out.push_back(current);
  if (open && timed) coarse_durations_s->push_back(span);
  return out;
}

Prediction predict_second_order(const std::vector<ArcSegment>& pieces, const Robot& robot,
                                const EffectList& effects) {
  return predict_second_order(pieces, {}, robot, effects);
}

CoarsePieces coarsen(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     double wheelbase_m) {
  CoarsePieces out;
  out.wheelbase_m = wheelbase_m;
  out.pieces = coarsen_pieces(pieces, wheelbase_m, durations_s, &out.durations_s);
  out.odometry_end_pose = odometry_walk(pieces, wheelbase_m);
  return out;
}

bool enters_after_prediction(const EffectSpec& effect) {
  const EffectInfo* info = info_of(effect);
  return info && (info->measurement_only || info->grouped);
}

PredictionParts predict_parts(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                              const Robot& robot, const EffectList& effects, int order, double heading0_rad,
                              const CoarsePieces* coarse) {
  // Without the measurement-only effects the engines' hooks do nothing: each part's mean is
  // pose_error(true_end_pose, odometry_end_pose) and its cov the true pose's. The grouped ones
  // (group_variation) have no hooks in one run's prediction, and go too: one may vary a
  // measurement-only effect's parameter.
  EffectList moving;
  for (const EffectSpec& e : effects) {
    if (!enters_after_prediction(e)) moving.push_back(e);
  }
  const bool given_usable = coarse != nullptr && coarse->wheelbase_m == robot.wheelbase_m;
  PredictionParts out;
  if (order == 1) {
    out.whole = predict(pieces, durations_s, robot, moving, heading0_rad,
                        given_usable ? &coarse->odometry_end_pose : nullptr);
    return out;
  }
  CoarsePieces here;
  if (!given_usable) {
    here = coarsen(pieces, durations_s, robot.wheelbase_m);
    coarse = &here;
  }
  if (coarse->pieces.size() == pieces.size()) {
    out.whole = predict_second_order(pieces, durations_s, robot, moving, heading0_rad);
    return out;
  }
  // Fine pieces (a logged run): the first order on them, with every piece's duration, and only
  // the order-2 correction (second minus first order) on the coarsened pieces, timed when the
  // pieces are (an effect may depend on the speed).
  out.whole = predict(pieces, durations_s, robot, moving, heading0_rad, &coarse->odometry_end_pose);
  out.corrected = true;
  out.coarse2 = predict_second_order(coarse->pieces, coarse->durations_s, robot, moving, heading0_rad);
  out.coarse1 = predict(coarse->pieces, coarse->durations_s, robot, moving, heading0_rad);
  return out;
}

Prediction measured(const PredictionParts& parts, const Robot& robot, const EffectList& effects) {
  EffectList hooks;
  for (const EffectSpec& e : effects) {
    const EffectInfo* info = info_of(e);
    if (info && info->measurement_only) hooks.push_back(e);
  }
  // resolve of no pieces: only the hooks (the engines' own, applied as they apply them)
  const effects::ResolvedPath reference = effects::resolve({}, {}, robot, hooks);
  auto view = [&reference](Prediction p) {
    Vector3 pose = p.true_end_pose;
    reference.measure(pose, p.cov);
    p.mean = pose_error(pose, p.odometry_end_pose);
    return p;
  };
  Prediction out = view(parts.whole);
  if (parts.corrected) {
    const Prediction coarse2 = view(parts.coarse2), coarse1 = view(parts.coarse1);
    out.noise_mean += coarse2.mean + coarse2.noise_mean - coarse1.mean - coarse1.noise_mean;
    out.cov += coarse2.cov - coarse1.cov;
  }
  return out;
}

Prediction predict_with_order(const std::vector<ArcSegment>& pieces,
                              const std::vector<double>& durations_s, const Robot& robot,
                              const EffectList& effects, int order, double heading0_rad,
                              const CoarsePieces* coarse) {
  return measured(predict_parts(pieces, durations_s, robot, effects, order, heading0_rad, coarse), robot, effects);
}

Prediction predict_with_order(const std::vector<ArcSegment>& pieces, const Robot& robot,
                              const EffectList& effects, int order) {
  return predict_with_order(pieces, {}, robot, effects, order);
}

}  // namespace odomcov
