#pragma once
/// Small typed accessors over yaml-cpp that turn every problem into a
/// one-line ConfigError naming the place.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <yaml-cpp/yaml.h>

namespace twin::io {

/// Largest YAML file load_yaml_file reads.
inline constexpr std::uintmax_t kMaxYamlBytes = std::uintmax_t{16} << 20;
/// Parses YAML text; ConfigError "source:line: ..." for a syntax error, a key
/// that is not a plain scalar (a map or list as key) or a key given twice in
/// one map.
YAML::Node parse_yaml_text(const std::string& text, const std::string& source);
/// Reads a regular file of at most kMaxYamlBytes (see read_file) and parses it.
YAML::Node load_yaml_file(const std::filesystem::path& path);
double yaml_number(const YAML::Node& node, const std::string& where);
std::string yaml_string(const YAML::Node& node, const std::string& where);
/// A name or file name: a non-empty string on one line, without control characters.
std::string yaml_name(const YAML::Node& node, const std::string& where);
bool yaml_bool(const YAML::Node& node, const std::string& where);
/// `text` for a one-line message: control bytes and backslashes as \xNN,
/// cut after max_chars with "...".
std::string escaped(std::string_view text, std::size_t max_chars = 60);

}  // namespace twin::io
