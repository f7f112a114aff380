#include "io/yaml_util.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>
#include <set>
#include <utility>

#include "io/input_file.hpp"
#include "odomcov/closed_form/limits.hpp"

namespace odomcov::yaml {
namespace {

const char* kind_name(const YAML::Node& node) {
  switch (node.Type()) {
    case YAML::NodeType::Map: return "a map";
    case YAML::NodeType::Sequence: return "a list";
    case YAML::NodeType::Null: return "an empty key";
    default: return "a value";
  }
}

/// The structural checks every loader relies on, done once on the whole tree: every map key is
/// a plain scalar, and no map has a key twice. Aliased containers are walked once (their mark
/// identifies them), so an alias bomb costs no more than the text it is written in.
void check_tree(const Where& where, const YAML::Node& node,
                std::set<std::pair<int, int>>& visited) {
  if (!node.IsMap() && !node.IsSequence()) return;
  const YAML::Mark mark = node.Mark();
  if (mark.line >= 0 && !visited.insert({mark.line, mark.column}).second) return;
  if (node.IsSequence()) {
    std::size_t i = 0;
    for (const auto& item : node) check_tree(where.index(i++), item, visited);
    return;
  }
  std::map<std::string, int> first_line;
  for (const auto& entry : node) {
    if (!entry.first.IsScalar()) {
      fail(where.child("?"), entry.first,
           std::string("keys must be plain names, got ") + kind_name(entry.first) + " as a key");
    }
    const std::string& name = entry.first.Scalar();
    const int line = line_of(entry.first);
    if (const auto [it, fresh] = first_line.emplace(name, line); !fresh) {
      fail(where.child(name), entry.first,
           "duplicate key (first at line " + std::to_string(it->second) + ")");
    }
    check_tree(where.child(name), entry.second, visited);
  }
}

}  // namespace

YAML::Node load_file(const std::string& path) {
  return load_text(read_input_file(path, kMaxYamlBytes, "YAML file"), path);
}

YAML::Node load_text(const std::string& text, const std::string& source) {
  if (text.size() > kMaxYamlBytes) {
    throw InputError(source, 0, "", "YAML text of " + std::to_string(text.size()) + " bytes, above the limit of " +
                                        std::to_string(kMaxYamlBytes));
  }
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(source, e.mark.line >= 0 ? e.mark.line + 1 : 0, "", "malformed YAML: " + e.msg);
  }
  if (!root.IsDefined() || root.IsNull()) throw InputError(source, 0, "", "file is empty");
  std::set<std::pair<int, int>> visited;
  check_tree({source, ""}, root, visited);
  return root;
}

void translate_yaml_exception(const std::string& file, const YAML::Exception& e) {
  throw InputError(file, e.mark.line >= 0 ? e.mark.line + 1 : 0, "",
                   "unexpected YAML structure: " + e.msg);
}

int line_of(const YAML::Node& node) {
  if (!node.IsDefined()) return 0;
  const YAML::Mark mark = node.Mark();
  return mark.line >= 0 ? mark.line + 1 : 0;
}

void fail(const Where& where, const YAML::Node& node, const std::string& what) {
  throw InputError(where.file, line_of(node), where.key, what);
}

void require_map(const Where& where, const YAML::Node& node,
                 std::initializer_list<const char*> allowed) {
  if (!node.IsMap()) fail(where, node, "expected a map");
  for (const auto& entry : node) {
    if (!entry.first.IsScalar()) fail(where.child("?"), entry.first, "keys must be plain names");
    const std::string name = entry.first.Scalar();
    bool known = false;
    std::string list;
    for (const char* a : allowed) {
      known = known || name == a;
      list += list.empty() ? a : std::string(", ") + a;
    }
    if (!known) fail(where.child(name), entry.first, "unknown key (allowed: " + list + ")");
  }
}

void require_sequence(const Where& where, const YAML::Node& node) {
  if (!node.IsSequence()) fail(where, node, "expected a list");
}

YAML::Node require(const Where& parent_where, const YAML::Node& parent, const char* key) {
  YAML::Node node = parent[key];
  if (!node.IsDefined() || node.IsNull()) {
    fail(parent_where.child(key), parent, "missing required key");
  }
  return node;
}

double to_number(const Where& where, const YAML::Node& node) {
  if (!node.IsScalar()) fail(where, node, "expected a number");
  double value = 0.0;
  try {
    value = node.as<double>();
  } catch (const YAML::Exception&) {
    fail(where, node, "expected a number, got " + quote(node.Scalar()));
  }
  if (!std::isfinite(value)) fail(where, node, "must be finite, got " + quote(node.Scalar()));
  return value;
}

std::int64_t to_integer(const Where& where, const YAML::Node& node, std::int64_t min,
                        std::int64_t max) {
  const double value = to_number(where, node);
  if (value != std::floor(value)) fail(where, node, "expected a whole number, got " + quote(node.Scalar()));
  if (value < static_cast<double>(min) || value > static_cast<double>(max)) {
    fail(where, node,
         "must be in [" + std::to_string(min) + ", " + std::to_string(max) + "], got " +
             quote(node.Scalar()));
  }
  return static_cast<std::int64_t>(value);
}

std::uint64_t to_unsigned(const Where& where, const YAML::Node& node) {
  if (!node.IsScalar()) fail(where, node, "expected a non-negative integer");
  const std::string& text = node.Scalar();
  if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos) {
    fail(where, node, "expected a non-negative integer, got " + quote(text));
  }
  errno = 0;
  const unsigned long long value = std::strtoull(text.c_str(), nullptr, 10);
  if (errno == ERANGE || value > std::numeric_limits<std::uint64_t>::max()) {
    fail(where, node, "integer out of range (at most 2^64 - 1): " + quote(text));
  }
  return static_cast<std::uint64_t>(value);
}

std::string to_string(const Where& where, const YAML::Node& node) {
  if (!node.IsScalar()) fail(where, node, "expected a string");
  return node.Scalar();
}

double require_number(const Where& parent_where, const YAML::Node& parent, const char* key) {
  return to_number(parent_where.child(key), require(parent_where, parent, key));
}

std::optional<double> optional_number(const Where& parent_where, const YAML::Node& parent,
                                      const char* key) {
  const YAML::Node node = parent[key];
  if (!node.IsDefined() || node.IsNull()) return std::nullopt;
  return to_number(parent_where.child(key), node);
}

std::string optional_text(const Where& parent_where, const YAML::Node& parent, const char* key,
                          const std::string& fallback) {
  const YAML::Node node = parent[key];
  if (!node) return fallback;
  std::string text = to_string(parent_where.child(key), node);
  if (text.empty()) fail(parent_where.child(key), node, "must not be empty");
  return text;
}

}  // namespace odomcov::yaml
