#include "odomcov/engine/propagation.hpp"

#include <type_traits>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <stdexcept>

#include "closed_form/arc_functions.hpp"
#include "effects/effect.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "engine/noise_mean.hpp"

namespace odomcov {

PathCovariance path_covariance(const Path& path, const Robot& robot) {
  const double B = robot.wheelbase_m;
  PathCovariance out;
  KeyframeCovariance current;  // t = 0, zero pose and covariance
  out.keyframes.push_back(current);
  Matrix3 P_tangential = Matrix3::Zero();
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment seg = path.interval(i);
    const double d = seg.center_m();
    const double a = seg.heading_change_rad(B);
    const Matrix3 phi = arc_transition(d, a);
    const Matrix3 q = arc_covariance(seg, B, robot.noise);
    P_tangential = phi * P_tangential * phi.transpose() + q;
    current.t_s = path.keyframes[i + 1].t_s;
    current.pose_world = drive(current.pose_world, seg, B);
    current.P_world = tangential_to_world(P_tangential, current.pose_world.z());
    current.segment_P_world = tangential_to_world(q, current.pose_world.z());
    out.keyframes.push_back(current);
  }
  return out;
}

namespace {

using Complex = std::complex<double>;

}  // namespace


namespace effects {
namespace {

/// Walks the encoder pieces as the effects see them and calls each(encoder, motion, systematic)
/// for every resulting piece, with its motion and every effect's systematic terms folded in:
///  * a piece is cut where a history effect changes its terms inside it (backlash taken up;
///    Effect::split_at), at most four times;
///  * for effects whose terms vary smoothly with the history (Effect::refines: a custom
///    expression in s, t, theta or heading), a piece is halved until evaluating the terms once
///    at its middle gives their mean along it within kRefineTolerance: by Richardson, the error
///    of the whole piece's value is 4/3 of its difference from the mean of its halves' values
///    (midpoint rule, error O(h^2)), at most kMaxRefineDepth times.
/// Every part keeps the acceleration of the piece it was cut from (Motion::a_mps2: a piece's own
/// speed against the previous piece's; cutting for accuracy must not move it). Without effects
/// nothing reads the motion, and it is not computed.
template <class Each>
class PieceWalker {
 public:
  PieceWalker(double wheelbase_m, double heading0_rad, const std::vector<std::unique_ptr<Effect>>& active,
              Each& each)
      : tracker_(wheelbase_m, heading0_rad), active_(active), each_(each) {
    for (const auto& e : active) {
      splits_ = splits_ || e->dependence() == Dependence::history;
      if (e->refines()) refining_.push_back(e.get());
    }
  }

  void piece(const ArcSegment& encoder, double dt) {
    if (!splits_ && refining_.empty()) return one(encoder, dt, nullptr);
    MotionTracker probe = tracker_;
    const double a = active_.empty() ? 0.0 : probe.next(encoder.left_m, encoder.right_m, dt).a_mps2;
    ArcSegment rest = encoder;
    for (int cut = 0; splits_ && cut < 4; ++cut) {
      probe = tracker_;
      const Motion whole = probe.next(rest.left_m, rest.right_m, dt);
      double f = 1.0;
      for (const auto& e : active_) f = std::min(f, e->split_at(whole));
      if (!(f > 1e-12 && f < 1.0 - 1e-12)) break;
      refine({f * rest.left_m, f * rest.right_m}, f * dt, a, 0);
      rest = {(1.0 - f) * rest.left_m, (1.0 - f) * rest.right_m};
      dt *= 1.0 - f;
    }
    refine(rest, dt, a, 0);
  }

 private:
  /// One piece to the caller; `a` (when given) replaces the motion's acceleration.
  void one(const ArcSegment& encoder, double dt, const double* a) {
    // for_each_piece walks an empty list itself: active_ has an effect, which reads the motion.
    Motion motion = tracker_.next(encoder.left_m, encoder.right_m, dt);
    if (a) motion.a_mps2 = *a;
    Systematic sys;
    for (const auto& e : active_) e->systematic(motion, sys);
    each_(encoder, motion, sys);
  }

  void refine(const ArcSegment& encoder, double dt, double a, int depth) {
    if (depth >= kMaxRefineDepth || linear_enough(encoder, dt, a)) return one(encoder, dt, &a);
    const ArcSegment half{0.5 * encoder.left_m, 0.5 * encoder.right_m};
    refine(half, 0.5 * dt, a, depth + 1);
    refine(half, 0.5 * dt, a, depth + 1);
  }

  /// Whether one evaluation at the piece's middle gives every refining effect's mean terms
  /// along it within kRefineTolerance.
  bool linear_enough(const ArcSegment& encoder, double dt, double a) const {
    if (refining_.empty()) return true;
    MotionTracker probe = tracker_;
    Motion whole = probe.next(encoder.left_m, encoder.right_m, dt);
    probe = tracker_;
    Motion first = probe.next(0.5 * encoder.left_m, 0.5 * encoder.right_m, 0.5 * dt);
    Motion second = probe.next(0.5 * encoder.left_m, 0.5 * encoder.right_m, 0.5 * dt);
    whole.a_mps2 = first.a_mps2 = second.a_mps2 = a;
    for (const Effect* e : refining_) {
      Systematic w, x, y;
      e->systematic(whole, w);
      e->systematic(first, x);
      e->systematic(second, y);
      const double terms[][3] = {{w.scale_left, x.scale_left, y.scale_left},
                                 {w.scale_right, x.scale_right, y.scale_right},
                                 {w.wheelbase_factor, x.wheelbase_factor, y.wheelbase_factor},
                                 {w.lateral, x.lateral, y.lateral},
                                 {w.noise_factor, x.noise_factor, y.noise_factor}};
      for (const auto& t : terms) {
        if (!(4.0 / 3.0 * std::abs(t[0] - 0.5 * (t[1] + t[2])) <= kRefineTolerance)) return false;
      }
    }
    return true;
  }

  MotionTracker tracker_;
  const std::vector<std::unique_ptr<Effect>>& active_;
  Each& each_;
  bool splits_ = false;  // a history effect may cut pieces (split_at)
  std::vector<const Effect*> refining_;
};

/// Runs a PieceWalker over the encoder pieces (durations as resolve takes them).
template <class Each>
void for_each_piece(const std::vector<ArcSegment>& encoder_pieces,
                    const std::vector<double>& durations_s, double wheelbase_m, double heading0_rad,
                    const std::vector<std::unique_ptr<Effect>>& active, Each&& each) {
  if (active.empty()) {  // the common plain model: no motion, no terms, no cuts
    const Motion none;
    const Systematic identity;
    for (const ArcSegment& piece : encoder_pieces) each(piece, none, identity);
    return;
  }
  PieceWalker<std::remove_reference_t<Each>> walker(wheelbase_m, heading0_rad, active, each);
  for (std::size_t i = 0; i < encoder_pieces.size(); ++i) {
    walker.piece(encoder_pieces[i], durations_s.empty() ? std::nan("") : durations_s[i]);
  }
}

/// The measurement hooks of the active effects (moved out of `active`).
std::vector<std::shared_ptr<const Effect>> measurement_effects(std::vector<std::unique_ptr<Effect>>& active) {
  std::vector<std::shared_ptr<const Effect>> out;
  for (auto& e : active) {
    if (e->measures()) out.push_back(std::shared_ptr<const Effect>(std::move(e)));
  }
  return out;
}

}  // namespace

ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces,
                     const std::vector<double>& durations_s, const Robot& robot,
                     const EffectList& effect_list, double heading0_rad) {
  auto active = instantiate(effect_list);
  ResolvedPath out;
  for (const auto& e : active) out.run_constants += e->run_constants();
  if (out.run_constants > kMaxRunConstants) {  // check_effects (instantiate) refuses such lists
    throw std::logic_error("resolve: more per-run constants than EffectInfo::run_constants says");
  }
  const double B = robot.wheelbase_m;
  out.pieces.reserve(encoder_pieces.size());
  out.input_columns.reserve(3 * static_cast<std::size_t>(out.run_constants) * encoder_pieces.size());
  // One PieceModel serves every piece: its run columns keep their storage, so the loop does
  // not allocate.
  PieceModel m;
  double inverse_for = 0.0, inverse = 0.0;  // 1/b for the true wheelbase b = inverse_for
  m.wheelbase_m = B;
  m.noise = robot.noise;
  m.effects = &active;
  for_each_piece(encoder_pieces, durations_s, B, heading0_rad, active,
                 [&](const ArcSegment& encoder, const Motion& motion, const Systematic& sys) {
    m.encoder = encoder;
    m.motion = &motion;  // only the effects read it, within this call
    m.scale_left = sys.scale_left;
    m.scale_right = sys.scale_right;
    m.wheelbase_factor = sys.wheelbase_factor;
    m.wheel_cov.setZero();
    m.wheel_cov.diagonal() = wheel_variances(encoder, robot.noise) * sys.noise_factor;
    m.heading_var = 0.0;
    m.run_columns.clear();
    for (const auto& e : active) e->model(m);

    ResolvedPiece& r = out.pieces.emplace_back(encoder);
    const ArcSegment travel = sys.travel(encoder.left_m, encoder.right_m);
    r.wheelbase_true_m = m.wheelbase_factor * B;
    r.center_m = travel.center_m();
    if (sys.lateral != 0.0) r.lateral_m = sys.lateral * 0.5 * (std::abs(encoder.left_m) + std::abs(encoder.right_m));
    r.angle_rad = travel.heading_change_rad(r.wheelbase_true_m);
    if (r.wheelbase_true_m != inverse_for) {  // 1/b changes only with the wheelbase factor
      inverse_for = r.wheelbase_true_m;
      inverse = 1.0 / inverse_for;
    }
    // (e_L, e_R) -> (e_dtheta, e_d) = ((e_R - e_L)/b, (e_L + e_R)/2), applied to the wheel
    // covariance W on both sides, written out.
    const double w11 = m.wheel_cov(0, 0), w22 = m.wheel_cov(1, 1);
    const double w12 = 0.5 * (m.wheel_cov(0, 1) + m.wheel_cov(1, 0));
    r.intensity(0, 0) = (w11 - 2.0 * w12 + w22) * inverse * inverse + m.heading_var;
    r.intensity(0, 1) = r.intensity(1, 0) = 0.5 * (w22 - w11) * inverse;
    r.intensity(1, 1) = 0.25 * (w11 + 2.0 * w12 + w22);
    for (int c = 0; c < out.run_constants; ++c) {
      const Eigen::Vector3d& w = m.run_columns.at(static_cast<std::size_t>(c));
      out.input_columns.insert(out.input_columns.end(), {(w.y() - w.x()) * inverse, 0.5 * (w.x() + w.y()), w.z()});
    }
  });
  out.measurement_effects = measurement_effects(active);
  return out;
}

}  // namespace effects

namespace {

/// A pose carried piece by piece, with the cosine and sine of its heading. They are updated by
/// multiplying with each piece's (cos a, sin a), which the piece's kernels have computed anyway,
/// and recomputed from the heading itself every kExactEvery pieces, so rounding in them stays
/// below ~kExactEvery ulps instead of growing with the path. The heading itself is summed
/// exactly as compose() does.
class PoseWalker {
 public:
  static constexpr int kExactEvery = 16;
  const Vector3& pose() const { return pose_; }
  Complex rotation() const { return rotation_; }
  /// Composes the piece of centre travel d and lateral slip l whose angle functions are f.
  void step(double d, const detail::ArcStep& f, double l = 0.0) {
    double x = f.chord_x(d), y = f.chord_y(d);
    if (l != 0.0) {  // (d + i l) U(a): ArcStep::chord_x(d, l), chord_y(d, l)
      x -= f.chord_y(l);
      y += f.chord_x(l);
    }
    const double c = rotation_.real(), s = rotation_.imag();
    pose_ = {pose_.x() + c * x - s * y, pose_.y() + s * x + c * y, pose_.z() + f.angle};
    if (++count_ == kExactEvery) {
      count_ = 0;
      rotation_ = Complex(std::cos(pose_.z()), std::sin(pose_.z()));
    } else {
      rotation_ *= Complex(f.cos1, f.sin1);
    }
  }

 private:
  Vector3 pose_ = Vector3::Zero();
  Complex rotation_ = 1.0;
  int count_ = 0;
};

/// Moves the odometry by one encoder piece. The odometry's arcs are the encoder's own, at the
/// nominal wheelbase B; `f` (the angle functions of the true piece of travel d, angle a and
/// lateral slip l) is reused when the true piece is the encoder's, which gives the same bits as
/// computing them again.
void step_odometry(PoseWalker& odometry, const ArcSegment& encoder, double B, double d, double a, double l,
                   const detail::ArcStep& f) {
  const double d_odometry = encoder.center_m(), a_odometry = encoder.heading_change_rad(B);
  if (d_odometry == d && a_odometry == a && l == 0.0) {
    odometry.step(d, f);
  } else {
    odometry.step(d_odometry, detail::ArcStep(a_odometry));
  }
}

/// phi P phi^T for the arc transition phi = [c s y; -s c x; 0 0 1] (arc_transition, with the
/// lateral slip l in its third column) and a symmetric P, written out: the zeros and ones of phi
/// cost nothing.
Matrix3 transition_congruence(const detail::ArcStep& f, double d, double l, const Matrix3& P) {
  const double c = f.cos1, s = f.sin1;
  double x = f.chord_x(d), y = f.chord_y(d);
  if (l != 0.0) {
    x += f.chord_y(l);
    y -= f.chord_x(l);
  }
  // M = phi P (rows 0 and 1; row 2 is P's)
  double m0[3], m1[3];
  for (int j = 0; j < 3; ++j) {
    m0[j] = c * P(0, j) + s * P(1, j) + y * P(2, j);
    m1[j] = -s * P(0, j) + c * P(1, j) + x * P(2, j);
  }
  Matrix3 out;
  out(0, 0) = c * m0[0] + s * m0[1] + y * m0[2];
  out(0, 1) = -s * m0[0] + c * m0[1] + x * m0[2];
  out(1, 1) = -s * m1[0] + c * m1[1] + x * m1[2];
  out(0, 2) = m0[2];
  out(1, 2) = m1[2];
  out(2, 2) = P(2, 2);
  out(1, 0) = out(0, 1);
  out(2, 0) = out(0, 2);
  out(2, 1) = out(1, 2);
  return out;
}

/// The engine's loop; `each` (when not nullptr) sees the prediction after every piece.
/// `odometry_end_pose`, when given, is odometry_walk(pieces, B), used instead of walking the
/// odometry again when the effects did not cut the pieces (then every resolved piece's encoder
/// arc is the given piece, and the walk would give the same bits).
template <class Each>
Prediction propagate(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effect_list, double heading0_rad, Each&& each,
                     const Vector3* odometry_end_pose = nullptr) {
  const effects::ResolvedPath path = effects::resolve(pieces, durations_s, robot, effect_list, heading0_rad);
  const int constants = path.run_constants;
  const double B = robot.wheelbase_m;
  constexpr bool kEachPiece = !std::is_same_v<std::decay_t<Each>, std::nullptr_t>;
  // Cuts only add pieces, so the same count means none was cut.
  const bool odometry_known = !kEachPiece && odometry_end_pose != nullptr && path.pieces.size() == pieces.size();

  Prediction out;
  Matrix3 P = Matrix3::Zero();                          // tangential, along the true path
  // cov(e, per-run constants); fixed storage, so the loop does not allocate
  Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, effects::kMaxRunConstants> C =
      Eigen::MatrixXd::Zero(3, constants);
  PoseWalker true_pose, odometry;
  Complex noise_mean = 0.0;
  for (std::size_t k = 0; k < path.pieces.size(); ++k) {
    const effects::ResolvedPiece& r = path.pieces[k];
    const double d = r.center_m;
    const double l = r.lateral_m;
    const double a = r.angle_rad;
    // One evaluation of the angle's functions serves every kernel below.
    const detail::ArcFunctions f(a);
    const Matrix3 q = l == 0.0 ? detail::arc_noise_covariance(d, f, r.intensity)
                               : detail::arc_noise_covariance(d, l, f, r.intensity);
    const double v0 = P(2, 2);
    if (constants == 0) {
      P = transition_congruence(f, d, l, P) + q;
    } else {
      const Matrix3 phi = detail::arc_transition(d, l, f);
      const Eigen::Matrix<double, 3, Eigen::Dynamic, 0, 3, effects::kMaxRunConstants> A =
          detail::arc_input_gain(d, l, f) * path.columns(k);
      const Matrix3 cross = phi * C * A.transpose();
      P = phi * P * phi.transpose() + cross + cross.transpose() + A * A.transpose() + q;
      C = phi * C + A;
    }
    const Complex undamped(f.sinc1, 0.5 * a * f.sinc_half * f.sinc_half);  // int_0^1 e^{i a u} du
    noise_mean += detail::noise_mean_of_piece(true_pose.rotation(), d, l, a, undamped, v0, P(2, 2) - v0,
                                              r.intensity(0, 1));
    true_pose.step(d, f, l);
    if (!odometry_known) step_odometry(odometry, r.encoder, B, d, a, l, f);
    if constexpr (kEachPiece) {
      each(Prediction{pose_error(true_pose.pose(), odometry.pose()),
                      {noise_mean.real(), noise_mean.imag(), 0.0},
                      tangential_to_world(P, true_pose.pose().z()), odometry.pose(), true_pose.pose()});
    }
  }
  out.odometry_end_pose = odometry_known ? *odometry_end_pose : odometry.pose();
  out.true_end_pose = true_pose.pose();
  out.cov = tangential_to_world(P, true_pose.pose().z());
  Vector3 measured = true_pose.pose();
  path.measure(measured, out.cov);  // what the external reference sees (reference_offset)
  out.mean = pose_error(measured, out.odometry_end_pose);
  out.noise_mean = {noise_mean.real(), noise_mean.imag(), 0.0};
  return out;
}

}  // namespace

namespace {

/// predict_mean's walk for one effect list: the true pose moved by each piece as the effects
/// make it, and (unless given) the odometry's.
class MeanWalk {
 public:
  MeanWalk(double wheelbase_m, const Vector3* odometry_end_pose)
      : B_(wheelbase_m), odometry_end_pose_(odometry_end_pose) {}

  void step(const ArcSegment& encoder, const effects::Systematic& sys) {
    const ArcSegment travel = sys.travel(encoder.left_m, encoder.right_m);
    const double center = travel.center_m(), angle = travel.heading_change_rad(sys.wheelbase_factor * B_);
    const double lateral = sys.lateral * 0.5 * (std::abs(encoder.left_m) + std::abs(encoder.right_m));
    const detail::ArcStep f(angle);
    true_pose_.step(center, f, lateral);
    if (odometry_end_pose_ == nullptr) step_odometry(odometry_, encoder, B_, center, angle, lateral, f);
  }

  /// The end pose error as the external reference sees it (the effects' measurement hooks).
  Vector3 error(std::vector<std::unique_ptr<effects::Effect>>& active) {
    effects::ResolvedPath hooks;
    hooks.measurement_effects = effects::measurement_effects(active);
    Vector3 measured = true_pose_.pose();
    Matrix3 unused = Matrix3::Zero();
    hooks.measure(measured, unused);
    return pose_error(measured, odometry_end_pose_ != nullptr ? *odometry_end_pose_ : odometry_.pose());
  }

 private:
  double B_;
  const Vector3* odometry_end_pose_;
  PoseWalker true_pose_, odometry_;
};

/// Whether the effects walk the pieces as they come: none cuts (a history effect's split_at)
/// or halves them (refines), so each piece's motion is the tracker's, whatever their values.
bool walks_plainly(const std::vector<std::unique_ptr<effects::Effect>>& active) {
  return std::none_of(active.begin(), active.end(), [](const auto& e) {
    return e->dependence() == effects::Dependence::history || e->refines();
  });
}

}  // namespace

Vector3 predict_mean(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                     const Robot& robot, const EffectList& effect_list,
                     const Vector3* odometry_end_pose, double heading0_rad) {
  return predict_means(pieces, durations_s, robot, {effect_list}, odometry_end_pose, heading0_rad)[0];
}

std::vector<Vector3> predict_means(const std::vector<ArcSegment>& pieces,
                                   const std::vector<double>& durations_s, const Robot& robot,
                                   const std::vector<EffectList>& lists,
                                   const Vector3* odometry_end_pose, double heading0_rad) {
  // resolve's pieces, streamed: only their true arcs (the same arithmetic), nothing stored.
  const double B = robot.wheelbase_m;
  std::vector<std::vector<std::unique_ptr<effects::Effect>>> active;
  for (const EffectList& list : lists) active.push_back(effects::instantiate(list));
  std::vector<MeanWalk> walks(lists.size(), MeanWalk(B, odometry_end_pose));
  const bool shared = std::all_of(active.begin(), active.end(),
                                  [](const auto& a) { return !a.empty() && walks_plainly(a); });
  if (shared) {
    // The first list's walk hands each piece's motion to the others: with no cuts it is the
    // motion each list's own walk would compute.
    effects::for_each_piece(pieces, durations_s, B, heading0_rad, active[0],
                            [&](const ArcSegment& encoder, const effects::Motion& motion,
                                const effects::Systematic& sys) {
      walks[0].step(encoder, sys);
      for (std::size_t j = 1; j < walks.size(); ++j) {
        effects::Systematic own;
        for (const auto& e : active[j]) e->systematic(motion, own);
        walks[j].step(encoder, own);
      }
    });
  } else {
    for (std::size_t j = 0; j < walks.size(); ++j) {
      effects::for_each_piece(pieces, durations_s, B, heading0_rad, active[j],
                              [&](const ArcSegment& encoder, const effects::Motion&,
                                  const effects::Systematic& sys) { walks[j].step(encoder, sys); });
    }
  }
  std::vector<Vector3> out;
  for (std::size_t j = 0; j < walks.size(); ++j) out.push_back(walks[j].error(active[j]));
  return out;
}

Prediction predict(const std::vector<ArcSegment>& pieces, const Robot& robot,
                   const EffectList& effect_list) {
  return propagate(pieces, {}, robot, effect_list, 0.0, nullptr);
}

Prediction predict(const std::vector<ArcSegment>& pieces, const std::vector<double>& durations_s,
                   const Robot& robot, const EffectList& effect_list, double heading0_rad,
                   const Vector3* odometry_end_pose) {
  return propagate(pieces, durations_s, robot, effect_list, heading0_rad, nullptr, odometry_end_pose);
}

Vector3 odometry_walk(const std::vector<ArcSegment>& pieces, double wheelbase_m) {
  PoseWalker odometry;  // step_odometry with nothing to reuse
  for (const ArcSegment& encoder : pieces) {
    odometry.step(encoder.center_m(), detail::ArcStep(encoder.heading_change_rad(wheelbase_m)));
  }
  return odometry.pose();
}

std::vector<Prediction> predict_trajectory(const std::vector<ArcSegment>& pieces,
                                           const std::vector<double>& durations_s,
                                           const Robot& robot, const EffectList& effect_list,
                                           double heading0_rad) {
  std::vector<Prediction> out;
  out.reserve(pieces.size() + 1);
  out.emplace_back();  // the start: exactly known
  propagate(pieces, durations_s, robot, effect_list, heading0_rad,
            [&out](const Prediction& p) { out.push_back(p); });
  return out;
}

std::vector<ArcSegment> path_model_pieces(const Path& path, double wheelbase_m, const EffectList& effects,
                                          std::vector<double>* durations_s) {
  return effect_needs(effects).sample_pieces ? sample_model_pieces(path, wheelbase_m, durations_s)
                                             : model_pieces(path, wheelbase_m, durations_s);
}

}  // namespace odomcov
