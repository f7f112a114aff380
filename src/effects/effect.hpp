// The internal interface every effect implements: its world side (hooks the simulator calls)
// and its model side (what it adds to the linearised propagation of one piece). Adding an effect
// is one file in this folder plus one line in registry.cpp.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <vector>

#include "odomcov/closed_form.hpp"
#include "odomcov/effects.hpp"
#include "odomcov/path.hpp"
#include "random.hpp"

namespace odomcov::effects {

/// Counter-based draws for one effect slot in one run (random.hpp): per-sample draws at
/// (run, sample, kTagEffect | slot << 8 | index), per-run draws at (run, index,
/// kTagPerRun | slot << 8). Streams never overlap the wheel noise or other effects.
class Draws {
 public:
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
  random::Philox::key_type key_;
  std::uint64_t run_;
  std::uint32_t slot_;
};

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
  double travel_left = 0.0;       // systematic true travel (scale x encoder)
  double travel_right = 0.0;
  double wheelbase = 0.0;         // true wheelbase
  double extra_left = 0.0;        // output: travel the effect adds to each wheel
  double extra_right = 0.0;
};

/// One constant-curvature piece on the model side. The engine fills the inputs, the plain
/// robot's values and the systematic factors (every effect's `systematic`, folded in first as on
/// the world side, so no effect's model depends on the order effects are listed); each effect's
/// `model` then adds what it models.
struct PieceModel {
  ArcSegment encoder;        // input: encoder travel over the piece
  double wheelbase_m = 0.0;  // input: nominal wheelbase
  WheelNoise noise;          // input: the model's wheel noise constants
  double scale_left = 1.0;   // input, systematic: true travel = scale x encoder travel
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

  // ---- World side ---------------------------------------------------------------------------
  /// Systematic factors on true travel and wheelbase, folded into the path once.
  virtual void systematic(double& scale_left, double& scale_right, double& wheelbase_factor) const {
    (void)scale_left, (void)scale_right, (void)wheelbase_factor;
  }
  /// True when the hooks below do anything (the simulator then runs its general kernel).
  virtual bool stochastic() const { return false; }
  virtual void begin_run(RunState& state, const Draws& draws) const { (void)state, (void)draws; }
  /// Acts on the standard normals of the two wheels' noise before they are scaled.
  virtual void shape_noise(double& z_left, double& z_right) const { (void)z_left, (void)z_right; }
  virtual void perturb(WorldSample& sample, RunState& state, const Draws& draws) const {
    (void)sample, (void)state, (void)draws;
  }

  // ---- Model side (first order in the effect) ------------------------------------------------
  /// Number of standard-normal per-run constants this effect contributes columns for.
  virtual int run_constants() const { return 0; }
  /// The effect's random part on one piece (systematic factors are already in `piece`).
  virtual void model(PieceModel& piece) const { (void)piece; }
};

/// A piece as every propagator sees it once the effects have spoken: the true motion (systematic
/// factors applied), the white noise intensity of (e_dtheta, e_d) over the piece, and the effect
/// of each standard-normal per-run constant on (e_dtheta, e_d). The first-order engine (predict)
/// and any higher-order propagator consume these, so effects are modelled in one place.
struct ResolvedPiece {
  ArcSegment encoder;            // encoder travel over the piece
  double center_m = 0.0;         // true centre travel d
  double angle_rad = 0.0;        // true heading change a
  double wheelbase_true_m = 0.0;
  Matrix2 intensity = Matrix2::Zero();  // cov of (e_dtheta, e_d) accumulated over the piece
  Eigen::MatrixXd input_columns;        // 2 x run_constants: per-run constants -> (e_dtheta, e_d)
};

struct ResolvedPath {
  std::vector<ResolvedPiece> pieces;
  int run_constants = 0;
};

/// Applies every effect's model side to each encoder piece (systematic factors first, then each
/// effect's `model`) for a robot (nominal wheelbase, model's wheel noise).
ResolvedPath resolve(const std::vector<ArcSegment>& encoder_pieces, const Robot& robot,
                     const EffectList& effects);

/// A catalogue entry: the public description plus the factory.
struct EffectType {
  EffectInfo info;
  std::unique_ptr<Effect> (*make)(const std::vector<double>& values);
};

/// The registry (registry.cpp): every effect, in SPEC order.
const std::vector<EffectType>& registry();

/// Builds effect objects from specs (which must have passed check_effect).
std::vector<std::unique_ptr<Effect>> instantiate(const EffectList& list);

}  // namespace odomcov::effects
