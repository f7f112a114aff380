// Physical effects (docs/formats.md, "Effect catalogue"): what a real robot does beyond white
// wheel noise. Each effect has a world side (the simulator's exact perturbation) and a model
// side (its first-order contribution to the predicted mean and covariance). The catalogue and
// its implementations live in src/effects/, one file per effect.
#pragma once

#include <memory>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "odomcov/base/error.hpp"
#include "odomcov/closed_form/path.hpp"

namespace odomcov {

/// At most this many effects in one list: each has its own random-stream slot (random.hpp).
inline constexpr std::size_t kMaxEffects = 16;

struct CustomEffect;

/// One effect with its parameter values, in the catalogue's parameter order (for a custom
/// effect, in the order of its definition's parameters).
struct EffectSpec {
  std::string name;
  std::vector<double> values;
  /// group_variation only: the parameter it varies between groups, "<effect>.<parameter>" of
  /// another effect in the same list (e.g. "wheelbase_error.Eb"); empty for every other effect.
  std::string target = {};
  /// The definition of a custom effect (docs/effects.md, "Custom effects"); null for a
  /// catalogue effect.
  std::shared_ptr<const CustomEffect> custom = nullptr;

  bool operator==(const EffectSpec& other) const;
};
using EffectList = std::vector<EffectSpec>;

struct EffectParameterInfo {
  std::string name;
  std::string unit;
  double lower = 0.0;  // valid values lie between lower and upper
  double upper = 0.0;
  bool open_lower = false;  // lower itself excluded
  bool open_upper = false;
  double neutral = 0.0;  // the value at which the effect does nothing
  double typical = 0.0;  // a moderate size, e.g. for starting a fit
  /// True for a size that plausibly changes between groups of runs (days, loads) even when the
  /// model does not have its effect yet (wheelbase_error.Eb, wheel_diameter_ratio.Ed: tyre
  /// pressure, load): diagnose then tries group_variation of it.
  bool varies_between_groups = false;
  /// True for the std-dev of a parameter a custom effect draws per run (`random: {p: sd}`, the
  /// fit parameter <name>.sd_p): a spread, fitted on the scatter and never varied by groups.
  bool random_sd = false;

  /// True when "no effect" is the closed lower edge of the range (a rate, a spread at 0): a
  /// likelihood ratio for the parameter is then a 50:50 chi^2 mixture [Self87].
  bool neutral_at_edge() const { return neutral == lower && !open_lower; }
};

/// How a fit moves one parameter: the coordinate u its optimiser sees (v = f(u)), the box and
/// initial step in u, and the fast path's difference step in v, max(fd_abs, fd_rel |v - fd_origin|).
struct FitCoordinate {
  enum class Transform { log, atanh, sqrt, identity };
  Transform transform = Transform::identity;
  double lower_u = -1e300, upper_u = 1e300;
  double step_u = 0.1;
  double mid = 0.0, half = 1.0;  // atanh: the open interval (mid - half, mid + half)
  double fd_abs = 0.0, fd_rel = 0.0, fd_origin = 0.0;
};

/// A parameter's fit coordinate, derived from its declared range: identity for a signed,
/// unbounded one (reference_offset.dx); log for a positive scale factor, range (0, inf) with
/// neutral 1 (Ed, Eb, Es; box [1/2, 2]); log for any other (0, inf) parameter (box typical
/// x 1e-6 .. 1e6); scaled atanh for an open interval (a, b) (rho in (-1, 1)); square root for a
/// size that may be zero, [0, inf) (slip, per-run sigma, bump rate).
FitCoordinate fit_coordinate(const EffectParameterInfo& p);

/// What a candidate's completion (EffectInfo::complete) sees of a suite: per experiment, its
/// planned path (nullptr for runs with their own encoder logs) and its runs' errors (measured -
/// odometry, start frame, at the model's wheelbase).
struct ObservedExperiment {
  const Path* path = nullptr;
  std::vector<Vector3> errors;
};

/// diagnose's completion of a candidate (EffectInfo::complete): `spec` holds the fitted values,
/// `stderrs` one entry per parameter (NaN where not fitted); it sets what the likelihood cannot
/// determine and returns a note on how, for the report ("" for none).
using CandidateCompletion = std::string (*)(const std::vector<ObservedExperiment>& data,
                                            EffectSpec& spec, std::vector<double>& stderrs);

/// An effect whose tails the Gaussian likelihood cannot see (bumps): makes its impulses `factor`
/// times larger at the same variance (bumps: sigma x factor, rate / factor^2), so the fourth
/// cumulant it adds, and the excess kurtosis of the errors, grow by factor^2. diagnose uses it
/// to give an adopted effect the data's kurtosis in the model's simulated world.
using TailRescale = void (*)(EffectSpec& spec, double factor);

struct EffectInfo {
  std::string name;
  std::vector<EffectParameterInfo> parameters;
  std::string physics;    // what it is, in plain words
  std::string signature;  // how it shows in the data
  std::string summary;    // the catalogue's one-line definition (docs/formats.md)
  /// True when the effect moves the mean (a systematic error: Ed, Eb, Es); false when it only
  /// adds randomness, which shows in the covariance (and the tails).
  bool systematic = false;
  /// True when the effect acts across the runs of a group (group_variation): it is not seen by
  /// one run alone, so the simulator of one path and the model of one run leave it out; synth
  /// draws it per group and the suite likelihood correlates the runs of a group (likelihood.hpp).
  bool grouped = false;
  // ---- What diagnose needs to know (so that diagnosis and calibration hold no effect names).
  /// The parameters diagnose fits for this candidate; empty: all of them (bumps: rate only, as
  /// a Gaussian likelihood sees rate and sigma only through rate sigma^2).
  std::vector<std::string> diagnose_fitted{};
  /// What completes the candidate after its fit (bumps: sigma from the tails); may be nullptr.
  CandidateCompletion complete = nullptr;
  /// May be nullptr; see TailRescale.
  TailRescale rescale_tails = nullptr;
  /// How many standard-normal per-run constants the model carries for the effect
  /// (per_run_radius: 2; a custom effect: one per random parameter); a model holds at most
  /// kMaxRunConstants (4) in all.
  int run_constants = 0;
  /// True when the effect depends on the run's absolute heading (the `heading` variable): each
  /// run is then predicted with its own start heading (SuiteRun::heading0_rad).
  bool uses_start_heading = false;
  /// True when the effect depends on the acceleration along the path (the `a` variable), which on
  /// a planned path changes only at the first sample of each stretch of equal samples: the model
  /// then sets those samples apart as pieces of their own (path_model_pieces).
  bool uses_acceleration = false;
  /// The catalogue effects this one reduces to exactly at some of its parameter values
  /// (turn_dependent_wheelbase at Eb_arc = Eb_spin is wheelbase_error): diagnose adopts it over
  /// one of them only when it fits significantly better (a likelihood ratio of nested models).
  std::vector<std::string> contains{};
  /// True when the effect acts only on what the external reference sees (a measurement hook,
  /// Effect::measure_model) and never on the motion (reference_offset): a run's prediction
  /// before that view does not depend on it (predict_parts).
  bool measurement_only = false;
};

/// What predictions with a list of effects need beyond the encoder pieces and their durations.
struct EffectNeeds {
  bool start_heading = false;  // each run's start heading (an effect uses `heading`)
  bool sample_pieces = false;  // planned paths resolved where the speed changes (`a`)
};
EffectNeeds effect_needs(const EffectList& list);

/// A custom effect, defined in YAML (docs/effects.md, "Custom effects"): its own parameters
/// and up to six expressions over the per-sample variables (custom_effect_variables) and the
/// parameters, evaluated by muparser. true travel of each wheel = scale x scale_<wheel> x
/// encoder, true wheelbase = wheelbase_factor x nominal (an empty expression means 1), a lateral
/// slip of the centre of `lateral` metres to the left per metre of mean wheel travel (empty: 0),
/// and both wheels' white noise variance times `noise` (empty: 1). The parameters named in
/// `random` are drawn once per run from N(value, sd^2). Build it with define_custom_effect.
struct CustomEffect {
  /// One expression and where it was written (file, line, dotted key) for runtime errors.
  struct Expression {
    std::string text;  // "" = the key's neutral value (1, or 0 for lateral)
    std::string file;
    int line = 0;
    std::string key;
  };
  std::string name;
  std::vector<std::string> parameters;
  /// The parameters drawn once per run (`random: {p: sd}`), in the order written; each one's sd
  /// is a value of the spec after the parameters' own (fit parameter <name>.sd_<p>).
  std::vector<std::string> random;
  std::string file;  // where the definition was written, for messages
  int line = 0;
  std::string key;
  Expression scale, scale_left, scale_right, wheelbase_factor, lateral, noise;
  /// The description fit and diagnose use: the parameters unbounded and signed (identity fit
  /// transform), neutral at the starting value, then each random parameter's sd_<p> (>= 0,
  /// square-root fit coordinate); systematic unless the effect only shapes the noise.
  EffectInfo info;
  /// What the expressions depend on, set by define_custom_effect: 0 nothing, 1 the increment
  /// (v, kappa, r, dir, turn, omega), 2 the history (s, t, a, theta, heading).
  int dependence = 0;
  /// Set by define_custom_effect: an expression uses s, t, theta or heading (smooth along a
  /// piece: the model cuts pieces finer where they are not linear along it).
  bool smooth_history = false;

  /// The effect's expressions with their YAML keys, in the order they are written.
  std::vector<std::pair<const char*, const Expression*>> expressions() const;
  std::vector<std::pair<const char*, Expression*>> expressions();
  bool operator==(const CustomEffect& other) const;
};

/// The per-sample variables a custom effect's expressions may use, in the SPEC's order:
/// v, kappa, r, dir, turn, s, t, a, omega, theta, heading. A parameter may take the name of one
/// of the last four (added after custom effects were first released: a definition with a
/// parameter `a` keeps its meaning), which then hides that variable in its effect.
const std::vector<std::string>& custom_effect_variables();

/// The most parameters a custom effect may draw per run (`random:`): each is a per-run constant
/// of the model (kMaxRunConstants in all).
inline constexpr std::size_t kMaxRandomParameters = 4;

/// "" when `text` compiles with the variables and these parameter names, else muparser's
/// message (e.g. "Unexpected token \"x\" found at position 4.").
std::string check_custom_expression(const std::string& text,
                                    const std::vector<std::string>& parameters);

/// "" when `name` can name a custom effect or one of its parameters (an identifier of letters,
/// digits and '_', not starting with a digit, not a variable's name), else why not.
std::string check_custom_name(const std::string& name);

/// Builds a custom effect definition and its spec with the starting values: the parameters',
/// then each random parameter's sd. Throws InputError (file, line and key of the offending
/// expression) for a bad expression or name, a name that clashes with a catalogue effect, a
/// random parameter that is not a parameter, or an sd that is negative or not finite.
EffectSpec define_custom_effect(CustomEffect definition, const std::vector<double>& start);

/// Every effect of the catalogue, in the order of docs/formats.md.
const std::vector<EffectInfo>& effect_catalogue();
/// The one lookup of an effect by name: a custom effect defined in `context` (a model's or a
/// candidate list's effects) first, then the catalogue; nullptr when unknown.
const EffectInfo* find_effect(const std::string& name, const EffectList& context = {});
/// The description of a spec: its custom definition's, or the catalogue's (nullptr when
/// unknown).
const EffectInfo* info_of(const EffectSpec& spec);
/// The spec named `name` in `list`; nullptr when absent.
const EffectSpec* find_spec(const EffectList& list, const std::string& name);
EffectSpec* find_spec(EffectList& list, const std::string& name);

/// "" when the values are valid for the effect, else what is wrong ("Ed must be > 0").
std::string check_effect(const EffectSpec& spec);

/// What the library throws for an effect list given through the API that is not valid: an
/// unknown name, the wrong number of values, a value out of range, an effect listed twice, more
/// than kMaxEffects effects, or (from the Simulator) a path an effect cannot be simulated on.
/// An InputError whose key names the list entry ("effects[1].bumps"), so the CLI reports it as
/// bad input (exit 2).
class EffectError : public InputError {
 public:
  EffectError(const std::string& key, const std::string& what) : InputError("", 0, key, what) {}
};

/// The candidate that refits the robot's white wheel noise (k_left, k_right) rather than adding
/// an effect.
inline constexpr const char* kWheelNoiseLevel = "wheel_noise_level";

/// The name of the one effect that varies another effect's parameter between groups.
inline constexpr const char* kGroupVariation = "group_variation";

/// "" when the list's group_variation (if any) names a parameter of another effect in the list
/// that moves the mean (a systematic effect), else what is wrong.
std::string check_group_target(const EffectList& list);

/// Where a list's group_variation points: the varied effect's index in the list, the index of
/// the parameter within it, and the between-group std-dev. `present` is false without one.
struct GroupTarget {
  bool present = false;
  std::size_t effect = 0, parameter = 0;
  double sd = 0.0;
};
GroupTarget group_target(const EffectList& list);

/// The effects one group of runs sees (world side): the list without group_variation, its
/// target parameter drawn from N(value, sd^2) by a counter-based draw keyed on (seed, group
/// name), so every experiment of a group gets the same value whatever the order or thread
/// count. Throws EffectError when the draw leaves the parameter's range (sd far too large).
EffectList group_effects(const EffectList& list, std::uint64_t seed, const std::string& group);

/// The most standard-normal per-run constants one model may carry (EffectInfo::run_constants).
inline constexpr int kMaxRunConstants = 4;
/// "" when the list's effects carry at most kMaxRunConstants per-run constants, else what is wrong.
std::string check_run_constants(const EffectList& list);

/// Throws EffectError unless every spec passes check_effect, no name repeats, a group_variation
/// names a systematic parameter of the list (check_group_target) and the list has
/// at most kMaxEffects entries. Every entry point that builds effects (Simulator, predict,
/// resolve) calls it.
void check_effects(const EffectList& list);

/// "" when every effect of the list adds only Gaussian noise or deterministic changes on the
/// world side, else the first that does not and why ("bumps: Poisson impulses (heavy tails)").
/// An effect at a size where it does nothing (bumps at rate 0) counts as Gaussian. compare
/// takes its Gaussian tests as exact only for such a list (docs/diagnose.md, "How compare
/// decides"). Throws EffectError for an invalid list.
std::string non_gaussian_effect(const EffectList& list);

/// True when an effect of the list gives errors with heavier tails than Gaussian ones on the
/// world side (bumps at a size where they act). Throws EffectError for an invalid list.
bool heavy_tailed_effect(const EffectList& list);

/// The spec as a YAML list entry, e.g. "- wheel_diameter_ratio: {Ed: 1.0041}" or
/// "- group_variation: {parameter: wheelbase_error.Eb, sd: 0.002}", or for a custom effect its
/// whole definition with the current values as starting values, on one line.
std::string effect_yaml(const EffectSpec& spec);

}  // namespace odomcov
