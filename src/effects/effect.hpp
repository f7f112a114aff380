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
};

/// Builds the Motion of consecutive increments, keeping time, distance and each wheel's
/// direction. `wheelbase_m` is the nominal one (curvature as the encoders see it).
class MotionTracker {
 public:
  explicit MotionTracker(double wheelbase_m) : wheelbase_m_(wheelbase_m) {}
  /// The Motion of the next increment (the first of `count` identical ones), then advances past
  /// all `count` of them.
  Motion next(double dL_m, double dR_m, double dt_s, std::int64_t count = 1);

 private:
  double wheelbase_m_;
  double t_s_ = 0.0, s_m_ = 0.0;
  int dir_left_ = 1, dir_right_ = 1;
  double since_left_ = HUGE_VAL, since_right_ = HUGE_VAL;
};

/// What a systematic effect does to one increment's true motion: true travel of each wheel =
/// scale x encoder + offset, true wheelbase = factor x nominal. Effects compose: scales and the
/// factor multiply, offsets add (applied after every scale).
struct Systematic {
  double scale_left = 1.0, scale_right = 1.0;
  double wheelbase_factor = 1.0;
  double offset_left_m = 0.0, offset_right_m = 0.0;

  bool operator==(const Systematic& o) const {
    return scale_left == o.scale_left && scale_right == o.scale_right &&
           wheelbase_factor == o.wheelbase_factor && offset_left_m == o.offset_left_m &&
           offset_right_m == o.offset_right_m;
  }
  ArcSegment travel(double dL_m, double dR_m) const {
    return {scale_left * dL_m + offset_left_m, scale_right * dR_m + offset_right_m};
  }
};

/// What a systematic effect's factors depend on, so the simulator knows how often to evaluate
/// them: never (`none`: once per path), on the increment only (`increment`: dL, dR, dt, v,
/// kappa, r, dir, turn, constant along a leg of equal samples), or on the history (`history`:
/// t, s or the reversal state, evaluated per sample).
enum class Dependence { none = 0, increment = 1, history = 2 };

/// What an effect keeps from one sample to the next within a run (per-run constants, the
/// distance to the next bump); zeroed by the simulator before begin_run.
struct RunState {
  double value[4] = {0.0, 0.0, 0.0, 0.0};
};

/// One sample on the world side as the per-sample hook sees it.
struct WorldSample {
  std::uint32_t index = 0;        // sample index within the run
  double encoder_left = 0.0;      // encoder increments
  double encoder_right = 0.0;
  double wheelbase_nominal = 0.0;
  double travel_left = 0.0;       // systematic true travel (scale x encoder + offset)
  double travel_right = 0.0;
  double wheelbase = 0.0;         // true wheelbase of this sample
  double extra_left = 0.0;        // output: travel the effect adds to each wheel
  double extra_right = 0.0;
};

/// One constant-curvature piece on the model side. The engine fills the inputs, the plain
/// robot's values and the systematic factors (every effect's `systematic` for this piece's
/// motion, folded in first as on the world side, so no effect's model depends on the order
/// effects are listed); each effect's `model` then adds what it models.
struct PieceModel {
  ArcSegment encoder;        // input: encoder travel over the piece
  double wheelbase_m = 0.0;  // input: nominal wheelbase
  WheelNoise noise;          // input: the model's wheel noise constants
  Motion motion;             // input: the piece's motion
  double scale_left = 1.0;   // input, systematic: true travel = scale x encoder (+ offset)
  double scale_right = 1.0;
  double wheelbase_factor = 1.0;  // input, systematic: true wheelbase = factor x nominal
  Eigen::Matrix2d wheel_cov = Eigen::Matrix2d::Zero();  // white (e_L, e_R) over the piece
  double heading_var = 0.0;  // extra white heading variance over the piece
  /// One column per standard-normal per-run constant: its effect on (e_L, e_R) over the piece.
  std::vector<Eigen::Vector2d> run_columns;
};

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

  // ---- World side: randomness -----------------------------------------------------------------
  /// True when the hooks below do anything (the simulator then runs its general kernel).
  virtual bool stochastic() const { return false; }
  virtual void begin_run(RunState& state, const Draws& draws) const { (void)state, (void)draws; }
  /// Acts on the standard normals of the two wheels' noise before they are scaled.
  virtual void shape_noise(double& z_left, double& z_right) const { (void)z_left, (void)z_right; }
  virtual void perturb(WorldSample& sample, RunState& state, const Draws& draws) const {
    (void)sample, (void)state, (void)draws;
  }

  /// World side: "" when the effect adds only Gaussian noise or deterministic changes, else what
  /// makes the errors it gives non-Gaussian ("a radius drawn once per run"): compare then
  /// calibrates its tests by simulating the model's world (non_gaussian_effect).
  virtual std::string non_gaussian() const { return ""; }

  // ---- Model side (first order in the effect) ------------------------------------------------
  /// Number of standard-normal per-run constants this effect contributes columns for.
  virtual int run_constants() const { return 0; }
  /// The effect's random part on one piece (systematic factors are already in `piece`).
  virtual void model(PieceModel& piece) const { (void)piece; }
};

/// The most standard-normal per-run constants a model may carry (per_run_radius has two); the
/// engine keeps their columns in fixed storage.
inline constexpr int kMaxRunConstants = 4;

/// A piece as every propagator sees it once the effects have spoken: the true motion (systematic
/// factors applied), the white noise intensity of (e_dtheta, e_d) over the piece, and the effect
/// of each standard-normal per-run constant on (e_dtheta, e_d). The first-order engine (predict)
/// and any higher-order propagator consume these, so effects are modelled in one place.
struct ResolvedPiece {
  /// Built from its encoder travel, the rest set by resolve (a user-provided constructor: the
  /// engine's emplace_back then does not zero the whole piece first).
  explicit ResolvedPiece(const ArcSegment& encoder_travel) : encoder(encoder_travel) {}

  ArcSegment encoder;            // encoder travel over the piece
  double center_m = 0.0;         // true centre travel d
  double angle_rad = 0.0;        // true heading change a
  double wheelbase_true_m = 0.0;
  Matrix2 intensity = Matrix2::Zero();  // cov of (e_dtheta, e_d) accumulated over the piece
  // 2 x run_constants: per-run constants -> (e_dtheta, e_d)
  Eigen::Matrix<double, 2, Eigen::Dynamic, 0, 2, kMaxRunConstants> input_columns;
};

/// The resolved path, plus what acts after the path: the measurement hooks (reference_offset).
/// A propagator that has the mean end pose (true, start frame) and its covariance P (world
/// frame) calls `measure(pose, P)`: the pose becomes the measured one and P becomes
/// J P J^T with the hooks' first-order Jacobian. The measured mean error is then
/// measure(true pose) - odometry.
struct ResolvedPath {
  std::vector<ResolvedPiece> pieces;
  int run_constants = 0;
  std::vector<std::shared_ptr<const Effect>> measurement_effects;

  void measure(Vector3& pose, Matrix3& P_world) const;
};

/// Applies every effect's model side to each encoder piece (systematic factors for the piece's
/// motion first, then each effect's `model`) for a robot (nominal wheelbase, model's wheel
/// noise). `durations_s` gives each piece's duration (empty: unknown, so the motion's dt and v
/// are NaN).
ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces,
                     const std::vector<double>& durations_s, const Robot& robot,
                     const EffectList& effects);

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
