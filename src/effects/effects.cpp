#include <cmath>

#include "effect.hpp"
#include "odomcov/format.hpp"

namespace odomcov {

const std::vector<EffectInfo>& effect_catalogue() {
  static const std::vector<EffectInfo> infos = [] {
    std::vector<EffectInfo> out;
    for (const effects::EffectType& t : effects::registry()) out.push_back(t.info);
    return out;
  }();
  return infos;
}

const EffectInfo* find_effect(const std::string& name) {
  for (const EffectInfo& info : effect_catalogue()) {
    if (info.name == name) return &info;
  }
  return nullptr;
}

std::string check_effect(const EffectSpec& spec) {
  const EffectInfo* info = find_effect(spec.name);
  if (!info) return "unknown effect '" + spec.name + "'";
  if (spec.values.size() != info->parameters.size()) {
    return spec.name + " takes " + std::to_string(info->parameters.size()) + " parameters";
  }
  for (std::size_t i = 0; i < spec.values.size(); ++i) {
    const EffectParameterInfo& p = info->parameters[i];
    const double v = spec.values[i];
    if (!std::isfinite(v)) return p.name + " must be finite";
    const bool below = p.open_lower ? !(v > p.lower) : !(v >= p.lower);
    const bool above = p.open_upper ? !(v < p.upper) : !(v <= p.upper);
    if (below || above) {
      std::string range = (p.open_lower ? "(" : "[") + format_number(p.lower) + ", ";
      range += p.upper >= 1e300 ? std::string("inf)") : format_number(p.upper) + (p.open_upper ? ")" : "]");
      return p.name + " must be in " + range + ", got " + format_number(v);
    }
  }
  return "";
}

std::string effect_yaml(const EffectSpec& spec) {
  const EffectInfo* info = find_effect(spec.name);
  std::string text = "- " + spec.name + ": {";
  for (std::size_t i = 0; i < spec.values.size(); ++i) {
    text += (i ? ", " : "") + (info ? info->parameters[i].name : "p" + std::to_string(i)) + ": " +
            format_number(spec.values[i]);
  }
  return text + "}";
}

namespace effects {

std::vector<std::unique_ptr<Effect>> instantiate(const EffectList& list) {
  std::vector<std::unique_ptr<Effect>> out;
  for (const EffectSpec& spec : list) {
    for (const EffectType& t : registry()) {
      if (t.info.name == spec.name) out.push_back(t.make(spec.values));
    }
  }
  return out;
}

}  // namespace effects
}  // namespace odomcov
