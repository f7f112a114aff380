#include "odomcov/io/suite_writer.hpp"

#include <yaml-cpp/yaml.h>

#include <stdexcept>

#include "odomcov/base/format.hpp"

namespace odomcov {
namespace {

/// Enough digits that any value typed with up to 15 significant digits reads back exactly.
constexpr int kYamlDigits = 15;

/// A custom effect's definition (inside its flow map): name, parameters with their values,
/// random with each sd, then its expressions.
void emit_custom(YAML::Emitter& out, const EffectSpec& e) {
  const CustomEffect& def = *e.custom;
  out << YAML::Key << "name" << YAML::Value << e.name << YAML::Key << "parameters" << YAML::Value << YAML::BeginMap;
  for (std::size_t i = 0; i < def.parameters.size(); ++i) {
    out << YAML::Key << def.parameters[i] << YAML::Value << e.values[i];
  }
  out << YAML::EndMap;
  if (!def.random.empty()) {
    out << YAML::Key << "random" << YAML::Value << YAML::BeginMap;
    for (std::size_t j = 0; j < def.random.size(); ++j) {
      out << YAML::Key << def.random[j] << YAML::Value << e.values[def.parameters.size() + j];
    }
    out << YAML::EndMap;
  }
  for (const auto& [key, x] : def.expressions()) {
    if (!x->text.empty()) out << YAML::Key << key << YAML::Value << YAML::DoubleQuoted << x->text;
  }
}

void emit_effects(YAML::Emitter& out, const EffectList& effects) {
  out << YAML::BeginSeq;
  for (const EffectSpec& e : effects) {
    const EffectInfo* info = info_of(e);
    if (!info || info->parameters.size() != e.values.size()) {
      throw std::invalid_argument("suite_yaml: unknown effect or wrong parameter count: " + e.name);
    }
    out << YAML::BeginMap << YAML::Key << (e.custom ? "custom" : e.name) << YAML::Value << YAML::Flow
        << YAML::BeginMap;
    if (e.custom) {
      emit_custom(out, e);
    } else {
      if (!e.target.empty()) out << YAML::Key << "parameter" << YAML::Value << e.target;
      for (std::size_t i = 0; i < e.values.size(); ++i) {
        out << YAML::Key << info->parameters[i].name << YAML::Value << e.values[i];
      }
    }
    out << YAML::EndMap << YAML::EndMap;
  }
  out << YAML::EndSeq;
}

}  // namespace

std::string suite_yaml(const SuiteDocument& suite) {
  YAML::Emitter out;
  out.SetDoublePrecision(kYamlDigits);
  out << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << YAML::DoubleQuoted << suite.name;
  out << YAML::Key << "robot" << YAML::Value << YAML::Flow << YAML::BeginMap
      << YAML::Key << "wheelbase" << YAML::Value << suite.robot.wheelbase_m
      << YAML::Key << "k_left" << YAML::Value << suite.robot.noise.k_left
      << YAML::Key << "k_right" << YAML::Value << suite.robot.noise.k_right << YAML::EndMap;
  out << YAML::Key << "measurement_noise" << YAML::Value << YAML::Flow << YAML::BeginMap
      << YAML::Key << "xy" << YAML::Value << suite.measurement_noise.xy_m
      << YAML::Key << "theta_deg" << YAML::Value << suite.measurement_noise.theta_rad / kDegToRad
      << YAML::EndMap;
  if (!suite.model_effects.empty()) {
    out << YAML::Key << "model" << YAML::Value << YAML::BeginMap << YAML::Key << "effects"
        << YAML::Value;
    emit_effects(out, suite.model_effects);
    out << YAML::EndMap;
  }
  out << YAML::Key << "experiments" << YAML::Value << YAML::BeginSeq;
  for (const SuiteDocument::Experiment& ex : suite.experiments) {
    out << YAML::BeginMap << YAML::Key << "name" << YAML::Value << YAML::DoubleQuoted << ex.name;
    if (!ex.group.empty()) out << YAML::Key << "group" << YAML::Value << YAML::DoubleQuoted << ex.group;
    if (!ex.kind.empty()) out << YAML::Key << "kind" << YAML::Value << YAML::DoubleQuoted << ex.kind;
    if (!ex.logs.empty()) {
      out << YAML::Key << "logs" << YAML::Value << YAML::BeginSeq;
      for (const std::string& log : ex.logs) out << YAML::DoubleQuoted << log;
      out << YAML::EndSeq;
    } else if (!ex.path_yaml.empty() && !ex.measurements.empty()) {
      out << YAML::Key << "path" << YAML::Value << YAML::Load(ex.path_yaml) << YAML::Key
          << "measurements" << YAML::Value << YAML::DoubleQuoted << ex.measurements;
    } else {
      throw std::invalid_argument("suite_yaml: experiment '" + ex.name +
                                  "' has neither logs nor a path with measurements");
    }
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  std::string text;
  for (const std::string& c : suite.comments) text += "#" + (c.empty() ? "" : " " + c) + "\n";
  return text + out.c_str() + "\n";
}

}  // namespace odomcov
