#include "odomcov/io/sweep.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <filesystem>

#include "odomcov/base/format.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "odomcov/io/config_io.hpp"
#include "base/random.hpp"
#include "io/config_yaml.hpp"
#include "io/yaml_util.hpp"

namespace odomcov {

struct SweepBase {
  YAML::Node root;
};
namespace {

using yaml::Where;

std::vector<std::string> split_dotted(const std::string& key) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t dot = key.find('.', start);
    parts.push_back(key.substr(start, dot - start));
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  return parts;
}

bool is_index(const std::string& s) {
  return !s.empty() && s.find_first_not_of("0123456789") == std::string::npos;
}

/// Sets the numeric value at a dotted key. Maps are entered by key and lists by index, or by
/// the name of the single-key map they hold (effects: "world.effects.wheel_diameter_ratio.Ed").
/// Every part but the last must exist in the base; the last may be new (the config parser then
/// rejects it if it is not a valid key). Returns an error or "".
std::string set_dotted(YAML::Node root, const std::string& key, double value) {
  const std::vector<std::string> parts = split_dotted(key);
  YAML::Node node = root;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    const std::string& part = parts[i];
    const bool last = i + 1 == parts.size();
    if (node.IsSequence()) {
      YAML::Node next;
      if (is_index(part)) {
        // Compared as text first: an index of any length is past the end of a real list.
        if (part.size() > 9 || std::stoul(part) >= node.size()) {
          return "index " + quote(part) + " is past the end of the list";
        }
        const std::size_t index = std::stoul(part);
        next = node[index];
      } else {
        for (std::size_t j = 0; j < node.size(); ++j) {
          if (node[j].IsMap() && node[j][part]) {
            next = node[j][part];
            break;
          }
        }
        if (!next) return "no list entry named " + quote(part);
      }
      if (last) {
        if (!next.IsScalar()) return quote(part) + " is not a number";
        next = value;
        return "";
      }
      node.reset(next);
      continue;
    }
    if (!node.IsMap()) return quote(part) + " is not inside a map";
    if (last) {
      if (node[part] && !node[part].IsScalar()) return quote(part) + " is not a number";
      node[part] = value;
      return "";
    }
    if (!node[part]) {
      std::string prefix;
      for (std::size_t j = 0; j <= i; ++j) prefix += (j ? "." : "") + parts[j];
      return "the base config has no " + quote(prefix);
    }
    YAML::Node next = node[part];
    node.reset(next);
  }
  return "";
}

}  // namespace

std::size_t SweepPlan::point_count() const {
  std::size_t n = 1;
  for (const SweepAxis& a : axes) n *= a.values.size();  // load_sweep bounds it (no overflow)
  return n;
}

std::vector<double> SweepPlan::point_values(std::size_t i) const {
  std::vector<double> values(axes.size());
  for (std::size_t a = axes.size(); a-- > 0;) {
    values[a] = axes[a].values[i % axes[a].values.size()];
    i /= axes[a].values.size();
  }
  return values;
}

std::uint64_t SweepPlan::point_seed(std::size_t i) const {
  return random::derive_seed(seed, static_cast<std::uint64_t>(i));
}

Config SweepPlan::point_config(std::size_t i) const {
  return yaml::guarded(file, [&] { return point_config_unguarded(i); });
}

Config SweepPlan::point_config_unguarded(std::size_t i) const {
  const std::vector<double> values = point_values(i);
  YAML::Node root = YAML::Clone(base->root);
  double noise_scale = 1.0, path_scale = 1.0;
  bool runs_on_axis = false;
  auto describe = [&] {
    std::string text = "point " + std::to_string(i) + " (";
    for (std::size_t a = 0; a < axes.size(); ++a) {
      text += (a ? ", " : "") + axes[a].name + " = " + format_number(values[a]);
    }
    return text + ")";
  };
  for (std::size_t a = 0; a < axes.size(); ++a) {
    const SweepAxis& axis = axes[a];
    if (axis.name == "noise_scale") {
      noise_scale *= values[a];
    } else if (axis.name == "path_scale") {
      path_scale *= values[a];
    } else {
      runs_on_axis = runs_on_axis || axis.name == "simulation.runs";
      const std::string error = set_dotted(root, axis.name, values[a]);
      if (!error.empty()) throw InputError(file, axis.line, "grid." + axis.name, error);
    }
  }
  if (runs > 0 && !runs_on_axis) {
    if (root["simulation"] && !root["simulation"].IsMap()) {
      throw InputError(base_file, yaml::line_of(root["simulation"]), "simulation", "expected a map");
    }
    root["simulation"]["runs"] = runs;
  }
  Config config;
  try {
    config = parse_config(root, base_file);
  } catch (const InputError& e) {
    const SweepAxis* axis = nullptr;
    for (const SweepAxis& a : axes) {
      if (e.key().rfind(a.name, 0) == 0) axis = &a;
    }
    throw InputError(file, axis ? axis->line : 0, axis ? "grid." + axis->name : "base",
                     describe() + ": " + e.key() + ": " + e.message());
  }
  config.simulation.seed = point_seed(i);
  // The wheel noise itself scales: the simulated world's and the model's alike.
  auto axis_line = [&](const char* name) {
    for (const SweepAxis& a : axes) {
      if (a.name == name) return a.line;
    }
    return 0;
  };
  for (WheelNoise* noise : {&config.robot.noise, &config.world.noise}) {
    noise->k_left *= noise_scale;
    noise->k_right *= noise_scale;
    if (const std::string e = limits::check_wheel_noise(*noise); !e.empty()) {
      throw InputError(file, axis_line("noise_scale"), "grid.noise_scale", describe() + ": " + e);
    }
  }
  if (path_scale != 1.0) {
    config.path = scale_path(config.path, path_scale);
    if (const std::string e = limits::check_path(config.path, config.robot.wheelbase_m); !e.empty()) {
      throw InputError(file, axis_line("path_scale"), "grid.path_scale", describe() + ": " + e);
    }
    check_simulation_size(file, axis_line("path_scale"), "grid.path_scale", config.simulation.runs,
                          sample_count(config.path));
  }
  return config;
}

SweepPlan load_sweep_unguarded(const std::string& file);

SweepPlan load_sweep(const std::string& file) {
  return yaml::guarded(file, [&] { return load_sweep_unguarded(file); });
}

SweepPlan load_sweep_unguarded(const std::string& file) {
  const YAML::Node root = yaml::load_file(file);
  const Where where{file, ""};
  yaml::require_map(where, root, {"base", "runs", "seed", "grid"});
  SweepPlan plan;
  plan.file = file;
  const std::string base = yaml::to_string(where.child("base"), yaml::require(where, root, "base"));
  plan.base_file = (std::filesystem::path(file).parent_path() / base).lexically_normal().string();
  if (root["runs"]) plan.runs = yaml::to_integer(where.child("runs"), root["runs"], 1, kMaxRuns);
  if (root["seed"]) plan.seed = yaml::to_unsigned(where.child("seed"), root["seed"]);
  const YAML::Node grid = yaml::require(where, root, "grid");
  double points = 1.0;
  if (!grid.IsMap() || grid.size() == 0) yaml::fail(where.child("grid"), grid, "expected a map of axes");
  for (const auto& entry : grid) {
    SweepAxis axis;
    axis.name = entry.first.Scalar();
    const Where axis_where = where.child("grid").child(axis.name);
    axis.line = yaml::line_of(entry.first);
    if (axis.name == "simulation.seed") {
      yaml::fail(axis_where, entry.first, "seeds are derived per point from the sweep's seed");
    }
    yaml::require_sequence(axis_where, entry.second);
    if (entry.second.size() == 0) yaml::fail(axis_where, entry.second, "needs at least one value");
    for (std::size_t i = 0; i < entry.second.size(); ++i) {
      const double v = yaml::to_number(axis_where.index(i), entry.second[i]);
      // A scale of 0 leaves no noise (or no path): nothing to test, and 0/0 metrics.
      if ((axis.name == "noise_scale" || axis.name == "path_scale") && !(v > 0.0)) {
        yaml::fail(axis_where.index(i), entry.second[i], "must be > 0");
      }
      axis.values.push_back(v);
    }
    for (const SweepAxis& other : plan.axes) {
      if (other.name == axis.name) yaml::fail(axis_where, entry.first, "axis given twice");
    }
    plan.axes.push_back(std::move(axis));
    points *= static_cast<double>(plan.axes.back().values.size());
    if (points > kMaxSweepPoints) {
      yaml::fail(axis_where, entry.first,
                 "the grid has " + format_number(points, "%.6g") + " points up to this axis, more than the limit of " +
                     format_number(kMaxSweepPoints, "%.6g"));
    }
  }
  plan.base = std::make_shared<const SweepBase>(SweepBase{yaml::load_file(plan.base_file)});
  for (std::size_t i = 0; i < plan.point_count(); ++i) plan.point_config(i);  // validate all
  return plan;
}

Path scale_path(const Path& path, double scale) {
  Path out{path.sample_rate_hz, {path.keyframes.front()}};
  for (std::size_t i = 0; i < path.interval_count(); ++i) {
    const ArcSegment seg = path.interval(i);
    const double half_turn = 0.5 * (seg.right_m - seg.left_m);  // a B/2, kept
    const ArcSegment scaled{scale * seg.center_m() - half_turn, scale * seg.center_m() + half_turn};
    const double fast = std::max(std::abs(seg.left_m), std::abs(seg.right_m));
    const double fast_scaled = std::max(std::abs(scaled.left_m), std::abs(scaled.right_m));
    const double span = path.keyframes[i + 1].t_s - path.keyframes[i].t_s;
    const Keyframe& last = out.keyframes.back();
    out.keyframes.push_back({last.t_s + (fast > 0 ? span * fast_scaled / fast : span),
                             last.left_m + scaled.left_m, last.right_m + scaled.right_m});
  }
  return out;
}

SweepMetrics sweep_metrics(const Validation& v) {
  SweepMetrics m;
  const Matrix3 sim = std_corr_matrix(v.simulation.cov);
  const Matrix3 theory = std_corr_matrix(v.theory_cov);
  const double n = static_cast<double>(v.simulation.n);
  for (int i = 0; i < 3; ++i) {
    m.std_rel_err(i) = sim(i, i) / theory(i, i) - 1.0;
    m.bias_se(i) = (v.simulation.mean(i) - v.theory_mean(i)) / (sim(i, i) / std::sqrt(n));
    for (int j = i + 1; j < 3; ++j) {
      m.max_corr_diff = std::max(m.max_corr_diff, std::abs(sim(i, j) - theory(i, j)));
    }
  }
  m.p_mean = v.mean_test.p_value;
  m.p_cov = v.cov_test.p_value;
  m.nees_mean = v.nees_mean;
  m.verdict = v.verdict;
  return m;
}

const std::vector<std::string>& sweep_metric_columns() {
  static const std::vector<std::string> columns{
      "runs",       "seed",          "std_rel_err_x", "std_rel_err_y", "std_rel_err_theta",
      "max_corr_diff", "bias_x_se",  "bias_y_se",     "bias_theta_se", "p_mean",
      "p_cov",      "nees_mean",     "verdict"};
  return columns;
}

}  // namespace odomcov
