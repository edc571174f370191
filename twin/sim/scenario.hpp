#pragma once
/// A scenario as data: a machine, a part program, where the axes start, how
/// long the run settles after the program, and, when it cuts, the process
/// setup (tool, material, stock). Read from scenario.yaml (twin/io) or from
/// an FMU's resources/model.json (fmu/model); build_cosimulation is the one
/// recipe that turns it into a running co-simulation.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "feeddrive/drive_bank.hpp"
#include "process/milling_process.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/machine.hpp"
#include "twin/sim/reference.hpp"

namespace twin::sim {

struct Scenario {
  std::string name;
  std::string description;
  std::filesystem::path path;          ///< the scenario file (empty when not read from one)
  std::filesystem::path program_path;  ///< the part program's file; names it in messages
  MachineDefinition machine;
  std::string program_text;
  AxisArray<double> start_mm{};
  double settle_s{0.05};
  /// The process setup (tool and material resolved to numbers); empty for an air cut.
  std::optional<process::ProcessSetup> process_setup;
};

/// "air cut", or the process setup in one line (tool, material, conditions).
std::string process_summary(const Scenario& scenario);
/// True when the scenario cuts with a vibrating tool (its process has tool-tip modes).
inline bool vibrating_tool(const Scenario& scenario) {
  return scenario.process_setup && !scenario.process_setup->tool_tip.empty();
}

/// The scenario's part program parsed for `machine` (its rapid rate) and
/// planned at its Ts, with the reference that follows the plan.
struct PlannedProgram {
  controller::Program program;
  std::shared_ptr<const ProgramReference> reference;
  const controller::Trajectory& trajectory() const noexcept { return reference->trajectory(); }
};

/// The program parsed for `machine`; ConfigError if it does not fit in the
/// machine's travel (controller::check_travel).
controller::Program parse_program(const Scenario& scenario, const MachineDefinition& machine);
inline controller::Program parse_program(const Scenario& scenario) { return parse_program(scenario, scenario.machine); }
/// The program parsed (as parse_program) and planned for `machine`.
PlannedProgram plan_program(const Scenario& scenario, const MachineDefinition& machine);
/// Ticks of a run of `trajectory`: the program's, then settle_s more.
std::int64_t run_ticks(const Scenario& scenario, const controller::Trajectory& trajectory);

/// What a caller may change of the scenario's co-simulation; the defaults
/// build the scenario as written.
struct CoSimulationChoices {
  /// Replaces the scenario's machine (tuned gains, an FMU's parameters); null: the scenario's.
  const MachineDefinition* machine{nullptr};
  /// Replaces the planned program (a plan made once and shared, an FMU's
  /// external inputs); null: the program planned for the machine.
  std::shared_ptr<const ReferenceSource> reference{};
  /// Replaces the scenario's start (a run begun in motion).
  std::optional<AxisArray<double>> start_mm{};
  /// Leaves the process out: the same motion, cutting air.
  bool air_cut{false};
  feeddrive::IntegratorOptions integrator{};
};

/// The co-simulation of `scenario`: the machine, the reference (its program
/// planned unless `choices` gives one), a fresh process model from its setup
/// (none for an air cut), every axis at rest at the start.
CoSimulation build_cosimulation(const Scenario& scenario, const CoSimulationChoices& choices = {});

}  // namespace twin::sim
