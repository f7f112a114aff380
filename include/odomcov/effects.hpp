// Physical effects (docs/formats.md, "Effect catalogue"): what a real robot does beyond white
// wheel noise. Each effect has a world side (the simulator's exact perturbation) and a model
// side (its first-order contribution to the predicted mean and covariance). The catalogue and
// its implementations live in src/effects/, one file per effect.
#pragma once

#include <string>
#include <vector>

#include "odomcov/error.hpp"

namespace odomcov {

/// At most this many effects in one list: each has its own random-stream slot (random.hpp).
inline constexpr std::size_t kMaxEffects = 16;

/// One effect with its parameter values, in the catalogue's parameter order.
struct EffectSpec {
  std::string name;
  std::vector<double> values;

  bool operator==(const EffectSpec& other) const {
    return name == other.name && values == other.values;
  }
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

struct Suite;
/// diagnose's completion of a candidate (EffectInfo::complete): `spec` holds the fitted values,
/// `stderrs` one entry per parameter (NaN where not fitted); it sets what the likelihood cannot
/// determine and returns a note on how, for the report ("" for none).
using CandidateCompletion = std::string (*)(const Suite& suite, double wheelbase_m, EffectSpec& spec,
                                            std::vector<double>& stderrs);

struct EffectInfo {
  std::string name;
  std::vector<EffectParameterInfo> parameters;
  std::string physics;    // what it is, in plain words
  std::string signature;  // how it shows in the data
  std::string summary;    // the catalogue's one-line definition (docs/formats.md)
  /// True when the effect moves the mean (a systematic error: Ed, Eb, Es); false when it only
  /// adds randomness, which shows in the covariance (and the tails).
  bool systematic = false;
  /// True when the effect makes the errors non-Gaussian (heavy tails): a model with it expects
  /// the kurtosis compare tests for.
  bool heavy_tails = false;
  // ---- What diagnose needs to know (so that diagnosis and calibration hold no effect names).
  /// The parameters diagnose fits for this candidate; empty: all of them (bumps: rate only, as
  /// a Gaussian likelihood sees rate and sigma only through rate sigma^2).
  std::vector<std::string> diagnose_fitted{};
  /// What completes the candidate after its fit (bumps: sigma from the tails); may be nullptr.
  CandidateCompletion complete = nullptr;
  /// The candidate a Gaussian likelihood cannot tell this one apart from ("" for none): when both
  /// are significant, heavy tails put the one with heavy_tails first, Gaussian tails the other.
  std::string confused_with{};
};

/// Every effect of the catalogue, in the order of docs/formats.md.
const std::vector<EffectInfo>& effect_catalogue();
/// nullptr when unknown.
const EffectInfo* find_effect(const std::string& name);

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

/// Throws EffectError unless every spec passes check_effect, no name repeats and the list has
/// at most kMaxEffects entries. Every entry point that builds effects (Simulator, predict,
/// resolve) calls it.
void check_effects(const EffectList& list);

/// The spec as a YAML list entry, e.g. "- wheel_diameter_ratio: {Ed: 1.0041}".
std::string effect_yaml(const EffectSpec& spec);

}  // namespace odomcov
