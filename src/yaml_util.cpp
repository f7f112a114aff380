#include "yaml_util.hpp"

#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

namespace odomcov::yaml {

YAML::Node load_file(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path, 0, "", "cannot open file");
  std::stringstream text;
  text << in.rdbuf();
  try {
    YAML::Node root = YAML::Load(text.str());
    if (!root.IsDefined() || root.IsNull()) throw InputError(path, 0, "", "file is empty");
    return root;
  } catch (const YAML::ParserException& e) {
    throw InputError(path, e.mark.line >= 0 ? e.mark.line + 1 : 0, "",
                     "malformed YAML: " + e.msg);
  }
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
    const std::string name = entry.first.as<std::string>();
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
    fail(where, node, "expected a number, got '" + node.Scalar() + "'");
  }
  if (!std::isfinite(value)) fail(where, node, "must be finite, got " + node.Scalar());
  return value;
}

std::int64_t to_integer(const Where& where, const YAML::Node& node, std::int64_t min,
                        std::int64_t max) {
  const double value = to_number(where, node);
  if (value != std::floor(value)) fail(where, node, "expected a whole number, got " + node.Scalar());
  if (value < static_cast<double>(min) || value > static_cast<double>(max)) {
    fail(where, node,
         "must be in [" + std::to_string(min) + ", " + std::to_string(max) + "], got " +
             node.Scalar());
  }
  return static_cast<std::int64_t>(value);
}

std::uint64_t to_unsigned(const Where& where, const YAML::Node& node) {
  if (!node.IsScalar()) fail(where, node, "expected a non-negative integer");
  const std::string& text = node.Scalar();
  if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos) {
    fail(where, node, "expected a non-negative integer, got '" + text + "'");
  }
  try {
    std::size_t used = 0;
    const unsigned long long value = std::stoull(text, &used, 10);
    return static_cast<std::uint64_t>(value);
  } catch (const std::exception&) {
    fail(where, node, "integer out of range: " + text);
  }
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

}  // namespace odomcov::yaml
