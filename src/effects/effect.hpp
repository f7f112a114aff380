// The internal interface every effect implements: its world side (hooks the simulator calls)
// and its model side (what it adds to the linearised propagation of one piece). Adding an effect
// is one file in this folder plus one line in registry.cpp.
#pragma once

#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "odomcov/closed_form/closed_form.hpp"
#include "odomcov/effects/effects.hpp"
#include "odomcov/closed_form/path.hpp"
#include "base/random.hpp"

namespace odomcov::effects {

/// Counter-based draws for one effect slot in one run (random.hpp): per-sample draws at
/// (run, sample, kTagEffect | slot << 8 | index), per-run draws at (run, index,
/// kTagPerRun | slot << 8). Streams never overlap the wheel noise or other effects.
class Draws {
 public:
  Draws() = default;
  Draws(const random::Philox::key_type& key, std::uint64_t run, std::uint32_t slot)
      : key_(key), run_(run), slot_(slot) {}
  double normal(std::uint32_t sample, std::uint32_t index) const {
    return random::normal_at(key_, run_, sample, random::kTagEffect | slot_ << 8 | index);
  }
  double uniform(std::uint32_t sample, std::uint32_t index) const {
    return random::uniform_at(key_, run_, sample, random::kTagEffect | slot_ << 8 | index);
  }
  double run_normal(std::uint32_t index) const {
    return random::normal_at(key_, run_, index, random::kTagPerRun | slot_ << 8);
  }
  double run_uniform(std::uint32_t index) const {
    return random::uniform_at(key_, run_, index, random::kTagPerRun | slot_ << 8);
  }

 private:
  random::Philox::key_type key_{};
  std::uint64_t run_ = 0;
  std::uint32_t slot_ = 0;
};

/// The motion of one increment (a simulated sample, or a model piece: a planned-path piece or a
/// logged row), as every effect sees it on both sides. Both sides build it with MotionTracker,
/// so the same increments give the same Motion.
struct Motion {
  double dL_m = 0.0, dR_m = 0.0;  // encoder increments
  double dt_s = 0.0;              // duration (NaN when unknown: model pieces given without times)
  double v_mps = 0.0;             // mean wheel speed (|dL| + |dR|)/(2 dt)
  double kappa_per_m = 0.0;       // signed curvature (dR - dL)/(B (dL + dR)/2); +-inf on a pure spin
  double r = 0.0;                 // spin fraction |dR - dL|/(|dR| + |dL|): 0 line, 1 spin
  int dir = 0;                    // +1 forwards, -1 backwards, 0 on the spot (sign of dL + dR)
  int turn = 0;                   // +1 CCW, -1 CW, 0 straight (sign of dR - dL)
  /// Each wheel's encoder travel since its last reversal of direction, at the start of the
  /// increment: 0 when this increment reverses the wheel, +inf before any reversal (a run starts
  /// with the play taken up forwards).
  double since_reversal_left_m = HUGE_VAL, since_reversal_right_m = HUGE_VAL;
  double t_s = 0.0;  // time at the start of the increment
  double s_m = 0.0;  // mean wheel travel (|dL| + |dR|)/2 so far, at the start of the increment
  /// Acceleration along the path: (v - v of the previous increment)/dt, with v = 0 before the
  /// first increment. On a model piece, the piece's own speed against the previous piece's (a
  /// piece the model cuts further for its own accuracy keeps its parent's value).
  double a_mps2 = 0.0;
  double omega_radps = 0.0;  // turn rate (dR - dL)/(B dt), nominal B
  double turn_rad = 0.0;     // encoder heading change (dR - dL)/B over the increment, nominal B
  double theta_rad = 0.0;    // encoder heading since the run's start, at the start of the increment
  double heading0_rad = 0.0;  // the run's start heading in the reference's frame (0 if unknown)
};

/// Builds the Motion of consecutive increments, keeping time, distance and each wheel's
/// direction. `wheelbase_m` is the nominal one (curvature as the encoders see it).
class MotionTracker {
 public:
  /// `heading0_rad`: the run's start heading in the reference's own frame (Motion::heading0_rad).
  explicit MotionTracker(double wheelbase_m, double heading0_rad = 0.0)
      : wheelbase_m_(wheelbase_m), heading0_rad_(heading0_rad) {}
  /// The Motion of the next increment (the first of `count` identical ones), then advances past
  /// all `count` of them.
  Motion next(double dL_m, double dR_m, double dt_s, std::int64_t count = 1);

 private:
  double wheelbase_m_;
  double heading0_rad_;
  double t_s_ = 0.0, s_m_ = 0.0, theta_rad_ = 0.0;
  double v_mps_ = 0.0;  // of the last increment (0 before the first)
  int dir_left_ = 1, dir_right_ = 1;
  double since_left_ = HUGE_VAL, since_right_ = HUGE_VAL;
};

/// What a systematic effect does to one increment's true motion: true travel of each wheel =
/// scale x encoder + offset, true wheelbase = factor x nominal, a lateral slip of the centre of
/// `lateral` metres to the left per metre of mean wheel travel (|dL| + |dR|)/2, and the white
/// wheel noise variance k^2 |dL| (and |dR|) times `noise_factor`. Effects compose: scales, the
/// wheelbase factor and the noise factor multiply, offsets and lateral slips add (offsets
/// applied after every scale).
///
/// Where the lateral slip acts (both sides): it accumulates along the increment's arc as the
/// travel does, so the increment's displacement in its start frame is (d + i l) U(a) with
/// d the true centre travel, l = lateral x (|dL| + |dR|)/2, a the true heading change and
/// U(a) = int_0^1 e^{i a u} du = sinc(a/2) e^{i a/2}: the lateral part is l sinc(a/2) to the
/// left of the chord's heading (a/2 into the increment). A piece of any length then gives the
/// same displacement as its samples together (docs/conventions.md, "Lateral slip").
struct Systematic {
  double scale_left = 1.0, scale_right = 1.0;
  double wheelbase_factor = 1.0;
  double offset_left_m = 0.0, offset_right_m = 0.0;
  double lateral = 0.0;       // [m/m] leftward slip per metre of mean wheel travel
  double noise_factor = 1.0;  // on both wheels' white noise variance

  bool operator==(const Systematic& o) const {
    return scale_left == o.scale_left && scale_right == o.scale_right &&
           wheelbase_factor == o.wheelbase_factor && offset_left_m == o.offset_left_m &&
           offset_right_m == o.offset_right_m && lateral == o.lateral && noise_factor == o.noise_factor;
  }
  ArcSegment travel(double dL_m, double dR_m) const {
    return {scale_left * dL_m + offset_left_m, scale_right * dR_m + offset_right_m};
  }
};

/// What a systematic effect's factors depend on, so the simulator knows how often to evaluate
/// them: never (`none`: once per path), on the increment only (`increment`: dL, dR, dt, v,
/// kappa, r, dir, turn, omega, constant along a leg of equal samples), or on the history
/// (`history`: t, s, theta, heading, the acceleration a or the reversal state, evaluated per
/// sample).
enum class Dependence { none = 0, increment = 1, history = 2 };

/// What an effect keeps from one run to the next sample (per-run constants, the distance to the
/// next event); zeroed by the simulator before begin_run.
struct RunState {
  double value[4] = {0.0, 0.0, 0.0, 0.0};
};

/// A leg of the world side (a stretch of equal samples) as a stochastic effect sees it.
struct LegView {
  double encoder_left = 0.0;      // encoder increments per sample
  double encoder_right = 0.0;
  double wheelbase_nominal = 0.0;
  double travel_left = 0.0;       // systematic true travel per sample (scale x encoder + offset)
  double travel_right = 0.0;
  double wheelbase = 0.0;         // true wheelbase of the leg's samples
};

/// One term of a sample's extra wheel travel: travel[wheel] gets (value x a) x b added, where
/// value is the effect's per-run value `index` (RunState::value, set by begin_run) or its
/// per-sample standard normal `index` (drawn at Draws::normal(sample, index)). a and b are the
/// leg's coefficients (two, so an effect keeps the rounding of its own formula).
struct TravelTerm {
  int wheel = 0;          // 0 left, 1 right
  bool per_run = false;   // value from RunState (true) or a per-sample normal (false)
  std::uint32_t index = 0;
  double a = 1.0, b = 1.0;
};

/// One constant-curvature piece on the model side. The engine fills the inputs, the plain
/// robot's values and the systematic factors (every effect's `systematic` for this piece's
/// motion, folded in first as on the world side, so no effect's model depends on the order
/// effects are listed); each effect's `model` then adds what it models.
class Effect;

struct PieceModel {
  ArcSegment encoder;        // input: encoder travel over the piece
  double wheelbase_m = 0.0;  // input: nominal wheelbase
  WheelNoise noise;          // input: the model's wheel noise constants
  const Motion* motion = nullptr;  // input: the piece's motion (the walker's, for the call)
  double scale_left = 1.0;   // input, systematic: true travel = scale x encoder (+ offset)
  double scale_right = 1.0;
  double wheelbase_factor = 1.0;  // input, systematic: true wheelbase = factor x nominal
  /// input: every active effect, for an effect whose random part moves its own systematic terms
  /// (others_systematic).
  const std::vector<std::unique_ptr<Effect>>* effects = nullptr;
  /// white (e_L, e_R) over the piece: k^2 |travel| times the systematic noise factor
  Eigen::Matrix2d wheel_cov = Eigen::Matrix2d::Zero();
  double heading_var = 0.0;  // extra white heading variance over the piece
  /// One column per standard-normal per-run constant: its effect on (e_L, e_R, e_lat) over the
  /// piece, e_lat the piece's lateral displacement (Systematic::lateral times the mean wheel
  /// travel), a change of the true wheelbase written as the wheel errors that turn the same.
  std::vector<Eigen::Vector3d> run_columns;
};

/// The systematic terms of every effect of `piece.effects` but `self`, for the piece's motion:
/// what an effect whose random draw moves its own terms composes them with (custom.cpp).
Systematic others_systematic(const PieceModel& piece, const Effect* self);

class Effect {
 public:
  virtual ~Effect() = default;

  // ---- Both sides: the systematic part --------------------------------------------------------
  /// What the factors below depend on (see Dependence).
  virtual Dependence dependence() const { return Dependence::none; }
  /// Systematic factors on one increment's true travel and wheelbase, given its motion. The
  /// simulator evaluates them per leg (or per sample, for `history`), the model per piece.
  virtual void systematic(const Motion& motion, Systematic& factors) const {
    (void)motion, (void)factors;
  }
  /// Model side, for history effects: the fraction in (0, 1] of this piece after which the
  /// factors change (backlash: where the play is taken up); resolve splits the piece there. Only
  /// effects whose dependence() is `history` are asked.
  virtual double split_at(const Motion& motion) const {
    (void)motion;
    return 1.0;
  }
  /// End-of-path hook on what the external reference measures (world side): `pose` is the true
  /// end pose in the start frame; the effect turns it into the measured one.
  virtual void measure(Vector3& pose) const { (void)pose; }
  /// The model side of `measure`, first order: maps the predicted mean end pose (true, start
  /// frame) to the measured one and multiplies J_measured_true by the hook's Jacobian.
  virtual void measure_model(Vector3& pose, Matrix3& J_measured_true) const {
    (void)pose, (void)J_measured_true;
  }
  virtual bool measures() const { return false; }
  /// World side: "" when the effect can be simulated exactly on samples of at most this mean
  /// wheel travel (|dL| + |dR|)/2, else why not (bumps: too many per sample).
  virtual std::string check_samples(double max_mean_travel_m) const {
    (void)max_mean_travel_m;
    return "";
  }

  /// Model side: true when the systematic terms vary smoothly with the history along a piece
  /// (a custom expression in s, t, theta or heading): resolve then cuts a piece finer wherever
  /// one evaluation at its middle would miss their mean along it (kRefineTolerance).
  virtual bool refines() const { return false; }

  // ---- World side: randomness -----------------------------------------------------------------
  // The simulator runs these for a block of runs at once in SIMD lanes (and run by run in its
  // scalar reference, with the same arithmetic), so an effect states what it does per leg rather
  // than acting per sample. Per sample and run, in the order the effects are listed:
  //   1. the wheels' standard normals (z_L, z_R) are mixed by every `noise_mix`;
  //   2. each effect's `terms` for the leg add to the wheels' extra travel, and an effect with
  //      `events` counts RunState::value[0] down by the sample's mean wheel travel
  //      (|dL| + |dR|)/2 and, when it reaches 0 or below, handles the event by `event`;
  //   3. true travel = systematic travel + sigma z + extra.
  /// True when the hooks below do anything (the simulator then runs its general kernel).
  virtual bool stochastic() const { return false; }
  /// Per-run values (per lane, once per run), e.g. per-run normals or the first event's distance.
  virtual void begin_run(RunState& state, const Draws& draws) const { (void)state, (void)draws; }
  /// True when the systematic terms depend on this run's draws (a custom effect with `random:`
  /// parameters): the simulator then leaves the effect out of the legs it builds once per path
  /// and composes, for every leg of every run, run_systematic with the leg's other terms.
  virtual bool per_run_systematic() const { return false; }
  /// The systematic terms of one increment for this run's draws (`state` from begin_run),
  /// composed into `factors` as systematic() does. Thread-safe: runs are simulated in parallel.
  virtual void run_systematic(const Motion& motion, const RunState& state, Systematic& factors) const {
    (void)motion, (void)state, (void)factors;
  }
  /// Mixes the standard normals of the two wheels' noise before they are scaled:
  /// z_R <- from_left z_L + from_right z_R. Returns false when the effect does not mix.
  virtual bool noise_mix(double& from_left, double& from_right) const {
    (void)from_left, (void)from_right;
    return false;
  }
  /// The terms this effect adds to each sample of a leg (none: the leg is untouched and draws
  /// nothing for this effect).
  virtual void terms(const LegView& leg, std::vector<TravelTerm>& out) const { (void)leg, (void)out; }
  /// Rare events along the travel (see above): `event` adds the event's travel to the wheels
  /// and moves RunState::value[0] on to the next event, drawing from `draws` at `sample`.
  virtual bool events() const { return false; }
  virtual void event(std::uint32_t sample, RunState& state, const Draws& draws, double& extra_left,
                     double& extra_right) const {
    (void)sample, (void)state, (void)draws, (void)extra_left, (void)extra_right;
  }

  /// World side: "" when the effect adds only Gaussian noise or deterministic changes, else what
  /// makes the errors it gives non-Gaussian ("a radius drawn once per run"): compare then
  /// calibrates its tests by simulating the model's world (non_gaussian_effect).
  virtual std::string non_gaussian() const { return ""; }
  /// World side: true when the errors it gives have heavier tails than Gaussian ones (a few runs
  /// far out: Poisson impulses), so that a Gaussian likelihood's ratio for a variance parameter
  /// is no longer chi^2 (heavy_tailed_effect; diagnose scales it).
  virtual bool heavy_tailed() const { return false; }

  // ---- Model side (first order in the effect) ------------------------------------------------
  /// Number of standard-normal per-run constants this effect contributes columns for.
  virtual int run_constants() const { return 0; }
  /// The effect's random part on one piece (systematic factors are already in `piece`).
  virtual void model(PieceModel& piece) const { (void)piece; }
};

/// The engine keeps the per-run constants' columns in fixed storage of kMaxRunConstants
/// (effects.hpp: per_run_radius has two, a custom effect one per random parameter).
using odomcov::kMaxRunConstants;

/// A piece as every propagator sees it once the effects have spoken: the true motion (systematic
/// factors applied) and the white noise intensity of (e_dtheta, e_d) over the piece (the per-run
/// constants' columns are the path's: ResolvedPath::columns). The first-order engine (predict)
/// and any higher-order propagator consume these, so effects are modelled in one place.
struct ResolvedPiece {
  /// Built from its encoder travel, the rest set by resolve (a user-provided constructor: the
  /// engine's emplace_back then does not zero the whole piece first).
  explicit ResolvedPiece(const ArcSegment& encoder_travel) : encoder(encoder_travel) {}

  ArcSegment encoder;            // encoder travel over the piece
  double center_m = 0.0;         // true centre travel d
  double lateral_m = 0.0;        // true lateral slip l (to the left; Systematic, "lateral")
  double angle_rad = 0.0;        // true heading change a
  double wheelbase_true_m = 0.0;
  Matrix2 intensity = Matrix2::Zero();  // cov of (e_dtheta, e_d) accumulated over the piece
};

/// The resolved path, plus what acts after the path: the measurement hooks (reference_offset).
/// A propagator that has the mean end pose (true, start frame) and its covariance P (world
/// frame) calls `measure(pose, P)`: the pose becomes the measured one and P becomes
/// J P J^T with the hooks' first-order Jacobian. The measured mean error is then
/// measure(true pose) - odometry.
struct ResolvedPath {
  std::vector<ResolvedPiece> pieces;
  int run_constants = 0;
  /// Piece after piece, the 3 x run_constants effect of each standard-normal per-run constant on
  /// (e_dtheta, e_d, e_lat), spread uniformly along the piece as its own motion is (column-major;
  /// empty without per-run constants, so that a piece stays small on the common path).
  std::vector<double> input_columns;
  std::vector<std::shared_ptr<const Effect>> measurement_effects;

  Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic>> columns(std::size_t piece) const {
    return {input_columns.data() + 3 * static_cast<std::size_t>(run_constants) * piece, 3, run_constants};
  }
  void measure(Vector3& pose, Matrix3& P_world) const;
};

/// Applies every effect's model side to each encoder piece (systematic factors for the piece's
/// motion first, then each effect's `model`) for a robot (nominal wheelbase, model's wheel
/// noise). `durations_s` gives each piece's duration (empty: unknown, so the motion's dt and v
/// are NaN); `heading0_rad` the run's start heading in the reference's frame (the `heading`
/// variable of custom effects). A piece is cut where a history effect changes its terms inside
/// it (Effect::split_at) and, for effects whose terms vary smoothly along it
/// (Effect::refines), where one evaluation at its middle would miss their mean along it.
ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces,
                     const std::vector<double>& durations_s, const Robot& robot,
                     const EffectList& effects, double heading0_rad = 0.0);

/// The largest error resolve allows in a piece's terms (scales, wheelbase and noise factors,
/// lateral slip per metre) from evaluating them once at the piece's middle instead of along it:
/// the error of the mean then stays far below any Monte-Carlo error (1e-7 of the travel).
inline constexpr double kRefineTolerance = 1e-7;
/// resolve halves a piece at most this many times for kRefineTolerance (2^8 parts).
inline constexpr int kMaxRefineDepth = 8;

/// A catalogue entry: the public description plus the factory.
struct EffectType {
  EffectInfo info;
  std::unique_ptr<Effect> (*make)(const std::vector<double>& values);
};

/// The registry (registry.cpp): every effect, in SPEC order.
const std::vector<EffectType>& registry();

/// Builds effect objects from specs; throws EffectError (check_effects) for an invalid list.
std::vector<std::unique_ptr<Effect>> instantiate(const EffectList& list);

/// A custom effect's world and model sides (custom.cpp), for a spec that carries its definition.
std::unique_ptr<Effect> make_custom(const EffectSpec& spec);

/// The registry entry of a name; throws EffectError when unknown.
const EffectType& type_of(const std::string& name);

}  // namespace odomcov::effects
