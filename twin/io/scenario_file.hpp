#pragma once
/// A scenario: a machine, a part program, where the machine starts and, when
/// it cuts, the process (tool, material, stock). YAML; see scenarios/README.md.
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "controller/gcode.hpp"
#include "process/milling_process.hpp"
#include "process/process_model.hpp"
#include "twin/sim/machine.hpp"

namespace twin::io {

struct Scenario {
  std::string name;
  std::string description;
  std::filesystem::path path;
  std::filesystem::path program_path;
  sim::MachineDefinition machine;
  std::string program_text;
  AxisArray<double> start_mm{};
  double settle_s{0.05};
  /// Builds a fresh process model (the in-process stock at its initial
  /// state); empty for an air cut.
  std::function<std::unique_ptr<process::ProcessModel>()> make_process;
  /// A one-line description of the process (tool, material, conditions).
  std::string process_summary;
  /// The process setup `make_process` builds from (set with it).
  std::optional<process::ProcessSetup> process_setup;
};

/// The built-in default: the FADAL 2216 pocket-corner scenario.
std::filesystem::path default_scenario_path();
/// A path to a scenario.yaml, a folder holding one, or the name of a shipped scenario.
std::filesystem::path resolve_scenario_path(const std::string& name_or_path);
/// Loads the scenario; `machine_override` (a name or path) replaces its machine.
Scenario load_scenario(const std::filesystem::path& path, const std::string& machine_override = {});
/// Makes the scenario's process cut with these tool-tip modes (empty: a rigid
/// tool); nothing for an air cut. load_scenario does this with the machine's
/// modes when the machine file has a `structure:`.
void set_tool_modes(Scenario& scenario, const process::ToolTipFrf& tool_tip);
/// True when the scenario cuts with a vibrating tool (its process has tool-tip modes).
bool vibrating_tool(const Scenario& scenario);
/// Parses the scenario's program against its (possibly overridden) machine;
/// ConfigError if the program does not fit in the machine's travel
/// (controller::check_travel).
controller::Program parse_program(const Scenario& scenario);

}  // namespace twin::io
