#pragma once
/// The model an exported FMU carries in resources/model.json: the machine
/// (every parameter by its table name, spec/interfaces.md), the part program,
/// where the axes start, and the process section of the scenario (JSON, or
/// null for an air cut). The twin executable writes it (model_to_json) and
/// the FMU reads it back (model_from_json); both build the variable table
/// and modelDescription.xml from the model read back, so the two agree by
/// construction.
#include <cstdint>
#include <memory>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "controller/interpolator.hpp"
#include "process/process_model.hpp"
#include "twin/core/axis.hpp"
#include "twin/sim/machine.hpp"
#include "twin/sim/scenario.hpp"

namespace twin::fmu {

/// The longest part program an FMU accepts: planned motion plus settle_s,
/// in machine time (one day: no part program runs that long, while a dwell
/// of G4 P1e9 or a move of 1e6 mm does) and in controller ticks (1e9 ticks
/// are 1.4 to 14 hours of computing at the 5 to 50 us per tick measured in
/// docs/fmu.md; 8.64e8 ticks are the day at Ts = 1e-4 s).
inline constexpr double kMaxProgramDuration_s = 86400.0;
inline constexpr double kMaxProgramTicks = 1e9;

/// The scenario the FMU carries (program_path: the program's file name, for
/// messages; program_text empty: mode 2 is not available) and the text it
/// was read from.
struct FmuModel : sim::Scenario {
  std::string model_json;       ///< the exact text this model was read from (hashed into the GUID)

  bool has_program() const noexcept { return !program_text.empty(); }
  bool has_process() const noexcept { return process_setup.has_value(); }
  /// Cycle time of the program plus settle_s, s (0 without a program).
  double program_duration_s() const;
  /// The program parsed for `machine` (its rapid rate, travel, limits and
  /// Ts) and planned (sim::plan_program). @throws ConfigError naming the program's file and line
  /// for a move beyond the machine's travel (controller::check_travel), and
  /// giving both figures and both limits for a program planned longer than
  /// kMaxProgramDuration_s or kMaxProgramTicks.
  sim::PlannedProgram plan_program(const sim::MachineDefinition& machine) const;
};

/// JSON text of the model (format "twin-fmu-model", version 1).
/// `process` is the scenario's process section (null: air cut).
std::string model_to_json(const std::string& scenario_name, const sim::MachineDefinition& machine,
                          const std::string& program_name, const std::string& program_text,
                          const AxisArray<double>& start_mm, double settle_s, const nlohmann::json& process);

/// Reads a model written by model_to_json. `where` names the file in messages.
/// @throws ConfigError naming `where` and the key for a missing or bad entry.
FmuModel model_from_json(const std::string& text, const std::string& where);

}  // namespace twin::fmu
