#include "twin/io/process_yaml.hpp"

#include <memory>
#include <vector>

#include <fmt/format.h>

#include "twin/sim/process_setup_reader.hpp"
#include "twin/io/yaml_util.hpp"

namespace twin::io {
namespace {

/// A YAML node as the process setup reader sees it; scalars naming files
/// are taken from `dir`.
class YamlSetupNode final : public sim::SetupNode {
 public:
  YamlSetupNode(YAML::Node node, std::filesystem::path dir) : node_(std::move(node)), dir_(std::move(dir)) {}
  const char* format() const override { return "YAML"; }
  bool is_map() const override { return node_.IsMap(); }
  bool is_list() const override { return node_.IsSequence(); }
  bool is_scalar() const override { return node_.IsScalar(); }
  std::vector<std::string> keys() const override {
    std::vector<std::string> out;
    for (const auto& kv : node_) out.push_back(kv.first.as<std::string>());
    return out;
  }
  std::unique_ptr<sim::SetupNode> get(const std::string& key) const override {
    const YAML::Node n = node_[key];
    return n ? wrap(n) : nullptr;
  }
  std::size_t size() const override { return node_.size(); }
  std::unique_ptr<sim::SetupNode> item(std::size_t i) const override { return wrap(node_[i]); }
  double number(const std::string& where) const override { return yaml_number(node_, where); }
  std::string name(const std::string& where) const override { return yaml_name(node_, where); }
  std::string text(const std::string& where) const override { return yaml_string(node_, where); }
  std::string locate(const std::string& where, const std::string& key) const override { return at(where, node_, key); }
  std::string locate_key(const std::string& where, const std::string& key, const std::string& label) const override {
    for (const auto& kv : node_)
      if (kv.first.as<std::string>() == key) return at(where, kv.first, label);
    return at(where, node_, label);
  }
  std::unique_ptr<sim::SetupNode> open_file(const std::string& where, std::string& file_where) const override {
    const std::filesystem::path path = dir_ / yaml_name(node_, where);
    file_where = path.string();
    return std::make_unique<YamlSetupNode>(load_yaml_file(path), path.parent_path());
  }

 private:
  static std::string at(const std::string& where, const YAML::Node& node, const std::string& key) {
    const auto m = node.Mark();
    if (m.line >= 0) return fmt::format("{}:{}: {}", where, m.line + 1, key);
    return fmt::format("{}: {}", where, key);
  }
  std::unique_ptr<sim::SetupNode> wrap(const YAML::Node& n) const { return std::make_unique<YamlSetupNode>(n, dir_); }

  YAML::Node node_;
  std::filesystem::path dir_;
};

}  // namespace

process::ToolGeometry parse_tool(const YAML::Node& node, const std::string& where) {
  return sim::read_tool(YamlSetupNode(node, {}), where);
}

process::ToolGeometry load_tool_file(const std::filesystem::path& path) {
  return sim::read_tool_document(YamlSetupNode(load_yaml_file(path), path.parent_path()), path.string());
}

process::CuttingCoefficients parse_material(const YAML::Node& node, const std::string& where, double lead_deg,
                                            double tilt_deg) {
  return sim::read_material(YamlSetupNode(node, {}), where, lead_deg, tilt_deg);
}

process::CuttingCoefficients load_material_file(const std::filesystem::path& path, double lead_deg, double tilt_deg) {
  return sim::read_material_document(YamlSetupNode(load_yaml_file(path), path.parent_path()), path.string(), lead_deg,
                                     tilt_deg);
}

process::ToolTipFrf parse_tool_tip(const YAML::Node& node, const std::string& where, std::string& source) {
  return sim::read_tool_tip(YamlSetupNode(node, {}), where, &source);
}

process::ProcessSetup parse_process_setup(const YAML::Node& node, const std::string& where,
                                          const std::filesystem::path& dir) {
  return sim::read_process_setup(YamlSetupNode(node, dir), where);
}

}  // namespace twin::io
