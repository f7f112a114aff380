// odomcov theory CONFIG [--json FILE]: the closed form at every keyframe ([Kleeman95] Tables I-II).
#include <cmath>
#include <iostream>
#include <sstream>

#include "commands.hpp"
#include "odomcov/config.hpp"
#include "odomcov/propagation.hpp"
#include "output.hpp"

namespace odomcov::cli {
namespace {

struct TheoryOptions {
  std::string config;
  std::string json;
};

constexpr double kRadToDeg = 180.0 / M_PI;

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
  const Config config = load_config(opt.config);
  const PathCovariance theory = path_covariance(config.path, config.robot);

  std::ostringstream out;
  out << "odomcov theory: " << config.name << "\n"
      << "B = " << config.robot.wheelbase_m << " m, kL = " << config.robot.noise.k_left
      << ", kR = " << config.robot.noise.k_right << " m^(1/2); closed form of [Kleeman95] with "
      << "the errata of seeds/README.md\n"
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
        << " m, theta = " << fixed(k.pose_world.z() * kRadToDeg, 2) << " deg\n"
        << matrix_rows(k.P_world, "    ")
        << "    1-sigma ellipse: " << ellipse_text(total) << "\n";
    keyframes.push_back({{"t", k.t_s},
                         {"pose", to_json(k.pose_world)},
                         {"cov", to_json(k.P_world)},
                         {"segment_cov", to_json(k.segment_P_world)},
                         {"ellipse", ellipse_json(total)},
                         {"segment_ellipse", ellipse_json(own)}});
  }
  std::cout << out.str();
  if (!opt.json.empty()) {
    const json doc = {{"name", config.name},
                      {"robot", {{"wheelbase", config.robot.wheelbase_m},
                                 {"k_left", config.robot.noise.k_left},
                                 {"k_right", config.robot.noise.k_right}}},
                      {"keyframes", keyframes},
                      {"final", {{"pose", to_json(theory.end().pose_world)},
                                 {"cov", to_json(theory.end().P_world)}}},
                      {"trace", path_trace(config)}};
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
  cmd->callback([opt, &exit_code] { exit_code = run_theory(*opt); });
}

}  // namespace odomcov::cli
