#pragma once
/// A scenario: a machine, a part program, where the machine starts and, when
/// it cuts, the process (tool, material, stock). YAML; see scenarios/README.md.
#include <filesystem>
#include <string>

#include "twin/sim/scenario.hpp"

namespace twin::io {

/// The scenario as data (twin/sim/scenario.hpp); this file reads it from YAML.
using Scenario = sim::Scenario;
using sim::parse_program;
using sim::vibrating_tool;

/// The built-in default: the FADAL 2216 pocket-corner scenario.
std::filesystem::path default_scenario_path();
/// A path to a scenario.yaml, a folder holding one, or the name of a shipped scenario.
std::filesystem::path resolve_scenario_path(const std::string& name_or_path);
/// Loads the scenario; `machine_override` (a name or path) replaces its machine.
Scenario load_scenario(const std::filesystem::path& path, const std::string& machine_override = {});

}  // namespace twin::io
