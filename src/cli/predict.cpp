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

/// The usage rules: writable outputs, the robot from exactly one source, a complete robot on
/// the command line, --every >= 1 and usable wheel scales.
void check_options(const PredictOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  if (!opt.csv.empty()) check_output_path(opt.csv);
  const bool flags = opt.wheelbase || opt.k_left || opt.k_right;
  const int sources = (flags ? 1 : 0) + !opt.suite.empty() + !opt.config.empty();
  if (sources != 1) throw UsageError("give the robot once: --wheelbase/--k-left/--k-right, --suite or --config");
  if (opt.wheelbase && !(opt.k_left && opt.k_right)) throw UsageError("--wheelbase needs --k-left and --k-right");
  if (!opt.wheelbase && (opt.k_left || opt.k_right)) throw UsageError("--k-left/--k-right need --wheelbase");
  if (opt.every < 1) throw UsageError("--every must be >= 1");
  const bool left_ok = opt.left_scale != 0 && std::isfinite(opt.left_scale);
  const bool right_ok = opt.right_scale != 0 && std::isfinite(opt.right_scale);
  if (!left_ok || !right_ok) throw UsageError("--left-scale and --right-scale must be finite and not 0");
}

/// The model to propagate: the robot and its effects, and where they came from (for the report).
struct PredictModel {
  Robot robot;
  EffectList effects;
  std::string source;
};

/// The model from the command line's robot, a suite or a path config (check_options: one).
PredictModel select_model(const PredictOptions& opt) {
  PredictModel m;
  if (opt.wheelbase) {
    m.robot = {*opt.wheelbase, {*opt.k_left, *opt.k_right}};
    if (!(m.robot.wheelbase_m > 0) || !(m.robot.noise.k_left >= 0) || !(m.robot.noise.k_right >= 0)) {
      throw UsageError("--wheelbase must be > 0, --k-left and --k-right >= 0");
    }
    m.source = "command line";
  } else if (!opt.suite.empty()) {
    const Suite suite = load_suite(opt.suite);
    m.robot = suite.robot;
    m.effects = suite.model_effects;
    m.source = opt.suite;
  } else {
    const Config config = load_config(opt.config);
    m.robot = config.robot;
    m.effects = config.model_effects;
    m.source = opt.config;
  }
  return m;
}

/// Per log sample (world frame, x, y [m], theta [rad]): the odometry pose, its covariance and,
/// with effects, the predicted mean error.
struct Track {
  std::vector<Vector3> pose, mean;
  std::vector<Matrix3> cov;
};

/// Propagates the model along the log, sample by sample: the closed form per step without
/// effects, predict_trajectory (which sees each sample's duration) with them.
Track propagate(const EncoderLog& log, const PredictModel& m) {
  const std::size_t n = log.t_s.size();
  std::vector<ArcSegment> pieces;
  std::vector<double> durations;  // from the log's t column: speed- and time-dependent effects
  for (std::size_t i = 1; i < n; ++i) {
    pieces.push_back({log.left_m[i] - log.left_m[i - 1], log.right_m[i] - log.right_m[i - 1]});
    durations.push_back(log.t_s[i] - log.t_s[i - 1]);
  }
  Track track{std::vector<Vector3>(n, Vector3::Zero()), std::vector<Vector3>(n, Vector3::Zero()),
              std::vector<Matrix3>(n, Matrix3::Zero())};
  if (m.effects.empty()) {
    OdometryCovariance odo(m.robot.wheelbase_m, m.robot.noise);
    for (std::size_t i = 1; i < n; ++i) {
      const OdometryStep& s = odo.step(pieces[i - 1]);
      track.pose[i] = s.pose_world;
      track.cov[i] = s.P_world;
    }
    return track;
  }
  const std::vector<Prediction> p = predict_trajectory(pieces, durations, m.robot, m.effects);
  for (std::size_t i = 0; i < n; ++i) {
    track.pose[i] = p[i].odometry_end_pose;
    track.cov[i] = p[i].cov;
    track.mean[i] = p[i].mean;
  }
  return track;
}

/// The samples written: every `every`-th from the first, and always the last.
std::vector<std::size_t> written_rows(std::size_t n, std::int64_t every) {
  std::vector<std::size_t> rows;
  for (std::size_t i = 0; i < n; i += static_cast<std::size_t>(every)) rows.push_back(i);
  if (rows.back() != n - 1) rows.push_back(n - 1);
  return rows;
}

/// The CSV text: t, pose, the covariance's upper triangle, the mean error with effects and the
/// ROS 6x6 covariance with --ros; every number at full precision.
std::string predict_csv(const PredictOptions& opt, const EncoderLog& log, const Track& track,
                        const std::vector<std::size_t>& rows, bool with_mean) {
  std::string text = "t,x,y,theta,cov_xx,cov_xy,cov_xtheta,cov_yy,cov_ytheta,cov_thetatheta";
  if (with_mean) text += ",mean_x,mean_y,mean_theta";
  if (opt.ros) for (int k = 0; k < 36; ++k) text += ",pose_covariance_" + std::to_string(k);
  text += "\n";
  auto g = [](double v) { return format_number(v, "%.17g"); };
  for (std::size_t i : rows) {
    const Vector3& pose = track.pose[i];
    const Matrix3& P = track.cov[i];
    text += g(log.t_s[i]) + "," + g(pose.x()) + "," + g(pose.y()) + "," + g(pose.z()) + "," +
            g(P(0, 0)) + "," + g(P(0, 1)) + "," + g(P(0, 2)) + "," + g(P(1, 1)) + "," + g(P(1, 2)) +
            "," + g(P(2, 2));
    if (with_mean) text += "," + g(track.mean[i].x()) + "," + g(track.mean[i].y()) + "," + g(track.mean[i].z());
    if (opt.ros) for (double c : ros_covariance(P, opt.ros_unused_variance)) text += "," + g(c);
    text += "\n";
  }
  return text;
}

/// The JSON document (docs/json.md, "predict"): the log, the model and the written samples.
json predict_json(const PredictOptions& opt, const EncoderLog& log, const PredictModel& m,
                  const Track& track, const std::vector<std::size_t>& rows) {
  json samples = json::array();
  for (std::size_t i : rows) {
    json s = {{"t", log.t_s[i]}, {"pose", to_json(track.pose[i])}, {"cov", to_json(track.cov[i])}};
    if (!m.effects.empty()) s["mean"] = to_json(track.mean[i]);
    if (opt.ros) s["pose_covariance"] = ros_covariance(track.cov[i], opt.ros_unused_variance);
    samples.push_back(s);
  }
  json eff = json::array();
  for (const EffectSpec& e : m.effects) eff.push_back(effect_yaml(e));
  return {{"log", opt.log},
          {"robot", {{"wheelbase", m.robot.wheelbase_m},
                     {"k_left", m.robot.noise.k_left},
                     {"k_right", m.robot.noise.k_right}}},
          {"effects", eff},
          {"samples", samples}};
}

/// The report on stdout: the log and the model, the end pose, its covariance and 1-sigma
/// ellipse, and where the rows went.
std::string predict_report(const PredictOptions& opt, const EncoderLog& log, const PredictModel& m,
                           const Track& track, std::size_t rows) {
  const Vector3& end = track.pose.back();
  const ErrorEllipse e = error_ellipse(track.cov.back());
  std::ostringstream out;
  out << "odomcov predict: " << opt.log << " (" << log.t_s.size() << " samples, "
      << fixed(log.t_s.back() - log.t_s.front(), 3) << " s), robot from " << m.source
      << ": B = " << m.robot.wheelbase_m << " m, kL = " << m.robot.noise.k_left
      << ", kR = " << m.robot.noise.k_right << " m^(1/2)" << (m.effects.empty() ? "" : ", with the model's effects")
      << "\nend pose x = " << fixed(end.x(), 4) << " m, y = " << fixed(end.y(), 4)
      << " m, theta = " << fixed(wrap_angle(end.z()) * 180.0 / M_PI, 2) << " deg\n"
      << "end covariance (world frame, x, y, theta):\n" << matrix_rows(track.cov.back(), "    ")
      << "1-sigma ellipse: a = " << sci(e.semi_major_m, 4) << " m, b = " << sci(e.semi_minor_m, 4)
      << " m, angle = " << fixed(e.angle_rad * 180.0 / M_PI, 2) << " deg\n"
      << rows << " rows written" << (opt.csv.empty() ? "" : " to " + opt.csv)
      << (opt.json.empty() ? "" : (opt.csv.empty() ? " to " : " and ") + opt.json) << "\n";
  return out.str();
}

int run_predict(const PredictOptions& opt) {
  check_options(opt);
  const PredictModel model = select_model(opt);
  const EncoderLog log = load_encoder_log(opt.log, opt.left_scale, opt.right_scale);
  const Track track = propagate(log, model);
  const std::vector<std::size_t> rows = written_rows(log.t_s.size(), opt.every);
  if (!opt.csv.empty()) write_file_atomic(opt.csv, predict_csv(opt, log, track, rows, !model.effects.empty()));
  if (!opt.json.empty()) write_json_atomic(opt.json, predict_json(opt, log, model, track, rows));
  std::cout << predict_report(opt, log, model, track, rows.size());
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
