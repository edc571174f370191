#pragma once
/// The FMU's variable table: one row per FMI variable, built from the model
/// (its present axes and the parameter tables of twin/sim/machine.hpp). The
/// same table drives fmi2Get*/fmi2Set* and the generated modelDescription.xml.
///
/// value references are the row indices (unique over all types). Rows:
///   parameters  `mode` (Integer: 1 external reference, 2 built-in program),
///               machine-wide `Ts`, `encoder_resolution`, ... and per axis
///               `x.J`, `x.Kp`, ... (tunable: the loop gains Kp Ki Kd K1 K2;
///               all others fixed);
///   inputs      `x_ref_mm` ... (mode 1), `spindle_override` (Boolean) and
///               `spindle_rpm`, `fx_ext_N` `fy_ext_N` `fz_ext_N` (force on the
///               workpiece added to the cutting force);
///   outputs     the trace columns of one tick (`x_mm`, `x_u_V`, `x_i_A`,
///               `fx_N`, `feed_mm_per_min`, ...); the reference the loop
///               followed is `x_ref_out_mm`, the spindle speed `spindle_speed_rpm`.
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "twin/core/axis.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/machine.hpp"

namespace twin::fmu {

enum class VarType { kReal, kInteger, kBoolean };
enum class Causality { kParameter, kInput, kOutput };
enum class Variability { kFixed, kTunable, kDiscrete, kContinuous };

/// What a row reads or writes.
enum class VarKind {
  kMode,            ///< Integer parameter
  kMachineParam,    ///< Real parameter: machine_param
  kAxisParam,       ///< Real parameter: axis, axis_param
  kRefInput,        ///< Real input x_ref_mm of `axis`
  kSpindleOverride, ///< Boolean input
  kSpindleInput,    ///< Real input spindle_rpm
  kForceInput,      ///< Real input: component `axis` (0 x, 1 y, 2 z) of the external force
  kAxisOutput,      ///< Real output: axis_output(snapshot.axes[axis])
  kOutput,          ///< Real output: output(snapshot)
  kBlockOutput,     ///< Integer output: the program block
  kDoneOutput,      ///< Boolean output: the reference has finished
};

struct Variable {
  std::string name;
  VarType type{VarType::kReal};
  Causality causality{Causality::kOutput};
  Variability variability{Variability::kContinuous};
  std::string unit;          ///< a unit of unit_definitions() (Modelica syntax, "N.m"); empty: none
  std::string description;
  VarKind kind{VarKind::kOutput};
  std::size_t axis{0};
  const sim::AxisParamSpec* axis_param{nullptr};
  const sim::MachineParamSpec* machine_param{nullptr};
  double (*axis_output)(const sim::AxisSnapshot&){nullptr};
  double (*output)(const sim::Snapshot&){nullptr};
  bool measured{false};      ///< axis output computed from the encoder reading (x_mm, x_err_mm)
};

/// Mode values of the `mode` parameter.
inline constexpr int kModeExternal = 1;
inline constexpr int kModeProgram = 2;

/// A unit of modelDescription.xml: its name in the syntax Modelica tools
/// check ("N.m", "kg.m2", "V.s2/mm", "rev/min") and its SI base units:
/// value_SI = factor * value, with the exponents of kg, m, s, A and rad.
struct UnitDefinition {
  std::string_view name;
  int kg{0}, m{0}, s{0}, A{0}, rad{0};
  double factor{1.0};
};

/// Every unit the variables use.
const std::vector<UnitDefinition>& unit_definitions();
/// The FMI unit of a unit as the twin's tables write it ("N m" -> "N.m",
/// "kg m^2" -> "kg.m2", "rpm" -> "rev/min"). Throws InternalError for one not
/// in the table (a new parameter needs its unit added there).
std::string fmi_unit(std::string_view twin_unit);

/// The table for a machine (only its present axes get rows); with
/// `vibrating_tool` (the process cuts with the tool's modes) the outputs
/// gain the tool's deflection and surface location error.
std::vector<Variable> make_variables(const sim::MachineDefinition& machine, bool vibrating_tool = false);

/// The value of a Real parameter row (kMachineParam or kAxisParam) in `machine`.
double get_parameter(const Variable& v, const sim::MachineDefinition& machine);

/// The loop gains, which a master may change between communication steps.
bool is_tunable_axis_param(const sim::AxisParamSpec& spec);

}  // namespace twin::fmu
