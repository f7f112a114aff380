#include "odomcov/io/config_io.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "odomcov/base/format.hpp"
#include "io/config_yaml.hpp"
#include "odomcov/closed_form/limits.hpp"
#include "io/yaml_util.hpp"

namespace odomcov {
namespace {

using yaml::Where;

/// "a, b, c".
std::string join(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

constexpr double kDefaultSpeedMps = 0.5;

std::vector<Keyframe> parse_keyframes(const Where& where, const YAML::Node& node) {
  yaml::require_sequence(where, node);
  std::vector<Keyframe> keyframes;
  for (std::size_t i = 0; i < node.size(); ++i) {
    const Where row_where = where.index(i);
    const YAML::Node row = node[i];
    if (!row.IsSequence() || row.size() != 3) {
      yaml::fail(row_where, row, "expected [time s, left m, right m]");
    }
    Keyframe k{yaml::to_number(row_where, row[0]), yaml::to_number(row_where, row[1]),
               yaml::to_number(row_where, row[2])};
    for (double travel : {k.left_m, k.right_m}) {
      if (const std::string e = limits::check_length(travel); !e.empty()) yaml::fail(row_where, row, e);
    }
    if (i == 0 && (k.t_s != 0.0 || k.left_m != 0.0 || k.right_m != 0.0)) {
      yaml::fail(row_where, row, "the first keyframe must be [0, 0, 0]");
    }
    if (i > 0 && !(k.t_s > keyframes.back().t_s)) {
      yaml::fail(row_where, row, "time must increase strictly (previous " +
                                     format_number(keyframes.back().t_s) + " s)");
    }
    keyframes.push_back(k);
  }
  if (keyframes.size() < 2) yaml::fail(where, node, "need at least two keyframes");
  return keyframes;
}

PathSegment parse_segment(const Where& where, const YAML::Node& node) {
  if (!node.IsMap() || node.size() != 1) {
    yaml::fail(where, node, "expected one of {line: m}, {turn_deg: deg}, {arc: {radius, angle_deg}}");
  }
  yaml::require_map(where, node, {"line", "turn_deg", "arc"});
  PathSegment segment;
  if (node["line"]) {
    segment.kind = PathSegment::Kind::line;
    segment.distance_m = yaml::require_number(where, node, "line");
    if (segment.distance_m == 0.0) yaml::fail(where.child("line"), node["line"], "must not be 0");
    if (const std::string e = limits::check_length(segment.distance_m); !e.empty()) {
      yaml::fail(where.child("line"), node["line"], e);
    }
  } else if (node["turn_deg"]) {
    segment.kind = PathSegment::Kind::turn;
    segment.angle_rad = yaml::require_number(where, node, "turn_deg") * kDegToRad;
    if (segment.angle_rad == 0.0) {
      yaml::fail(where.child("turn_deg"), node["turn_deg"], "must not be 0");
    }
    if (!(std::abs(segment.angle_rad) <= kMaxTurn_rad)) {
      yaml::fail(where.child("turn_deg"), node["turn_deg"],
                 "turn beyond the limit of " + format_number(kMaxTurn_rad / kDegToRad, "%.6g") + " deg");
    }
  } else {
    const Where arc_where = where.child("arc");
    const YAML::Node arc = node["arc"];
    yaml::require_map(arc_where, arc, {"radius", "angle_deg"});
    segment.kind = PathSegment::Kind::arc;
    segment.radius_m = yaml::require_number(arc_where, arc, "radius");
    segment.angle_rad = yaml::require_number(arc_where, arc, "angle_deg") * kDegToRad;
    if (segment.angle_rad == 0.0) {
      yaml::fail(arc_where.child("angle_deg"), arc["angle_deg"], "must not be 0");
    }
    if (!(std::abs(segment.angle_rad) <= kMaxTurn_rad)) {
      yaml::fail(arc_where.child("angle_deg"), arc["angle_deg"],
                 "turn beyond the limit of " + format_number(kMaxTurn_rad / kDegToRad, "%.6g") + " deg");
    }
    if (const std::string e = limits::check_length(segment.radius_m); !e.empty()) {
      yaml::fail(arc_where.child("radius"), arc["radius"], e);
    }
    if (const std::string e = limits::check_length(segment.radius_m * segment.angle_rad); !e.empty()) {
      yaml::fail(arc_where, arc, "arc length: " + e);
    }
  }
  return segment;
}

/// A custom effect's `random: {p: sd}`: each key a parameter of the effect, each sd a number
/// >= 0; appended to `def.random` and `sds` in the order written.
void parse_random(const Where& where, const YAML::Node& node, CustomEffect& def, std::vector<double>& sds) {
  const Where random_where = where.child("random");
  const YAML::Node random = node["random"];
  if (!random.IsMap()) yaml::fail(random_where, random, "expected a map {parameter: sd}");
  for (const auto& entry : random) {
    const std::string p = entry.first.Scalar();
    const Where p_where = random_where.child(p);
    if (std::find(def.parameters.begin(), def.parameters.end(), p) == def.parameters.end()) {
      yaml::fail(p_where, entry.first, "not a parameter of the effect (its parameters: " +
                                           (def.parameters.empty() ? std::string("none") : join(def.parameters)) + ")");
    }
    const double sd = yaml::to_number(p_where, entry.second);
    if (!(sd >= 0.0)) yaml::fail(p_where, entry.second, "the sd must be >= 0, got " + format_number(sd));
    if (def.random.size() == kMaxRandomParameters) {
      yaml::fail(p_where, entry.first, "at most " + std::to_string(kMaxRandomParameters) + " parameters drawn per run");
    }
    def.random.push_back(p);
    sds.push_back(sd);
  }
}

/// `- custom: {name, parameters: {p: start}, random: {p: sd}, scale, scale_left, scale_right,
/// wheelbase_factor, lateral, noise}`.
EffectSpec parse_custom(const Where& where, const YAML::Node& node) {
  yaml::require_map(where, node, {"name", "parameters", "random", "scale", "scale_left", "scale_right",
                                  "wheelbase_factor", "lateral", "noise"});
  CustomEffect def;
  def.file = where.file;
  def.line = yaml::line_of(node);
  def.key = where.key;
  def.name = yaml::to_string(where.child("name"), yaml::require(where, node, "name"));
  if (const std::string e = check_custom_name(def.name); !e.empty()) yaml::fail(where.child("name"), node["name"], e);
  if (find_effect(def.name)) yaml::fail(where.child("name"), node["name"], "name clash: " + quote(def.name) + " is a catalogue effect");
  std::vector<double> start;
  if (const YAML::Node params = node["parameters"]) {
    const Where params_where = where.child("parameters");
    if (!params.IsMap()) yaml::fail(params_where, params, "expected a map {name: starting value}");
    for (const auto& entry : params) {
      const std::string p = entry.first.Scalar();
      if (const std::string e = check_custom_name(p); !e.empty()) yaml::fail(params_where.child(p), entry.first, e);
      def.parameters.push_back(p);
      start.push_back(yaml::to_number(params_where.child(p), entry.second));
    }
  }
  if (node["random"]) parse_random(where, node, def, start);
  bool any = false;
  for (const auto& [k, e] : def.expressions()) {
    const YAML::Node expr = node[k];
    if (!expr) continue;
    const Where expr_where = where.child(k);
    *e = {yaml::to_string(expr_where, expr), where.file, yaml::line_of(expr), expr_where.key};
    if (e->text.find_first_not_of(" \t") == std::string::npos) yaml::fail(expr_where, expr, "empty expression");
    if (const std::string error = check_custom_expression(e->text, def.parameters); !error.empty()) {
      yaml::fail(expr_where, expr, error);
    }
    any = true;
  }
  if (!any) {
    yaml::fail(where, node, "give at least one of scale, scale_left, scale_right, wheelbase_factor, lateral, noise");
  }
  return define_custom_effect(std::move(def), start);
}

/// A group_variation must vary a systematic parameter of another effect of its list: else bad
/// input at its `parameter` line.
void check_group_target_at(const Where& where, const YAML::Node& node, const EffectList& list) {
  const std::string error = check_group_target(list);
  if (error.empty()) return;
  for (std::size_t i = 0; i < list.size(); ++i) {
    if (list[i].name != kGroupVariation) continue;
    yaml::fail(where.index(i).child(kGroupVariation).child("parameter"),
               node[i].begin()->second["parameter"], error);
  }
}

/// A custom effect as an item of an effect list (`- custom: {...}`): its name must not be
/// listed yet.
EffectSpec parse_custom_item(const Where& effect_where, const YAML::Node& item, const EffectList& list) {
  EffectSpec spec = parse_custom(effect_where, item.begin()->second);
  if (find_spec(list, spec.name)) {
    yaml::fail(effect_where.child("name"), item.begin()->second["name"],
               "name clash: effect " + quote(spec.name) + " listed twice");
  }
  return spec;
}

/// The catalogue's entry for an item's effect name; bad input naming the known effects else.
const EffectInfo& catalogue_entry(const Where& effect_where, const YAML::Node& item, const std::string& name) {
  const EffectInfo* info = find_effect(name);
  if (!info) {
    std::string known;
    for (const EffectInfo& e : effect_catalogue()) known += (known.empty() ? "" : ", ") + e.name;
    yaml::fail(effect_where, item.begin()->first, "unknown effect (known: " + known + ", custom)");
  }
  return *info;
}

/// group_variation's `parameter: <effect>.<parameter>`, the parameter it varies (required;
/// check_group_target_at checks it against the list).
std::string parse_group_target(const Where& effect_where, const YAML::Node& params) {
  return yaml::to_string(effect_where.child("parameter"), yaml::require(effect_where, params, "parameter"));
}

/// Every key of a catalogue effect's map must name one of its parameters (or be
/// group_variation's `parameter`).
void check_parameter_names(const Where& effect_where, const YAML::Node& params, const EffectInfo& info) {
  for (const auto& entry : params) {
    const std::string p = entry.first.Scalar();
    bool known = info.grouped && p == "parameter";
    for (const EffectParameterInfo& info_p : info.parameters) known = known || info_p.name == p;
    if (!known) yaml::fail(effect_where.child(p), entry.first, "unknown parameter");
  }
}

/// A failed check_effect as bad input: at the offending parameter's line when the message
/// starts with its name, else at the effect's map.
[[noreturn]] void fail_effect_check(const Where& effect_where, const YAML::Node& params,
                                    const EffectInfo& info, const std::string& error) {
  for (const EffectParameterInfo& p : info.parameters) {
    if (error.rfind(p.name + " ", 0) == 0) {
      yaml::fail(effect_where.child(p.name), params[p.name], error.substr(p.name.size() + 1));
    }
  }
  yaml::fail(effect_where, params, error);
}

/// A catalogue effect (`- name: {parameter: value, ...}`, group_variation with its target):
/// every parameter given, none unknown, each within its range (check_effect).
EffectSpec parse_catalogue_effect(const Where& effect_where, const YAML::Node& params,
                                  const EffectInfo& info, const std::string& name) {
  if (!params.IsMap()) yaml::fail(effect_where, params, "expected a map of parameters");
  EffectSpec spec{name, {}, {}};
  if (info.grouped) spec.target = parse_group_target(effect_where, params);
  check_parameter_names(effect_where, params, info);
  for (const EffectParameterInfo& p : info.parameters) {
    spec.values.push_back(yaml::require_number(effect_where, params, p.name.c_str()));
  }
  if (const std::string error = check_effect(spec); !error.empty()) fail_effect_check(effect_where, params, info, error);
  return spec;
}

}  // namespace

EffectList parse_effects(const YAML::Node& node, const std::string& file, const std::string& key) {
  const Where where{file, key};
  yaml::require_sequence(where, node);
  EffectList list;
  for (std::size_t i = 0; i < node.size(); ++i) {
    const Where item_where = where.index(i);
    const YAML::Node item = node[i];
    if (!item.IsMap() || item.size() != 1) {
      yaml::fail(item_where, item, "expected a single-key map such as {wheel_diameter_ratio: {Ed: 1.004}}");
    }
    const std::string name = item.begin()->first.Scalar();
    const Where effect_where = item_where.child(name);
    if (name == "custom") {
      list.push_back(parse_custom_item(effect_where, item, list));
      continue;
    }
    const EffectInfo& info = catalogue_entry(effect_where, item, name);
    EffectSpec spec = parse_catalogue_effect(effect_where, item.begin()->second, info, name);
    if (find_spec(list, name)) yaml::fail(effect_where, item, "effect listed twice");
    list.push_back(std::move(spec));
  }
  if (list.size() > kMaxEffects) yaml::fail(where, node, "at most " + std::to_string(kMaxEffects) + " effects");
  if (const std::string e = check_run_constants(list); !e.empty()) yaml::fail(where, node, e);
  check_group_target_at(where, node, list);
  return list;
}

World parse_world(const YAML::Node& node, const std::string& file, const std::string& key,
                  const WheelNoise& nominal) {
  const Where where{file, key};
  yaml::require_map(where, node, {"effects", "k_left", "k_right"});
  World world;
  world.noise = nominal;
  if (node["effects"]) world.effects = parse_effects(node["effects"], file, where.child("effects").key);
  for (auto [name, target] : {std::pair{"k_left", &world.noise.k_left},
                              std::pair{"k_right", &world.noise.k_right}}) {
    if (const auto k = yaml::optional_number(where, node, name)) {
      if (*k < 0.0) yaml::fail(where.child(name), node[name], "must be >= 0");
      if (const std::string e = limits::check_wheel_noise({*k, *k}); !e.empty()) {
        yaml::fail(where.child(name), node[name], e);
      }
      *target = *k;
    }
  }
  return world;
}

Robot parse_robot(const YAML::Node& node, const std::string& file, const std::string& key) {
  const Where where{file, key};
  yaml::require_map(where, node, {"wheelbase", "k_left", "k_right"});
  Robot robot;
  robot.wheelbase_m = yaml::require_number(where, node, "wheelbase");
  if (!(robot.wheelbase_m > 0.0)) {
    yaml::fail(where.child("wheelbase"), node["wheelbase"], "must be > 0 m");
  }
  if (const std::string e = limits::check_wheelbase(robot.wheelbase_m); !e.empty()) {
    yaml::fail(where.child("wheelbase"), node["wheelbase"], e);
  }
  robot.noise.k_left = yaml::require_number(where, node, "k_left");
  robot.noise.k_right = yaml::require_number(where, node, "k_right");
  if (robot.noise.k_left < 0.0) yaml::fail(where.child("k_left"), node["k_left"], "must be >= 0");
  if (robot.noise.k_right < 0.0) {
    yaml::fail(where.child("k_right"), node["k_right"], "must be >= 0");
  }
  for (const char* k : {"k_left", "k_right"}) {
    const double value = std::string(k) == "k_left" ? robot.noise.k_left : robot.noise.k_right;
    if (const std::string e = limits::check_wheel_noise({value, value}); !e.empty()) {
      yaml::fail(where.child(k), node[k], e);
    }
  }
  return robot;
}

Path parse_path(const YAML::Node& node, const std::string& file, const std::string& key,
                double wheelbase_m) {
  const Where where{file, key};
  yaml::require_map(where, node, {"sample_rate", "keyframes", "segments", "speed"});
  Path path;
  path.sample_rate_hz = yaml::require_number(where, node, "sample_rate");
  if (!(path.sample_rate_hz > 0.0)) {
    yaml::fail(where.child("sample_rate"), node["sample_rate"], "must be > 0 Hz");
  }
  const bool has_keyframes = node["keyframes"].IsDefined();
  const bool has_segments = node["segments"].IsDefined();
  if (has_keyframes == has_segments) {
    yaml::fail(where.child("keyframes"), node, "give exactly one of 'keyframes' and 'segments'");
  }
  if (has_keyframes) {
    if (node["speed"]) yaml::fail(where.child("speed"), node["speed"], "only used with segments");
    path.keyframes = parse_keyframes(where.child("keyframes"), node["keyframes"]);
  } else {
    const double speed = yaml::optional_number(where, node, "speed").value_or(kDefaultSpeedMps);
    if (!(speed > 0.0)) yaml::fail(where.child("speed"), node["speed"], "must be > 0 m/s");
    if (!(speed <= kMaxLength_m)) {
      yaml::fail(where.child("speed"), node["speed"], "must be at most " + format_number(kMaxLength_m) + " m/s");
    }
    const Where seg_where = where.child("segments");
    const YAML::Node list = node["segments"];
    yaml::require_sequence(seg_where, list);
    if (list.size() == 0) yaml::fail(seg_where, list, "need at least one segment");
    std::vector<PathSegment> segments;
    for (std::size_t i = 0; i < list.size(); ++i) {
      segments.push_back(parse_segment(seg_where.index(i), list[i]));
    }
    path.keyframes = keyframes_from_segments(segments, wheelbase_m, speed);
  }
  if (const std::string e = limits::check_path(path, wheelbase_m); !e.empty()) {
    yaml::fail(where, node, e);
  }
  return path;
}

Config parse_config_unguarded(const YAML::Node& root, const std::string& file);

void check_simulation_size(const std::string& file, int line, const std::string& key,
                           std::int64_t runs, std::int64_t samples_per_run) {
  if (runs < 1 || runs > kMaxRuns) {
    throw InputError(file, line, key,
                     "runs must be in [1, " + std::to_string(kMaxRuns) + "], got " +
                         std::to_string(runs));
  }
  const double steps = static_cast<double>(runs) * static_cast<double>(samples_per_run);
  if (steps > kMaxSimulationSteps) {
    throw InputError(file, line, key,
                     std::to_string(runs) + " runs x " + std::to_string(samples_per_run) +
                         " samples exceeds the limit of 1e12 wheel-sample steps");
  }
}

Config parse_config(const YAML::Node& root, const std::string& file) {
  return yaml::guarded(file, [&] { return parse_config_unguarded(root, file); });
}

Config parse_config_unguarded(const YAML::Node& root, const std::string& file) {
  const Where where{file, ""};
  yaml::require_map(where, root, {"name", "robot", "path", "world", "model", "simulation"});
  Config config;
  config.file = file;
  config.name = root["name"] ? yaml::to_string(where.child("name"), root["name"])
                             : std::filesystem::path(file).stem().string();
  config.robot = parse_robot(yaml::require(where, root, "robot"), file, "robot");
  config.path =
      parse_path(yaml::require(where, root, "path"), file, "path", config.robot.wheelbase_m);
  config.world.noise = config.robot.noise;
  if (const YAML::Node world = root["world"]) {
    config.world = parse_world(world, file, "world", config.robot.noise);
  }
  config.model_effects = config.world.effects;
  if (const YAML::Node model = root["model"]) {
    const Where model_where = where.child("model");
    yaml::require_map(model_where, model, {"effects"});
    config.model_effects = model["effects"]
                               ? parse_effects(model["effects"], file, "model.effects")
                               : EffectList{};
  }
  if (const YAML::Node sim = root["simulation"]) {
    const Where sim_where = where.child("simulation");
    yaml::require_map(sim_where, sim, {"runs", "seed"});
    if (sim["runs"]) {
      config.simulation.runs =
          yaml::to_integer(sim_where.child("runs"), sim["runs"], 1, kMaxRuns);
    }
    if (sim["seed"]) config.simulation.seed = yaml::to_unsigned(sim_where.child("seed"), sim["seed"]);
    check_simulation_size(file, yaml::line_of(sim["runs"] ? sim["runs"] : sim),
                          "simulation.runs", config.simulation.runs, sample_count(config.path));
  }
  return config;
}

namespace {
EffectList effect_list(const YAML::Node& root, const std::string& source, const std::string& key) {
  if (!root.IsSequence()) yaml::fail({source, key}, root, "expected a list of effects, e.g. - custom: {name: ..., ...}");
  return parse_effects(root, source, key);
}
}  // namespace

EffectList load_effects(const std::string& file) {
  return yaml::guarded(file, [&] { return effect_list(yaml::load_file(file), file, ""); });
}

EffectList parse_effect_list(const std::string& text, const std::string& source) {
  return yaml::guarded(source, [&] { return effect_list(yaml::load_text(text, source), source, source); });
}

Config load_config(const std::string& file) { return parse_config(yaml::load_file(file), file); }

}  // namespace odomcov
