// What fit and diagnose know about parameters and candidates, in one place beside the effects:
// each effect parameter's fit coordinate (derived from its declared range), the robot
// parameters a fit can move, and the candidate list (every registered effect, from its own
// EffectInfo, plus the robot's wheel noise level). calibration.cpp and diagnosis.cpp hold no
// effect's name; adding a catalogue effect is its file and its registry line.
#include <algorithm>
#include <cmath>

#include "effect.hpp"
#include "odomcov/calibration.hpp"
#include "odomcov/diagnosis.hpp"

namespace odomcov {

FitCoordinate fit_coordinate(const EffectParameterInfo& p) {
  FitCoordinate c;
  const double scale = std::abs(p.typical - p.neutral);
  c.fd_abs = 0.05 * std::max(scale, 1e-9);
  c.fd_rel = 0.05;
  c.fd_origin = p.neutral;
  using T = FitCoordinate::Transform;
  if (p.lower <= -1e300 && p.upper >= 1e300) {  // signed and unbounded (reference_offset.dx)
    c.transform = T::identity;
    c.lower_u = p.neutral - 1e4 * scale;
    c.upper_u = p.neutral + 1e4 * scale;
    c.step_u = std::max(scale, 1e-6);
  } else if (p.open_lower && p.lower == 0.0 && p.upper >= 1e300 && p.neutral == 1.0) {
    c.transform = T::log;  // a positive scale factor (Ed, Eb, Es)
    c.lower_u = std::log(0.5);
    c.upper_u = std::log(2.0);
    c.step_u = std::max(scale, 1e-3);
  } else if (p.open_lower && p.lower == 0.0 && p.upper >= 1e300) {
    c.transform = T::log;  // any other positive quantity
    const double typical = p.typical > 0 ? p.typical : 1.0;
    c.lower_u = std::log(typical) - std::log(1e6);
    c.upper_u = std::log(typical) + std::log(1e6);
    c.step_u = 0.3;
  } else if (p.open_lower && p.open_upper) {  // an open interval (a, b), e.g. rho in (-1, 1)
    c.transform = T::atanh;
    c.mid = 0.5 * (p.lower + p.upper);
    c.half = 0.5 * (p.upper - p.lower);
    c.lower_u = -6.0;
    c.upper_u = 6.0;
    c.step_u = 0.3;
  } else {  // a size that may be zero (slip, per-run sigma, bump rate and size)
    c.transform = T::sqrt;
    c.lower_u = 0.0;
    c.upper_u = std::sqrt(1e4 * p.typical);
    c.step_u = 0.5 * std::sqrt(p.typical);
  }
  return c;
}

CandidateType effect_candidate(const EffectInfo& info) {
  CandidateType c;
  c.name = info.name;
  c.effect = info.name;
  c.physics = info.physics;
  c.signature = info.signature;
  c.systematic = info.systematic;
  c.heavy_tails = info.heavy_tails;
  c.confused_with = info.confused_with;
  c.complete = info.complete;
  c.on_boundary = true;
  for (const EffectParameterInfo& p : info.parameters) {
    const bool fitted = info.diagnose_fitted.empty() ||
                        std::find(info.diagnose_fitted.begin(), info.diagnose_fitted.end(), p.name) !=
                            info.diagnose_fitted.end();
    if (!fitted) continue;
    c.fitted.push_back(info.name + "." + p.name);
    c.on_boundary = c.on_boundary && p.neutral == p.lower && !p.open_lower;
  }
  return c;
}

namespace {

/// Wheel noise constants: log coordinates over (1e-9, 1) m^1/2.
FitCoordinate wheel_noise_coordinate(const Robot&) {
  FitCoordinate c;
  c.transform = FitCoordinate::Transform::log;
  c.lower_u = std::log(1e-9);
  c.upper_u = std::log(1.0);
  c.step_u = 0.3;
  c.fd_abs = 1e-9;
  c.fd_rel = 0.05;
  return c;
}

/// The nominal wheelbase (the one the odometry uses): log coordinates within a factor 2.
FitCoordinate wheelbase_coordinate(const Robot& robot) {
  FitCoordinate c;
  c.transform = FitCoordinate::Transform::log;
  c.lower_u = std::log(0.5 * robot.wheelbase_m);
  c.upper_u = std::log(2.0 * robot.wheelbase_m);
  c.step_u = 0.01;
  c.fd_abs = 1e-4 * robot.wheelbase_m;
  return c;
}

/// The robot's wheel noise at another level: k_left and k_right refitted.
CandidateType wheel_noise_level() {
  CandidateType c;
  c.name = kWheelNoiseLevel;
  c.physics = "wheel noise at another level than the model's";
  c.signature = "variance off in every experiment, growing with distance as wheel noise does";
  c.fitted = {"k_left", "k_right"};
  c.robot = true;
  return c;
}

}  // namespace

const std::vector<RobotParameter>& robot_parameters() {
  static const std::vector<RobotParameter> params{
      {"k_left", [](Robot& r) -> double& { return r.noise.k_left; }, wheel_noise_coordinate},
      {"k_right", [](Robot& r) -> double& { return r.noise.k_right; }, wheel_noise_coordinate},
      {"wheelbase", [](Robot& r) -> double& { return r.wheelbase_m; }, wheelbase_coordinate},
  };
  return params;
}

const std::vector<CandidateType>& candidate_types() {
  static const std::vector<CandidateType> types = [] {
    std::vector<CandidateType> out;
    for (const effects::EffectType& t : effects::registry()) out.push_back(effect_candidate(t.info));
    out.push_back(wheel_noise_level());
    return out;
  }();
  return types;
}

const CandidateType* find_candidate(const std::string& name) {
  for (const CandidateType& c : candidate_types()) {
    if (c.name == name) return &c;
  }
  return nullptr;
}

}  // namespace odomcov
