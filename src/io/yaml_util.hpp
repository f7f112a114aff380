// Checked access to YAML input: every failure is an InputError naming file, line and dotted key.
#pragma once

#include <yaml-cpp/yaml.h>

#include <cstdint>
#include <initializer_list>
#include <optional>
#include <string>

#include "odomcov/base/error.hpp"

namespace odomcov::yaml {

/// Where a node came from: its file and dotted key path (e.g. "robot.wheelbase").
struct Where {
  std::string file;
  std::string key;

  Where child(const std::string& name) const { return {file, key.empty() ? name : key + "." + name}; }
  Where index(std::size_t i) const { return {file, key + "[" + std::to_string(i) + "]"}; }
};

/// Parses a YAML file. A missing, non-regular or over-large file (input_file.hpp), malformed
/// YAML, a key that is not a plain scalar (`? [1]: 2`, `? :`) and a key given twice in one map
/// are InputErrors naming the file, the line and the dotted key.
YAML::Node load_file(const std::string& path);
/// The same checks on YAML (or JSON, its subset) text; `source` names it in errors.
YAML::Node load_text(const std::string& text, const std::string& source);

/// Turns a yaml-cpp exception into an InputError with the file and the node's line.
[[noreturn]] void translate_yaml_exception(const std::string& file, const YAML::Exception& e);

/// Runs `body` (a loader's work on YAML nodes) so that no yaml-cpp exception escapes it: the
/// checks above come first, and anything yaml-cpp still throws becomes an InputError.
template <class Body>
auto guarded(const std::string& file, Body&& body) -> decltype(body()) {
  try {
    return body();
  } catch (const YAML::Exception& e) {
    translate_yaml_exception(file, e);
  }
}

/// 1-based line of a node, 0 if unknown.
int line_of(const YAML::Node& node);

[[noreturn]] void fail(const Where& where, const YAML::Node& node, const std::string& what);

/// The node must be a map whose keys are all in `allowed` (so typos do not pass silently).
void require_map(const Where& where, const YAML::Node& node,
                 std::initializer_list<const char*> allowed);
void require_sequence(const Where& where, const YAML::Node& node);

/// `parent[key]`, which must exist (the error points at the parent when it does not).
YAML::Node require(const Where& parent_where, const YAML::Node& parent, const char* key);

/// A finite number.
double to_number(const Where& where, const YAML::Node& node);
/// A whole number in [min, max] (written as an integer, or as 1e4 and the like).
std::int64_t to_integer(const Where& where, const YAML::Node& node, std::int64_t min,
                        std::int64_t max);
/// A non-negative 64-bit integer (seeds).
std::uint64_t to_unsigned(const Where& where, const YAML::Node& node);
std::string to_string(const Where& where, const YAML::Node& node);

double require_number(const Where& parent_where, const YAML::Node& parent, const char* key);
std::optional<double> optional_number(const Where& parent_where, const YAML::Node& parent,
                                      const char* key);
/// `parent[key]` as non-empty text (an experiment's group or kind), or `fallback` when absent.
std::string optional_text(const Where& parent_where, const YAML::Node& parent, const char* key,
                          const std::string& fallback = "");

}  // namespace odomcov::yaml
