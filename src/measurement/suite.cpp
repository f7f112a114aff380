#include "odomcov/measurement/suite.hpp"

#include <algorithm>
#include <cmath>

#include "odomcov/base/format.hpp"
#include "odomcov/engine/propagation.hpp"

namespace odomcov {

Matrix3 MeasurementNoise::covariance() const {
  return Vector3(xy_m * xy_m, xy_m * xy_m, theta_rad * theta_rad).asDiagonal();
}

std::string group_key(const SuiteExperiment& ex) {
  return ex.group.empty() ? "experiment:" + ex.name : "group:" + ex.group;
}

std::string default_kind(const std::string& experiment_name) {
  return experiment_name.substr(0, experiment_name.find('-'));
}

std::string experiment_kind(const SuiteExperiment& ex) {
  return ex.kind.empty() ? default_kind(ex.name) : ex.kind;
}

Vector3 odometry_end_pose(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m) {
  if (!ex.logged) return sampled_end_pose(ex.path, wheelbase_m);
  Vector3 pose = Vector3::Zero();
  for (const ArcSegment& piece : run.pieces) pose = drive(pose, piece, wheelbase_m);
  return pose;
}

std::vector<ArcSegment> encoder_pieces(const SuiteExperiment& ex, const SuiteRun& run) {
  return ex.logged ? run.pieces : sample_arcs(ex.path);
}

Vector3 run_error(const SuiteExperiment& ex, const SuiteRun& run, double wheelbase_m) {
  return pose_error(run.measured, odometry_end_pose(ex, run, wheelbase_m));
}

Vector3 sampled_end_pose(const Path& path, double wheelbase_m) {
  Vector3 pose = Vector3::Zero();
  for (const ArcSegment& arc : sample_arcs(path)) pose = drive(pose, arc, wheelbase_m);
  return pose;
}

SuiteModel suite_model(const Suite& suite) {
  SuiteModel model{suite.robot, suite.model_effects, suite.measurement_noise};
  model.domain = suite.model_domain;
  return model;
}

std::string robot_yaml(const Robot& robot) {
  return "robot: {wheelbase: " + format_number(robot.wheelbase_m) + ", k_left: " +
         format_number(robot.noise.k_left) + ", k_right: " + format_number(robot.noise.k_right) + "}";
}

std::string domain_yaml(const Domain& d) {
  auto range = [](const char* key, const Domain::Range& r) {
    return std::string(key) + ": [" + format_number(r.lo, "%.9g") + ", " + format_number(r.hi, "%.9g") + "]";
  };
  return "domain: {" + range("speed", d.speed_mps) + ", " + range("spin_fraction", d.spin_fraction) + ", " +
         range("length", d.length_m) + ", " + range("duration", d.duration_s) + "}";
}

std::string model_yaml(const SuiteModel& model) {
  std::string text = robot_yaml(model.robot) + "\n";
  if (model.effects.empty() && !model.domain) return text;
  text += "model:\n";
  if (model.domain) text += "  " + domain_yaml(*model.domain) + "\n";
  if (!model.effects.empty()) {
    text += "  effects:\n";
    for (const EffectSpec& e : model.effects) text += "    " + effect_yaml(e) + "\n";
  }
  return text;
}


}  // namespace odomcov
