#pragma once
/// Reads the `process:` section of a scenario and the tool and material
/// files it names (YAML, see docs/process.md for the schema) through the one
/// process setup reader (twin/sim/process_setup_reader.hpp), which the FMU's
/// resources go through as well. Every problem is a ConfigError
/// "file:line: process.key ...".
#include <filesystem>
#include <string>

#include <yaml-cpp/yaml.h>

#include "process/milling_process.hpp"

namespace twin::io {

/// A tool mapping (keys of process::ToolGeometry, `type` flat|bull_nose|ball).
process::ToolGeometry parse_tool(const YAML::Node& node, const std::string& where);
process::ToolGeometry load_tool_file(const std::filesystem::path& path);
/// A material mapping with `sets:`; picks the set measured at (lead, tilt).
process::CuttingCoefficients parse_material(const YAML::Node& node, const std::string& where, double lead_deg,
                                            double tilt_deg);
process::CuttingCoefficients load_material_file(const std::filesystem::path& path, double lead_deg, double tilt_deg);
/// A machine file's `tool_tip:` map (x and y mode lists and its `source`, into
/// `source` when present); `where` names it ("machine.yaml: tool_tip").
process::ToolTipFrf parse_tool_tip(const YAML::Node& node, const std::string& where, std::string& source);
/// The whole `process:` section; relative file names are taken from `dir`.
process::ProcessSetup parse_process_setup(const YAML::Node& node, const std::string& where,
                                          const std::filesystem::path& dir);

}  // namespace twin::io
