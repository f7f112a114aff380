// What fit and diagnose know about candidates: the robot parameters a fit can move, and the
// candidate list (every registered effect, from its own EffectInfo, plus the robot's wheel
// noise level). calibration.cpp and diagnosis.cpp hold no effect's name; adding a catalogue
// effect is its file and its registry line.
#include <algorithm>
#include <cmath>

#include "effects/effect.hpp"
#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/diagnosis.hpp"

namespace odomcov {

CandidateType effect_candidate(const EffectInfo& info) {
  CandidateType c;
  c.name = info.name;
  c.effect = info.name;
  c.physics = info.physics;
  c.signature = info.signature;
  c.systematic = info.systematic;
  c.complete = info.complete;
  c.contains = info.contains;
  c.on_boundary = true;
  for (const EffectParameterInfo& p : info.parameters) {
    const bool fitted = info.diagnose_fitted.empty() ||
                        std::find(info.diagnose_fitted.begin(), info.diagnose_fitted.end(), p.name) !=
                            info.diagnose_fitted.end();
    if (!fitted) continue;
    c.fitted.push_back(info.name + "." + p.name);
    c.on_boundary = c.on_boundary && p.neutral_at_edge();
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
