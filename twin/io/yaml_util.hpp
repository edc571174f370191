#pragma once
/// Small typed accessors over yaml-cpp that turn every problem into a
/// one-line ConfigError naming the place.
#include <filesystem>
#include <string>

#include <yaml-cpp/yaml.h>

namespace twin::io {

YAML::Node load_yaml_file(const std::filesystem::path& path);
double yaml_number(const YAML::Node& node, const std::string& where);
std::string yaml_string(const YAML::Node& node, const std::string& where);
bool yaml_bool(const YAML::Node& node, const std::string& where);

}  // namespace twin::io
