// Covariance along a whole path: the closed form composed segment by segment ([Kleeman95] §6,
// Tables I-II), and the per-sample linearised propagation of [Wang88] as an independent check.
#pragma once

#include <vector>

#include "odomcov/closed_form/closed_form.hpp"
#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"

namespace odomcov {

/// The theory at one keyframe (Tables I-II): accumulated covariance and the interval's own
/// contribution, both in the world frame at the keyframe's heading.
struct KeyframeCovariance {
  double t_s = 0.0;
  Vector3 pose_world = Vector3::Zero();
  Matrix3 P_world = Matrix3::Zero();
  Matrix3 segment_P_world = Matrix3::Zero();  // zero for the first keyframe
};

struct PathCovariance {
  std::vector<KeyframeCovariance> keyframes;  // one per keyframe, the first at t = 0
  const KeyframeCovariance& end() const { return keyframes.back(); }
};

/// Closed-form covariance at every keyframe of the path [Kleeman95, eqs. (40)-(43)].
PathCovariance path_covariance(const Path& path, const Robot& robot);

/// First-order covariance of the sampled odometry, propagated sample by sample with the exact
/// Jacobians of the discrete arc update (the approach of [Wang88]): for each sample,
///   P <- Phi P Phi^T + J N J^T,
/// with J the derivative of the sample's end pose (in its end frame) with respect to
/// (dtheta, d) and N the sample's noise intensity. It converges to path_covariance as the
/// sample rate grows, with an O(1/f^2) difference (midpoint-rule error of the noise integral)
/// when keyframes fall on sample boundaries. A sample that straddles a keyframe at which a
/// wheel reverses has noise k^2 |net increment| (noise model of docs/conventions.md), an O(1/f) difference.
/// Returns the world-frame covariance at the end of the path.
Matrix3 sampled_covariance(const Path& path, const Robot& robot);

/// The mean of the end-pose error induced by white wheel noise, which first-order theory sets to
/// zero ([Kleeman95] Table V shows it at large noise). The heading error Theta(u) is a sum of
/// Gaussian increments, so E[exp(i Theta)] = exp(-V/2) exactly, with V its accumulated variance;
/// the along-track noise of each increment correlates with its own heading change through the
/// midpoint of the arc. In the continuum limit this gives, along the path,
///   E[d(x + i y)] = exp(-V(u)/2) exp(i theta(u)) (ds + i N_td du / 2),   E[theta] = 0,
/// with N_td the off-diagonal of the noise intensity (wheel_noise_intensity). The result is
/// exact in the heading variance and first order in the along-track noise; the sampled
/// simulation adds O(1/f). World frame, error = true - odometry.
Vector3 noise_induced_mean(const Path& path, const Robot& robot);

/// The model's prediction of the end-pose error (world frame, error = true - odometry).
struct Prediction {
  Vector3 mean = Vector3::Zero();        // from systematic effects: exact (perturbed path)
  Vector3 noise_mean = Vector3::Zero();  // noise-induced, beyond first order (see above)
  Matrix3 cov = Matrix3::Zero();         // first order, along the true (perturbed) path
  Vector3 odometry_end_pose = Vector3::Zero();
  Vector3 true_end_pose = Vector3::Zero();  // mean true pose (systematic effects only)
};

/// The general linearised propagation engine: any sequence of constant-curvature pieces
/// (keyframe intervals, or one piece per sample of a logged run) with any model effects.
///  * Systematic effects move the true path; the mean is that path's end pose minus the
///    odometry's, computed exactly.
///  * White noise (the robot's, and the effects' extra wheel and heading variance) adds
///    arc_noise_covariance per piece, with the piece's noise intensity.
///  * Per-run random constants (e.g. per_run_radius) are carried as augmented state with their
///    cross-covariance: e_end = Phi e + A c + w, A = arc_input_gain * (their wheel columns).
///  * The noise-induced mean uses the heading variance V(u) the propagation itself carries
///    (linear within a piece).
/// With no effects the covariance is exactly the composed closed form.
///  * Effects see each piece's motion (effects/effect.hpp: speed, curvature, direction,
///    reversals, time); `durations_s` gives each piece's duration (the overload without it
///    leaves time and speed unknown, NaN).
///  * Measurement hooks (reference_offset) map the mean end pose and the covariance last.
///  * A lateral slip (effects' Systematic::lateral) adds to each piece's displacement and turns
///    with the heading error as the travel does (arc kernels with a lateral slip).
///  * `heading0_rad`: the run's start heading in the reference's frame, which effects that use
///    the absolute heading see (custom effects' `heading`; 0 where unknown).
///  * The odometry depends on the encoders and the nominal wheelbase only:
///    `odometry_end_pose`, when given, is odometry_walk(pieces, robot.wheelbase_m) (a logged
///    run's, computed once), and is used instead of walking the odometry again where that
///    would give the same bits (no effect cut the pieces).
Prediction predict(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                   const Robot& robot, const EffectList& effects, double heading0_rad = 0.0,
                   const Vector3* odometry_end_pose = nullptr);
Prediction predict(const std::vector<ArcSegment>& pieces, const Robot& robot,
                   const EffectList& effects);

/// The odometry's end pose over `pieces` at `wheelbase_m`, as predict integrates it (bit for
/// bit when no effect cuts the pieces): predict's `odometry_end_pose`.
Vector3 odometry_walk(const std::vector<ArcSegment>& pieces, double wheelbase_m);

/// predict(...).mean alone, by the same arithmetic (bit for bit), without the covariance and
/// the noise-induced mean: for derivatives of the systematic mean (group_variation's column).
/// The odometry depends on the encoders and the nominal wheelbase only: `odometry_end_pose`,
/// when given (predict's odometry_end_pose for the same pieces and robot), is used instead of
/// integrating it again.
Vector3 predict_mean(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effects,
                     const Vector3* odometry_end_pose = nullptr, double heading0_rad = 0.0);

/// predict_mean for several lists of the same effects with other values (a parameter moved
/// to several points: group_variation's terms), bit for bit, in one walk over the pieces when
/// no effect cuts or refines them (each piece's motion is then the same for every list), else
/// in one walk each.
std::vector<Vector3> predict_means(const std::vector<ArcSegment>& pieces,
                                   const std::vector<double>& durations_s, const Robot& robot,
                                   const std::vector<EffectList>& lists,
                                   const Vector3* odometry_end_pose = nullptr,
                                   double heading0_rad = 0.0);

/// The engine's prediction after every piece, for covariance along a trajectory (an encoder
/// log, one piece per sample): element 0 is the start (all zero), element i the state after
/// pieces[0 .. i-1]. Same frames and conventions as predict(); `durations_s` as there (each
/// piece's duration, for effects that depend on speed or time; empty when unknown).
std::vector<Prediction> predict_trajectory(const std::vector<ArcSegment>& pieces,
                                           const std::vector<double>& durations_s,
                                           const Robot& robot, const EffectList& effects,
                                           double heading0_rad = 0.0);

/// The pieces the model resolves a planned path into for a list of effects: model_pieces, or,
/// when an effect uses the acceleration (effect_needs: `a`, which on a sampled path changes
/// only at the first sample of each stretch of equal samples), sample_model_pieces, on which the
/// acceleration is constant piece by piece as it is sample by sample in the simulator.
/// `durations_s`, when given, receives each piece's duration.
std::vector<ArcSegment> path_model_pieces(const Path& path, double wheelbase_m, const EffectList& effects,
                                          std::vector<double>* durations_s = nullptr);


}  // namespace odomcov
