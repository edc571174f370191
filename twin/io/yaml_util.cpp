#include "twin/io/yaml_util.hpp"

#include <charconv>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"

namespace twin::io {

YAML::Node load_yaml_file(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path)) throw IoError(fmt::format("{}: no such file", path.string()));
  const std::string text = read_file(path);
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(fmt::format("{}:{}: {}", path.string(), e.mark.line + 1, e.msg));
  }
}

double yaml_number(const YAML::Node& node, const std::string& where) {
  if (!node.IsScalar()) throw ConfigError(fmt::format("{} must be a number", where));
  const std::string& s = node.Scalar();
  double v = 0.0;
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (s.empty() || ec != std::errc() || p != s.data() + s.size())
    throw ConfigError(fmt::format("{} = '{}' is not a number", where, s));
  if (!std::isfinite(v)) throw ConfigError(fmt::format("{} = {} is not finite", where, s));
  return v;
}

std::string yaml_string(const YAML::Node& node, const std::string& where) {
  if (!node.IsScalar()) throw ConfigError(fmt::format("{} must be a string", where));
  return node.Scalar();
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
