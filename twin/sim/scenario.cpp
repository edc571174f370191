#include "twin/sim/scenario.hpp"

#include <cmath>

namespace twin::sim {

std::string process_summary(const Scenario& scenario) {
  return scenario.process_setup ? scenario.process_setup->summary() : std::string("air cut");
}

controller::Program parse_program(const Scenario& s, const MachineDefinition& machine) {
  controller::Program program =
      controller::parse_gcode(s.program_text, s.program_path.string(), s.start_mm, machine.rapid_mm_per_min);
  AxisArray<double> lo{}, hi{};
  for (std::size_t a = 0; a < kNumAxes; ++a) {
    lo[a] = machine.axes[a].travel_min_mm;
    hi[a] = machine.axes[a].travel_max_mm;
  }
  controller::check_travel(program, lo, hi);
  return program;
}

PlannedProgram plan_program(const Scenario& scenario, const MachineDefinition& machine) {
  PlannedProgram p;
  p.program = parse_program(scenario, machine);
  p.reference = std::make_shared<ProgramReference>(
      controller::plan_trajectory(p.program, machine.motion_limits(), machine.Ts_s));
  return p;
}

std::int64_t run_ticks(const Scenario& scenario, const controller::Trajectory& trajectory) {
  return trajectory.num_ticks() + static_cast<std::int64_t>(std::ceil(scenario.settle_s / trajectory.Ts_s()));
}

CoSimulation build_cosimulation(const Scenario& scenario, const CoSimulationChoices& choices) {
  const MachineDefinition& machine = choices.machine != nullptr ? *choices.machine : scenario.machine;
  std::shared_ptr<const ReferenceSource> reference = choices.reference;
  if (reference == nullptr) reference = plan_program(scenario, machine).reference;
  std::unique_ptr<process::ProcessModel> process;
  if (scenario.process_setup && !choices.air_cut) process = process::make_process(*scenario.process_setup);
  return CoSimulation(machine, std::move(reference), std::move(process), choices.start_mm.value_or(scenario.start_mm),
                      choices.integrator);
}

}  // namespace twin::sim
