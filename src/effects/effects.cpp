#include <algorithm>
#include <cmath>

#include "effects/effect.hpp"
#include "odomcov/base/format.hpp"

namespace odomcov {

const std::vector<EffectInfo>& effect_catalogue() {
  static const std::vector<EffectInfo> infos = [] {
    std::vector<EffectInfo> out;
    for (const effects::EffectType& t : effects::registry()) out.push_back(t.info);
    return out;
  }();
  return infos;
}

const EffectSpec* find_spec(const EffectList& list, const std::string& name) {
  for (const EffectSpec& spec : list) {
    if (spec.name == name) return &spec;
  }
  return nullptr;
}

EffectSpec* find_spec(EffectList& list, const std::string& name) {
  return const_cast<EffectSpec*>(find_spec(static_cast<const EffectList&>(list), name));
}

const EffectInfo* find_effect(const std::string& name, const EffectList& context) {
  const EffectSpec* spec = find_spec(context, name);
  if (spec && spec->custom) return &spec->custom->info;
  for (const EffectInfo& info : effect_catalogue()) {
    if (info.name == name) return &info;
  }
  return nullptr;
}

const EffectInfo* info_of(const EffectSpec& spec) {
  return spec.custom ? &spec.custom->info : find_effect(spec.name);
}

EffectNeeds effect_needs(const EffectList& list) {
  EffectNeeds needs;
  for (const EffectSpec& spec : list) {
    const EffectInfo* info = info_of(spec);
    if (!info) continue;  // unknown: check_effects refuses it where it is used
    needs.start_heading = needs.start_heading || info->uses_start_heading;
    needs.sample_pieces = needs.sample_pieces || info->uses_acceleration;
  }
  return needs;
}

namespace {

/// A parameter's value checked against its range: "" when within, else the error.
std::string check_value(const EffectParameterInfo& p, double v) {
  if (!std::isfinite(v)) return p.name + " must be finite";
  const bool below = p.open_lower ? !(v > p.lower) : !(v >= p.lower);
  const bool above = p.open_upper ? !(v < p.upper) : !(v <= p.upper);
  if (!below && !above) return "";
  std::string range = (p.open_lower ? "(" : "[") + format_number(p.lower) + ", ";
  range += p.upper >= 1e300 ? std::string("inf)") : format_number(p.upper) + (p.open_upper ? ")" : "]");
  return p.name + " must be in " + range + ", got " + format_number(v);
}

}  // namespace

std::string check_effect(const EffectSpec& spec) {
  if (spec.custom && spec.custom->name != spec.name) return "custom effect named '" + spec.custom->name + "'";
  if (spec.custom && find_effect(spec.name)) return "custom effect '" + spec.name + "' has a catalogue effect's name";
  const EffectInfo* info = info_of(spec);
  if (!info) return "unknown effect '" + spec.name + "'";
  if (spec.values.size() != info->parameters.size()) {
    return spec.name + " takes " + std::to_string(info->parameters.size()) + " parameters";
  }
  for (std::size_t i = 0; i < spec.values.size(); ++i) {
    if (std::string e = check_value(info->parameters[i], spec.values[i]); !e.empty()) return e;
  }
  return "";
}

namespace {

/// A YAML double-quoted scalar.
std::string yaml_quoted(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string custom_yaml(const EffectSpec& spec) {
  const CustomEffect& def = *spec.custom;
  std::string text = "- custom: {name: " + def.name + ", parameters: {";
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    text += (i ? ", " : "") + def.parameters[i] + ": " + format_number(spec.values[i]);
  }
  text += "}";
  if (!def.random.empty()) {
    text += ", random: {";
    for (std::size_t j = 0; j < def.random.size(); ++j) {
      text += (j ? ", " : "") + def.random[j] + ": " + format_number(spec.values[def.parameters.size() + j]);
    }
    text += "}";
  }
  for (const auto& [key, e] : def.expressions()) {
    if (!e->text.empty()) text += std::string(", ") + key + ": " + yaml_quoted(e->text);
  }
  return text + "}";
}

}  // namespace

std::string effect_yaml(const EffectSpec& spec) {
  if (spec.custom) return custom_yaml(spec);
  const EffectInfo* info = find_effect(spec.name);
  std::string text = "- " + spec.name + ": {";
  if (!spec.target.empty()) text += "parameter: " + spec.target + (spec.values.empty() ? "" : ", ");
  for (std::size_t i = 0; i < spec.values.size(); ++i) {
    text += (i ? ", " : "") + (info ? info->parameters[i].name : "p" + std::to_string(i)) + ": " +
            format_number(spec.values[i]);
  }
  return text + "}";
}

namespace {

/// "" when `target` ("<effect>.<parameter>") names a systematic parameter of an effect of
/// `list` other than group_variation, else what is wrong.
std::string check_varied_parameter(const EffectList& list, const std::string& target) {
  const std::size_t dot = target.find('.');
  if (dot == std::string::npos) {
    return "parameter must be <effect>.<parameter> of another effect in the list, got '" + target + "'";
  }
  const std::string effect = target.substr(0, dot), param = target.substr(dot + 1);
  const EffectSpec* varied = nullptr;
  for (const EffectSpec& e : list) varied = e.name == effect && effect != kGroupVariation ? &e : varied;
  if (!varied) return "parameter '" + target + "': no effect " + effect + " in the list";
  const EffectInfo* info = info_of(*varied);  // a catalogue or a custom effect
  const EffectParameterInfo* p = nullptr;
  for (const EffectParameterInfo& q : info->parameters) p = q.name == param ? &q : p;
  if (!p) return "parameter '" + target + "': " + effect + " has no parameter " + param;
  if (p->random_sd) {
    return "parameter '" + target + "': the sd of a parameter drawn per run; group_variation varies a systematic parameter";
  }
  if (!info->systematic) {
    return "parameter '" + target + "': " + effect + " only adds randomness; group_variation varies a systematic parameter";
  }
  return "";
}

}  // namespace

std::string check_group_target(const EffectList& list) {
  for (const EffectSpec& g : list) {
    if (g.name != kGroupVariation) {
      if (!g.target.empty()) return g.name + " takes no 'parameter'";
      continue;
    }
    if (std::string e = check_varied_parameter(list, g.target); !e.empty()) return e;
  }
  return "";
}

std::string check_run_constants(const EffectList& list) {
  int total = 0;
  for (const EffectSpec& spec : list) {
    const EffectInfo* info = info_of(spec);
    total += info ? info->run_constants : 0;
  }
  if (total <= kMaxRunConstants) return "";
  return "at most " + std::to_string(kMaxRunConstants) +
         " per-run constants in one model (per_run_radius has 2, each random parameter of a custom "
         "effect 1), got " + std::to_string(total);
}

void check_effects(const EffectList& list) {
  if (list.size() > kMaxEffects) {
    throw EffectError("effects", "at most " + std::to_string(kMaxEffects) + " effects, got " +
                                     std::to_string(list.size()));
  }
  if (const std::string e = check_run_constants(list); !e.empty()) throw EffectError("effects", e);
  for (std::size_t i = 0; i < list.size(); ++i) {
    const std::string key = "effects[" + std::to_string(i) + "]." + list[i].name;
    if (const std::string error = check_effect(list[i]); !error.empty()) throw EffectError(key, error);
    for (std::size_t j = 0; j < i; ++j) {
      if (list[j].name == list[i].name) throw EffectError(key, "effect listed twice");
    }
    if (list[i].name == kGroupVariation) {
      if (const std::string error = check_group_target(list); !error.empty()) throw EffectError(key, error);
    }
  }
}

namespace effects {

Motion MotionTracker::next(double dL_m, double dR_m, double dt_s, std::int64_t count) {
  Motion m;
  m.dL_m = dL_m;
  m.dR_m = dR_m;
  m.dt_s = dt_s;
  const double travel = std::abs(dL_m) + std::abs(dR_m);
  m.v_mps = travel / (2.0 * dt_s);
  const double sum = dL_m + dR_m, diff = dR_m - dL_m;
  m.dir = (sum > 0) - (sum < 0);
  m.turn = (diff > 0) - (diff < 0);
  m.r = travel > 0 ? std::abs(diff) / travel : 0.0;
  m.kappa_per_m = sum != 0 ? 2.0 * diff / (wheelbase_m_ * sum) : m.turn * HUGE_VAL;
  m.turn_rad = diff / wheelbase_m_;
  m.omega_radps = m.turn_rad / dt_s;
  m.a_mps2 = (m.v_mps - v_mps_) / dt_s;  // the first of `count` equal increments; the rest: 0
  m.theta_rad = theta_rad_;
  m.heading0_rad = heading0_rad_;
  // A wheel reverses when it moves against its last direction of motion; standing still keeps it.
  auto wheel = [](double d, int& dir, double& since) {
    const int sign = (d > 0) - (d < 0);
    if (sign != 0 && sign != dir) {
      dir = sign;
      since = 0.0;
    }
  };
  wheel(dL_m, dir_left_, since_left_);
  wheel(dR_m, dir_right_, since_right_);
  m.since_reversal_left_m = since_left_;
  m.since_reversal_right_m = since_right_;
  m.t_s = t_s_;
  m.s_m = s_m_;
  const double n = static_cast<double>(count);
  since_left_ += n * std::abs(dL_m);
  since_right_ += n * std::abs(dR_m);
  t_s_ += n * dt_s;
  s_m_ += n * 0.5 * travel;
  theta_rad_ += n * m.turn_rad;
  v_mps_ = m.v_mps;
  return m;
}

Systematic others_systematic(const PieceModel& piece, const Effect* self) {
  Systematic s;
  for (const auto& e : *piece.effects) {
    if (e.get() != self) e->systematic(*piece.motion, s);
  }
  return s;
}

void ResolvedPath::measure(Vector3& pose, Matrix3& P_world) const {
  if (measurement_effects.empty()) return;
  Matrix3 J = Matrix3::Identity();
  for (const auto& e : measurement_effects) e->measure_model(pose, J);
  P_world = J * P_world * J.transpose();
}

const EffectType& type_of(const std::string& name) {
  for (const EffectType& t : registry()) {
    if (t.info.name == name) return t;
  }
  throw EffectError("effects", "unknown effect '" + name + "'");
}

std::vector<std::unique_ptr<Effect>> instantiate(const EffectList& list) {
  check_effects(list);
  std::vector<std::unique_ptr<Effect>> out;
  for (const EffectSpec& spec : list) {
    out.push_back(spec.custom ? make_custom(spec) : type_of(spec.name).make(spec.values));
  }
  return out;
}

}  // namespace effects

std::string non_gaussian_effect(const EffectList& list) {
  const auto objects = effects::instantiate(list);
  for (std::size_t i = 0; i < list.size(); ++i) {
    if (std::string why = objects[i]->non_gaussian(); !why.empty()) return list[i].name + ": " + why;
  }
  return "";
}

bool heavy_tailed_effect(const EffectList& list) {
  const auto objects = effects::instantiate(list);
  return std::any_of(objects.begin(), objects.end(), [](const auto& e) { return e->heavy_tailed(); });
}

FitCoordinate fit_coordinate(const EffectParameterInfo& p) {
  FitCoordinate c;
  const double scale = std::abs(p.typical - p.neutral);
  c.fd_abs = 0.05 * std::max(scale, 1e-9);
  c.fd_rel = 0.05;
  c.fd_origin = p.neutral;
  using T = FitCoordinate::Transform;
  if (p.lower <= -1e300 && p.upper >= 1e300) {  // signed and unbounded (reference_offset.dx)
    c.transform = T::identity;
    c.lower_u = p.neutral - 1e4 * scale;
    c.upper_u = p.neutral + 1e4 * scale;
    c.step_u = std::max(scale, 1e-6);
  } else if (p.open_lower && p.lower == 0.0 && p.upper >= 1e300 && p.neutral == 1.0) {
    c.transform = T::log;  // a positive scale factor (Ed, Eb, Es)
    c.lower_u = std::log(0.5);
    c.upper_u = std::log(2.0);
    c.step_u = std::max(scale, 1e-3);
  } else if (p.open_lower && p.lower == 0.0 && p.upper >= 1e300) {
    c.transform = T::log;  // any other positive quantity
    const double typical = p.typical > 0 ? p.typical : 1.0;
    c.lower_u = std::log(typical) - std::log(1e6);
    c.upper_u = std::log(typical) + std::log(1e6);
    c.step_u = 0.3;
  } else if (p.open_lower && p.open_upper) {  // an open interval (a, b), e.g. rho in (-1, 1)
    c.transform = T::atanh;
    c.mid = 0.5 * (p.lower + p.upper);
    c.half = 0.5 * (p.upper - p.lower);
    c.lower_u = -6.0;
    c.upper_u = 6.0;
    c.step_u = 0.3;
  } else {  // a size that may be zero (slip, per-run sigma, bump rate and size)
    c.transform = T::sqrt;
    c.lower_u = 0.0;
    c.upper_u = std::sqrt(1e4 * p.typical);
    c.step_u = 0.5 * std::sqrt(p.typical);
  }
  return c;
}

}  // namespace odomcov
