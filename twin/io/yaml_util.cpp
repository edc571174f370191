#include "twin/io/yaml_util.hpp"

#include <charconv>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/text.hpp"
#include "twin/io/atomic_file.hpp"

namespace twin::io {

std::string escaped(std::string_view text, std::size_t max_chars) {
  return printable_excerpt(text, max_chars, ExcerptBytes::kUtf8Ok);
}

namespace {

bool has_control_char(std::string_view s) {
  for (char ch : s) {
    const auto c = static_cast<unsigned char>(ch);
    if (c < 0x20 || c == 0x7f) return true;
  }
  return false;
}

/// Every key of every map is a plain scalar and appears once. Aliases share
/// their node: each collection is visited once (by its position in the
/// text), so an alias bomb costs no more than its text.
void check_keys(const YAML::Node& node, const std::string& source, std::set<std::size_t>& seen) {
  if (!node.IsMap() && !node.IsSequence()) return;
  if (!seen.insert(static_cast<std::size_t>(node.Mark().pos)).second) return;
  if (node.IsSequence()) {
    for (const auto& item : node) check_keys(item, source, seen);
    return;
  }
  std::set<std::string> keys;
  for (const auto& kv : node) {
    const int line = kv.first.Mark().line + 1;
    if (!kv.first.IsScalar())
      throw ConfigError(fmt::format("{}:{}: a key must be a plain name, not a {}", source, line,
                                    kv.first.IsMap() ? "map" : kv.first.IsSequence() ? "list" : "null"));
    const std::string& key = kv.first.Scalar();
    if (has_control_char(key))
      throw ConfigError(fmt::format("{}:{}: a key must be a plain name, not '{}'", source, line, escaped(key)));
    if (!keys.insert(key).second)
      throw ConfigError(fmt::format("{}:{}: key '{}' appears twice in the same map", source, line, key));
    check_keys(kv.second, source, seen);
  }
}

}  // namespace

YAML::Node parse_yaml_text(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(fmt::format("{}:{}: {}", source, e.mark.line + 1, escaped(e.msg, 200)));
  }
  std::set<std::size_t> seen;
  check_keys(root, source, seen);
  return root;
}

YAML::Node load_yaml_file(const std::filesystem::path& path) {
  return parse_yaml_text(read_file(path, kMaxYamlBytes), path.string());
}

double yaml_number(const YAML::Node& node, const std::string& where) {
  if (!node.IsScalar()) throw ConfigError(fmt::format("{} must be a number", where));
  const std::string& s = node.Scalar();
  double v = 0.0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || ec != std::errc() || p != s.data() + s.size())
    throw ConfigError(fmt::format("{} = '{}' is not a number", where, escaped(s)));
  if (!std::isfinite(v)) throw ConfigError(fmt::format("{} = {} is not finite", where, s));
  return v;
}

std::string yaml_string(const YAML::Node& node, const std::string& where) {
  if (!node.IsScalar()) throw ConfigError(fmt::format("{} must be a string", where));
  return node.Scalar();
}

std::string yaml_name(const YAML::Node& node, const std::string& where) {
  const std::string s = yaml_string(node, where);
  if (s.empty() || has_control_char(s))
    throw ConfigError(fmt::format("{} = '{}' must be a non-empty single line without control characters", where,
                                  escaped(s)));
  return s;
}

bool yaml_bool(const YAML::Node& node, const std::string& where) {
  if (node.IsScalar()) {
    const std::string& s = node.Scalar();
    if (s == "true" || s == "yes" || s == "on") return true;
    if (s == "false" || s == "no" || s == "off") return false;
  }
  throw ConfigError(fmt::format("{} must be true or false", where));
}

}  // namespace twin::io
