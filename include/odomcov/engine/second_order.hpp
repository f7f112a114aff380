// The order-2 model: the mean and covariance of the end-pose error exact in the heading noise
// (docs/orders.md has the derivation; src/engine/second_order.cpp the formulas).
//
// With white Gaussian wheel noise, Gaussian per-run constants and systematic factors, the true
// heading error phi(t) along the path is a Gaussian process, linear in the noise. Writing the
// true position in complex form, p = int exp(i (theta_bar(t) + phi(t))) (d(t) dt + dn(t)), the
// Gaussian characteristic function E[exp(i psi)] = exp(-Var(psi)/2) and Stein's lemma
// (E[X f(psi)] = Cov(X, psi) E[f'(psi)] for jointly Gaussian zero-mean X, psi) give E[p],
// Cov(p, conj p), Cov(p, p), Cov(p, phi_end) and Var(phi_end) as single and double integrals
// along the path, with no truncation in the noise. The integrals are done by Gauss-Legendre
// quadrature per piece (<= 0.25 rad, <= 1 m; equal consecutive model pieces are merged first).
//
// Exact for the white wheel noise, wheel noise correlation, turn slip, per-run radius, custom
// effects' random parameters (to first order in their sd, as the first-order engine carries
// them), lateral slips and every systematic effect; bumps enter through their Gaussian equivalent (an approximation: the
// model's mean and covariance stay exact to second order in the bump size, its higher moments
// do not). Not modelled: the wrap of theta to (-pi, pi] (the model's theta is unwrapped), and the
// O(1/f) difference between the sampled odometry and the continuous noise of the model.
#pragma once

#include <vector>

#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"
#include "odomcov/engine/propagation.hpp"

namespace odomcov {

/// Gauss-Legendre nodes per model piece in the order-2 integrals (the integrand varies over a
/// piece as exp(i a u) with |a| <= 0.25 and linearly in the variances; 4 nodes give ~1e-10
/// relative accuracy, checked against 8 in the tests).
inline constexpr int kSecondOrderNodes = 4;

/// The order-2 prediction for a sequence of constant-curvature pieces (each already small, e.g.
/// model_pieces): `mean` is the exact systematic mean, `noise_mean` the exact noise-induced
/// mean (E[error] - mean), `cov` the exact covariance; world frame, error = true - odometry.
/// Consumes only effects::resolve, so every effect's model side (and any piece-dependent one)
/// enters as it does in the first-order engine.
Prediction predict_second_order(const std::vector<ArcSegment>& pieces, const Robot& robot,
                                const EffectList& effects);
/// The same with each piece's duration, which motion-dependent effects use (speed, time), and
/// the run's start heading in the reference's frame (effects' `heading`).
Prediction predict_second_order(const std::vector<ArcSegment>& pieces,
                                const std::vector<double>& durations_s, const Robot& robot,
                                const EffectList& effects, double heading0_rad = 0.0);

/// The number of quadrature pieces predict_second_order cuts `pieces` into (before any
/// effect's split) for effects that do not use the acceleration; above kMaxSecondOrderPieces
/// (limits.hpp) predict_second_order throws InputError (key "order 2"), as it does when the
/// effects cut the pieces beyond it (a smooth history term, Effect::refines) while the model
/// has per-run constants (the cost is quadratic only then; without, beyond kMaxModelPieces).
std::size_t second_order_piece_count(const std::vector<ArcSegment>& pieces, double wheelbase_m);
/// The same for these effects and durations (pieces whose speed changes are not merged when an
/// effect uses the acceleration).
std::size_t second_order_piece_count(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                                     double wheelbase_m, const EffectList& effects);

/// Merges consecutive pieces (e.g. the per-sample pieces of a logged run) into pieces that turn
/// at most kPieceMaxAngle and travel at most kPieceMaxTravel, never merging across a reversal
/// of either wheel.
std::vector<ArcSegment> coarsen_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m);
/// The same, with each coarse piece's duration (the sum of its pieces') in `coarse_durations_s`
/// when `durations_s` is not empty.
std::vector<ArcSegment> coarsen_pieces(const std::vector<ArcSegment>& pieces, double wheelbase_m,
                                       const std::vector<double>& durations_s,
                                       std::vector<double>* coarse_durations_s);

/// Pieces coarsened once (coarsen_pieces at `wheelbase_m`, with their durations when the fine
/// pieces have them): a logged run's, for predict_with_order to reuse at every evaluation. With
/// them, the odometry's end pose over the fine pieces (odometry_walk at `wheelbase_m`), which
/// no model changes.
struct CoarsePieces {
  double wheelbase_m = 0.0;
  std::vector<ArcSegment> pieces;
  std::vector<double> durations_s;
  Vector3 odometry_end_pose = Vector3::Zero();
};
CoarsePieces coarsen(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     double wheelbase_m);

/// The model of the given order (1: predict, the first-order engine; 2: the order-2 model) for
/// any pieces. For order 2 on fine pieces (a logged run), the first order is taken on the fine
/// pieces and only the higher-order correction on coarsened ones:
///   P2 = P1(fine) + [P2(coarse) - P1(coarse)],   mean likewise,
/// so the coarsening costs accuracy only in the (small) correction.
Prediction predict_with_order(const std::vector<ArcSegment>& pieces, const Robot& robot,
                              const EffectList& effects, int order);
/// The same with each piece's duration (logged runs: the log's t column; planned paths:
/// model_pieces), which motion-dependent effects use. `coarse`, when given, is coarsen() of the
/// same pieces and durations, used when made at the robot's wheelbase (the same numbers as
/// coarsening them here; its odometry end pose serves order 1 too).
Prediction predict_with_order(const std::vector<ArcSegment>& pieces,
                              const std::vector<double>& durations_s, const Robot& robot,
                              const EffectList& effects, int order, double heading0_rad = 0.0,
                              const CoarsePieces* coarse = nullptr);

/// predict_with_order in two steps, for a caller that predicts again with only the values of
/// measurement-only effects changed (EffectInfo::measurement_only: reference_offset):
///  * predict_parts: the prediction without those effects, which do not move the robot (nor the
///    grouped ones, which one run's prediction leaves to likelihood.hpp's group terms): `whole`
///    (predict, or predict_second_order on pieces it cannot coarsen) and, for fine pieces at
///    order 2, the coarse pieces' order-2 and order-1 predictions;
///  * measured: what the external reference sees of them (each part through the hooks, then
///    combined as predict_with_order says), predict_with_order's numbers bit for bit.
struct PredictionParts {
  Prediction whole;
  bool corrected = false;  // coarse2 and coarse1 hold the order-2 correction's parts
  Prediction coarse2, coarse1;
};
/// Whether predict_parts leaves the effect out: a measurement-only one, or a grouped one
/// (group_variation), whose terms likelihood.hpp adds after one run's prediction. What keys
/// kept predictions must leave out the same (calibration.cpp's model_key).
bool enters_after_prediction(const EffectSpec& effect);
PredictionParts predict_parts(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                              const Robot& robot, const EffectList& effects, int order, double heading0_rad = 0.0,
                              const CoarsePieces* coarse = nullptr);
Prediction measured(const PredictionParts& parts, const Robot& robot, const EffectList& effects);

}  // namespace odomcov
