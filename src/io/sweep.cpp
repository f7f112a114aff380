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

/// The entry of a list that a key part names: an index ("2") or the name of the single-key map
/// the entry holds ("wheel_diameter_ratio"). Sets `next` to it; returns an error or "".
std::string list_entry(YAML::Node list, const std::string& part, YAML::Node& next) {
  if (is_index(part)) {
    // Compared as text first: an index of any length is past the end of a real list.
    if (part.size() > 9 || std::stoul(part) >= list.size()) {
      return "index " + quote(part) + " is past the end of the list";
    }
    const std::size_t index = std::stoul(part);
    next = list[index];
    return "";
  }
  for (std::size_t j = 0; j < list.size(); ++j) {
    if (list[j].IsMap() && list[j][part]) {
      next = list[j][part];
      break;
    }
  }
  if (!next) return "no list entry named " + quote(part);
  return "";
}

/// Sets an existing list entry, which must be a scalar, to `value`; returns an error or "".
std::string set_list_entry(YAML::Node entry, const std::string& part, double value) {
  if (!entry.IsScalar()) return quote(part) + " is not a number";
  entry = value;
  return "";
}

/// Sets a map's key `part` to `value`, adding it when absent; an existing value must be a
/// scalar. Returns an error or "".
std::string set_map_key(YAML::Node map, const std::string& part, double value) {
  if (map[part] && !map[part].IsScalar()) return quote(part) + " is not a number";
  map[part] = value;
  return "";
}

/// The first `count` parts of a dotted key, joined again ("robot.wheelbase").
std::string dotted_prefix(const std::vector<std::string>& parts, std::size_t count) {
  std::string prefix;
  for (std::size_t j = 0; j < count; ++j) prefix += (j ? "." : "") + parts[j];
  return prefix;
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
      if (const std::string error = list_entry(node, part, next); !error.empty()) return error;
      if (last) return set_list_entry(next, part, value);
      node.reset(next);
      continue;
    }
    if (!node.IsMap()) return quote(part) + " is not inside a map";
    if (last) return set_map_key(node, part, value);
    if (!node[part]) return "the base config has no " + quote(dotted_prefix(parts, i + 1));
    YAML::Node next = node[part];
    node.reset(next);
  }
  return "";
}

/// "point I (axis = value, ...)": a grid point for error messages.
std::string point_description(const SweepPlan& plan, std::size_t i, const std::vector<double>& values) {
  std::string text = "point " + std::to_string(i) + " (";
  for (std::size_t a = 0; a < plan.axes.size(); ++a) {
    text += (a ? ", " : "") + plan.axes[a].name + " = " + format_number(values[a]);
  }
  return text + ")";
}

/// The line of the axis `name` in the sweep file; 0 when the grid has no such axis.
int axis_line(const SweepPlan& plan, const char* name) {
  for (const SweepAxis& a : plan.axes) {
    if (a.name == name) return a.line;
  }
  return 0;
}

/// The convenience axes' factors of a point (1 where absent), and whether simulation.runs is
/// an axis.
struct PointScales {
  double noise = 1.0, path = 1.0;
  bool runs_on_axis = false;
};

/// Writes a point's values of the config-key axes into the base config `root`, and collects
/// those of noise_scale and path_scale.
PointScales set_axes(const SweepPlan& plan, const std::vector<double>& values, YAML::Node root) {
  PointScales scales;
  for (std::size_t a = 0; a < plan.axes.size(); ++a) {
    const SweepAxis& axis = plan.axes[a];
    if (axis.name == "noise_scale") {
      scales.noise *= values[a];
    } else if (axis.name == "path_scale") {
      scales.path *= values[a];
    } else {
      scales.runs_on_axis = scales.runs_on_axis || axis.name == "simulation.runs";
      const std::string error = set_dotted(root, axis.name, values[a]);
      if (!error.empty()) throw InputError(plan.file, axis.line, "grid." + axis.name, error);
    }
  }
  return scales;
}

/// The point's config parsed; bad input names the sweep file and the axis whose key the
/// error's key starts with (the last such axis), else "base".
Config parse_point(const SweepPlan& plan, const YAML::Node& root, const std::string& description) {
  try {
    return parse_config(root, plan.base_file);
  } catch (const InputError& e) {
    const SweepAxis* axis = nullptr;
    for (const SweepAxis& a : plan.axes) {
      if (e.key().rfind(a.name, 0) == 0) axis = &a;
    }
    throw InputError(plan.file, axis ? axis->line : 0, axis ? "grid." + axis->name : "base",
                     description + ": " + e.key() + ": " + e.message());
  }
}

/// Applies noise_scale to the wheel noise (the simulated world's and the model's alike) and
/// path_scale to the path, each checked against the numeric limits.
void scale_point(const SweepPlan& plan, const PointScales& scales, const std::string& description,
                 Config& config) {
  for (WheelNoise* noise : {&config.robot.noise, &config.world.noise}) {
    noise->k_left *= scales.noise;
    noise->k_right *= scales.noise;
    if (const std::string e = limits::check_wheel_noise(*noise); !e.empty()) {
      throw InputError(plan.file, axis_line(plan, "noise_scale"), "grid.noise_scale", description + ": " + e);
    }
  }
  if (scales.path != 1.0) {
    config.path = scale_path(config.path, scales.path);
    if (const std::string e = limits::check_path(config.path, config.robot.wheelbase_m); !e.empty()) {
      throw InputError(plan.file, axis_line(plan, "path_scale"), "grid.path_scale", description + ": " + e);
    }
    check_simulation_size(plan.file, axis_line(plan, "path_scale"), "grid.path_scale", config.simulation.runs,
                          sample_count(config.path));
  }
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
  const PointScales scales = set_axes(*this, values, root);
  if (runs > 0 && !scales.runs_on_axis) {
    if (root["simulation"] && !root["simulation"].IsMap()) {
      throw InputError(base_file, yaml::line_of(root["simulation"]), "simulation", "expected a map");
    }
    root["simulation"]["runs"] = runs;
  }
  const std::string description = point_description(*this, i, values);
  Config config = parse_point(*this, root, description);
  config.simulation.seed = point_seed(i);
  // The wheel noise itself scales: the simulated world's and the model's alike.
  scale_point(*this, scales, description, config);
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
