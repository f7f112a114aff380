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
  return {suite.robot, suite.model_effects, suite.measurement_noise};
}

std::string robot_yaml(const Robot& robot) {
  return "robot: {wheelbase: " + format_number(robot.wheelbase_m) + ", k_left: " +
         format_number(robot.noise.k_left) + ", k_right: " + format_number(robot.noise.k_right) + "}";
}

std::string model_yaml(const SuiteModel& model) {
  std::string text = robot_yaml(model.robot) + "\n";
  if (!model.effects.empty()) {
    text += "model:\n  effects:\n";
    for (const EffectSpec& e : model.effects) text += "    " + effect_yaml(e) + "\n";
  }
  return text;
}


}  // namespace odomcov
