// odomcov predict LOG.csv (--wheelbase B --k-left K --k-right K | --suite SUITE | --config CONFIG)
//                 [--left-scale S] [--right-scale S] [--every N] [--csv FILE] [--json FILE]
//                 [--ros] [--ros-unused-variance V]
// Pose and covariance along an encoder log, per sample (docs/json.md, "predict").
#include <array>
#include <cmath>
#include <iostream>
#include <optional>
#include <sstream>

#include "commands.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/io/csv_import.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/odometry_covariance.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/io/suite_io.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

/// nav_msgs/Odometry's unused pose variances (z, roll, pitch): large, as ROS 2D odometry
/// publishers such as diff_drive_controller set them, so that fusing nodes ignore them.
constexpr double kRosUnusedVariance = 1e6;

struct PredictOptions {
  std::string log;
  std::optional<double> wheelbase, k_left, k_right;
  std::string suite, config;
  double left_scale = 1.0, right_scale = 1.0;
  std::int64_t every = 1;
  std::string csv, json;
  bool ros = false;
  double ros_unused_variance = kRosUnusedVariance;
};

/// The 6x6 row-major pose covariance of nav_msgs/Odometry (x, y, z, roll, pitch, yaw) from the
/// planar (x, y, theta) one: theta is yaw; z, roll and pitch are independent with `unused`.
std::array<double, 36> ros_covariance(const Matrix3& P, double unused) {
  std::array<double, 36> c{};
  const int index[3] = {0, 1, 5};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) c[static_cast<std::size_t>(6 * index[i] + index[j])] = P(i, j);
  for (int k : {2, 3, 4}) c[static_cast<std::size_t>(7 * k)] = unused;
  return c;
}

int run_predict(const PredictOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  if (!opt.csv.empty()) check_output_path(opt.csv);
  const int sources = (opt.wheelbase || opt.k_left || opt.k_right ? 1 : 0) + !opt.suite.empty() + !opt.config.empty();
  if (sources != 1) throw UsageError("give the robot once: --wheelbase/--k-left/--k-right, --suite or --config");
  if (opt.wheelbase && !(opt.k_left && opt.k_right)) throw UsageError("--wheelbase needs --k-left and --k-right");
  if (!opt.wheelbase && (opt.k_left || opt.k_right)) throw UsageError("--k-left/--k-right need --wheelbase");
  if (opt.every < 1) throw UsageError("--every must be >= 1");
  if (!(opt.left_scale != 0 && std::isfinite(opt.left_scale)) || !(opt.right_scale != 0 && std::isfinite(opt.right_scale))) {
    throw UsageError("--left-scale and --right-scale must be finite and not 0");
  }
  Robot robot;
  EffectList effects;
  std::string source;
  if (opt.wheelbase) {
    robot = {*opt.wheelbase, {*opt.k_left, *opt.k_right}};
    if (!(robot.wheelbase_m > 0) || !(robot.noise.k_left >= 0) || !(robot.noise.k_right >= 0)) {
      throw UsageError("--wheelbase must be > 0, --k-left and --k-right >= 0");
    }
    source = "command line";
  } else if (!opt.suite.empty()) {
    const Suite suite = load_suite(opt.suite);
    robot = suite.robot;
    effects = suite.model_effects;
    source = opt.suite;
  } else {
    const Config config = load_config(opt.config);
    robot = config.robot;
    effects = config.model_effects;
    source = opt.config;
  }
  const EncoderLog log = load_encoder_log(opt.log, opt.left_scale, opt.right_scale);
  const std::size_t n = log.t_s.size();
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;  // from the log's t column: speed- and time-dependent effects
  for (std::size_t i = 1; i < n; ++i) {
    pieces.push_back({log.left_m[i] - log.left_m[i - 1], log.right_m[i] - log.right_m[i - 1]});
    durations.push_back(log.t_s[i] - log.t_s[i - 1]);
  }
  std::vector<Vector3> pose(n, Vector3::Zero()), mean(n, Vector3::Zero());
  std::vector<Matrix3> cov(n, Matrix3::Zero());
  if (effects.empty()) {
    OdometryCovariance odo(robot.wheelbase_m, robot.noise);
    for (std::size_t i = 1; i < n; ++i) {
      const OdometryStep& s = odo.step(pieces[i - 1]);
      pose[i] = s.pose_world;
      cov[i] = s.P_world;
    }
  } else {
    const std::vector<Prediction> p = predict_trajectory(pieces, durations, robot, effects);
    for (std::size_t i = 0; i < n; ++i) {
      pose[i] = p[i].odometry_end_pose;
      cov[i] = p[i].cov;
      mean[i] = p[i].mean;
    }
  }
  std::vector<std::size_t> rows;
  for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(opt.every)) rows.push_back(i);
  if (rows.back() != n - 1) rows.push_back(n - 1);

  if (!opt.csv.empty()) {
    std::string text = "t,x,y,theta,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta";
    if (!effects.empty()) text += ",mean_x,mean_y,mean_theta";
    if (opt.ros) for (int k = 0; k < 36; ++k) text += ",pose_covariance_" + std::to_string(k);
    text += "\n";
    auto g = [](double v) { return format_number(v, "%.17g"); };
    for (std::size_t i : rows) {
      const Matrix3& P = cov[i];
      text += g(log.t_s[i]) + "," + g(pose[i].x()) + "," + g(pose[i].y()) + "," + g(pose[i].z()) + "," +
              g(P(0, 0)) + "," + g(P(0, 1)) + "," + g(P(0, 2)) + "," + g(P(1, 1)) + "," + g(P(1, 2)) +
              "," + g(P(2, 2));
      if (!effects.empty()) text += "," + g(mean[i].x()) + "," + g(mean[i].y()) + "," + g(mean[i].z());
      if (opt.ros) for (double c : ros_covariance(P, opt.ros_unused_variance)) text += "," + g(c);
      text += "\n";
    }
    write_file_atomic(opt.csv, text);
  }
  if (!opt.json.empty()) {
    json samples = json::array();
    for (std::size_t i : rows) {
      json s = {{"t", log.t_s[i]}, {"pose", to_json(pose[i])}, {"cov", to_json(cov[i])}};
      if (!effects.empty()) s["mean"] = to_json(mean[i]);
      if (opt.ros) s["pose_covariance"] = ros_covariance(cov[i], opt.ros_unused_variance);
      samples.push_back(s);
    }
    json eff = json::array();
    for (const EffectSpec& e : effects) eff.push_back(effect_yaml(e));
    write_json_atomic(opt.json, {{"log", opt.log},
                                 {"robot", {{"wheelbase", robot.wheelbase_m},
                                            {"k_left", robot.noise.k_left},
                                            {"k_right", robot.noise.k_right}}},
                                 {"effects", eff},
                                 {"samples", samples}});
  }
  const Vector3& end = pose.back();
  const ErrorEllipse e = error_ellipse(cov.back());
  std::ostringstream out;
  out << "odomcov predict: " << opt.log << " (" << n << " samples, " << fixed(log.t_s.back() - log.t_s.front(), 3)
      << " s), robot from " << source << ": B = " << robot.wheelbase_m << " m, kL = " << robot.noise.k_left
      << ", kR = " << robot.noise.k_right << " m^(1/2)" << (effects.empty() ? "" : ", with the model's effects")
      << "\nend pose x = " << fixed(end.x(), 4) << " m, y = " << fixed(end.y(), 4)
      << " m, theta = " << fixed(wrap_angle(end.z()) * 180.0 / M_PI, 2) << " deg\n"
      << "end covariance (world frame, x, y, theta):\n" << matrix_rows(cov.back(), "    ")
      << "1-sigma ellipse: a = " << sci(e.semi_major_m, 4) << " m, b = " << sci(e.semi_minor_m, 4)
      << " m, angle = " << fixed(e.angle_rad * 180.0 / M_PI, 2) << " deg\n"
      << rows.size() << " rows written" << (opt.csv.empty() ? "" : " to " + opt.csv)
      << (opt.json.empty() ? "" : (opt.csv.empty() ? " to " : " and ") + opt.json) << "\n";
  std::cout << out.str();
  return kExitOk;
}

}  // namespace

void setup_predict(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<PredictOptions>();
  CLI::App* cmd = app.add_subcommand(
      "predict", "Pose and covariance along an encoder log (t,left,right), per sample");
  cmd->add_option("log", opt->log, "Encoder log CSV: t,left,right (or t,left,right,x,y,theta)")->required();
  cmd->add_option("--wheelbase", opt->wheelbase, "Wheelbase B [m] (with --k-left, --k-right)");
  cmd->add_option("--k-left", opt->k_left, "Left wheel noise constant [m^(1/2)]");
  cmd->add_option("--k-right", opt->k_right, "Right wheel noise constant [m^(1/2)]");
  cmd->add_option("--suite", opt->suite, "Take the robot and model effects from a suite (e.g. fitted)");
  cmd->add_option("--config", opt->config, "Take the robot and model effects from a path config");
  cmd->add_option("--left-scale", opt->left_scale, "Metres per unit of the left column")->capture_default_str();
  cmd->add_option("--right-scale", opt->right_scale, "Metres per unit of the right column")->capture_default_str();
  cmd->add_option("--every", opt->every, "Write every N-th sample (and always the last)")->capture_default_str();
  cmd->add_option("--csv", opt->csv, "Write t, pose and covariance per row as CSV to this file");
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->add_flag("--ros", opt->ros,
                "Add the 6x6 row-major pose covariance of nav_msgs/Odometry (x, y, z, roll, pitch, yaw)");
  cmd->add_option("--ros-unused-variance", opt->ros_unused_variance,
                  "Variance written for the unused z, roll and pitch")->capture_default_str();
  cmd->callback([opt, &exit_code] { exit_code = run_predict(*opt); });
}

}  // namespace odomcov::cli
