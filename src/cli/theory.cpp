// odomcov theory CONFIG [--json FILE]: the closed form at every keyframe ([Kleeman95] Tables I-II).
#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/closed_form/odometry_covariance.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/io/config_io.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct TheoryOptions {
  std::string config;
  std::string json;
  double every = 0.0;  // metres of centre travel between the points along the path; 0: none
};

struct AlongPoint {
  double s_m = 0.0, t_s = 0.0;
  Vector3 pose = Vector3::Zero();
  Matrix3 P = Matrix3::Zero();
};

/// Pose and covariance every `every` metres of centre travel |d| (and at every keyframe), by
/// the per-step closed form; splitting an interval does not change the covariance.
std::vector<AlongPoint> along_path(const Config& config, double every) {
  std::vector<AlongPoint> points{{}};
  OdometryCovariance odo(config.robot.wheelbase_m, config.robot.noise);
  double s = 0.0;
  for (std::size_t i = 0; i < config.path.interval_count(); ++i) {
    const ArcSegment seg = config.path.interval(i);
    const Keyframe& a = config.path.keyframes[i];
    const Keyframe& b = config.path.keyframes[i + 1];
    const double length = std::abs(seg.center_m());
    double done = 0.0;  // fraction of the interval driven
    auto go = [&](double f) {
      const OdometryStep& st = odo.step({(f - done) * seg.left_m, (f - done) * seg.right_m});
      done = f;
      points.push_back({s + f * length, a.t_s + f * (b.t_s - a.t_s), st.pose_world, st.P_world});
    };
    for (double next = (std::floor(s / every + 1e-9) + 1) * every; next < s + length - 1e-9 * every;
         next += every) {
      go((next - s) / length);
    }
    go(1.0);
    s += length;
  }
  return points;
}

constexpr double kRadToDeg = 180.0 / M_PI;

/// A standard deviation from a variance that rounding may leave a hair below 0 (a wheel that
/// pivots leaves one component's variance at 0: -1.6e-25 m^2 after the world-frame transforms).
double sd(double variance) { return std::sqrt(std::max(variance, 0.0)); }

/// A heading for display: wrapped to (-180, 180] deg, and no "-0.00" for a rounding residue.
double display_deg(double heading_rad) {
  const double deg = wrap_angle(heading_rad) * kRadToDeg;
  return std::abs(deg) < 5e-3 ? 0.0 : deg;
}

/// Keyframes are labelled A, B, C, ... as in [Kleeman95] Fig. 7; past Z by number.
std::string label(std::size_t i) {
  return i < 26 ? std::string(1, static_cast<char>('A' + i)) : "#" + std::to_string(i);
}

std::string ellipse_text(const ErrorEllipse& e) {
  return "a = " + sci(e.semi_major_m, 4) + " m, b = " + sci(e.semi_minor_m, 4) +
         " m, angle = " + fixed(e.angle_rad * kRadToDeg, 2) + " deg";
}

json ellipse_json(const ErrorEllipse& e) {
  return {{"semi_axes", {e.semi_major_m, e.semi_minor_m}}, {"angle", e.angle_rad}};
}

/// Points along the nominal path and both wheel tracks, for plotting (Fig. 7).
json path_trace(const Config& config) {
  constexpr int kPointsPerInterval = 48;
  const double half_b = 0.5 * config.robot.wheelbase_m;
  json center = json::array(), left = json::array(), right = json::array();
  Vector3 start = Vector3::Zero();
  auto add = [&](const Vector3& pose) {
    const double nx = -std::sin(pose.z()), ny = std::cos(pose.z());  // left normal
    center.push_back({pose.x(), pose.y()});
    left.push_back({pose.x() + half_b * nx, pose.y() + half_b * ny});
    right.push_back({pose.x() - half_b * nx, pose.y() - half_b * ny});
  };
  add(start);
  for (std::size_t i = 0; i < config.path.interval_count(); ++i) {
    const ArcSegment seg = config.path.interval(i);
    for (int k = 1; k <= kPointsPerInterval; ++k) {
      const double f = static_cast<double>(k) / kPointsPerInterval;
      add(drive(start, {f * seg.left_m, f * seg.right_m}, config.robot.wheelbase_m));
    }
    start = drive(start, seg, config.robot.wheelbase_m);
  }
  return {{"center", center}, {"left", left}, {"right", right}};
}

int run_theory(const TheoryOptions& opt) {
  if (!opt.json.empty()) check_output_path(opt.json);
  if (opt.every < 0 || !std::isfinite(opt.every)) throw UsageError("--every must be > 0 m");
  const Config config = load_config(opt.config);
  const PathCovariance theory = path_covariance(config.path, config.robot);

  std::ostringstream out;
  out << "odomcov theory: " << config.name << "\n"
      << "B = " << config.robot.wheelbase_m << " m, kL = " << config.robot.noise.k_left
      << ", kR = " << config.robot.noise.k_right << " m^(1/2); closed form of [Kleeman95] with "
      << "the errata of docs/conventions.md\n"
      << "Covariances are world-frame P_xy (x, y, theta), in m^2, m rad and rad^2.\n";
  json keyframes = json::array();
  for (std::size_t i = 0; i < theory.keyframes.size(); ++i) {
    const KeyframeCovariance& k = theory.keyframes[i];
    const ErrorEllipse total = error_ellipse(k.P_world);
    const ErrorEllipse own = error_ellipse(k.segment_P_world);
    if (i > 0) {
      out << "\n" << label(i - 1) << " to " << label(i) << "  (this segment's own contribution)\n"
          << matrix_rows(k.segment_P_world, "    ")
          << "    1-sigma ellipse: " << ellipse_text(own) << "\n";
    }
    out << "\n" << label(i) << "  t = " << fixed(k.t_s, 3) << " s, pose x = "
        << fixed(k.pose_world.x(), 4) << " m, y = " << fixed(k.pose_world.y(), 4)
        << " m, theta = " << fixed(display_deg(k.pose_world.z()), 2) << " deg\n"
        << matrix_rows(k.P_world, "    ")
        << "    1-sigma ellipse: " << ellipse_text(total) << "\n";
    keyframes.push_back({{"t", k.t_s},
                         {"pose", to_json(k.pose_world)},
                         {"cov", to_json(k.P_world)},
                         {"segment_cov", to_json(k.segment_P_world)},
                         {"ellipse", ellipse_json(total)},
                         {"segment_ellipse", ellipse_json(own)}});
  }
  json along = json::array();
  if (opt.every > 0) {
    out << "\nAlong the path, every " << opt.every << " m of centre travel (and at each keyframe):\n"
        << "      s [m]     t [s]     x [m]     y [m]  theta [deg]   sd_x [m]    sd_y [m]  sd_theta [rad]\n";
    for (const AlongPoint& p : along_path(config, opt.every)) {
      char line[200];
      std::snprintf(line, sizeof line, "  %9.3f %9.3f %9.4f %9.4f %12.2f %10.4e %11.4e %15.4e\n", p.s_m,
                    p.t_s, p.pose.x(), p.pose.y(), display_deg(p.pose.z()),
                    sd(p.P(0, 0)), sd(p.P(1, 1)), sd(p.P(2, 2)));
      out << line;
      along.push_back({{"s", p.s_m}, {"t", p.t_s}, {"pose", to_json(p.pose)}, {"cov", to_json(p.P)}});
    }
  }
  std::cout << out.str();
  if (!opt.json.empty()) {
    json doc = {{"name", config.name},
                      {"robot", {{"wheelbase", config.robot.wheelbase_m},
                                 {"k_left", config.robot.noise.k_left},
                                 {"k_right", config.robot.noise.k_right}}},
                      {"keyframes", keyframes},
                      {"final", {{"pose", to_json(theory.end().pose_world)},
                                 {"cov", to_json(theory.end().P_world)}}},
                      {"trace", path_trace(config)}};
    if (opt.every > 0) doc["along"] = along;
    write_json_atomic(opt.json, doc);
  }
  return kExitOk;
}

}  // namespace

void setup_theory(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<TheoryOptions>();
  CLI::App* cmd = app.add_subcommand(
      "theory", "Closed-form covariance at each keyframe and per segment (Tables I-II)");
  cmd->add_option("config", opt->config, "Path config (YAML)")->required();
  cmd->add_option("--json", opt->json, "Write the results as JSON to this file");
  cmd->add_option("--every", opt->every,
                  "Also give pose and covariance every DIST metres of centre travel (JSON 'along')");
  cmd->callback([opt, &exit_code] { exit_code = run_theory(*opt); });
}

}  // namespace odomcov::cli
