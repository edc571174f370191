#include "fmu/variables.hpp"

#include <array>
#include <string_view>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::fmu {
namespace {

struct AxisOutputSpec {
  const char* suffix;
  const char* unit;
  const char* doc;
  double (*get)(const sim::AxisSnapshot&);
  bool measured{false};  ///< computed from the encoder reading
};
struct OutputSpec {
  const char* name;
  const char* unit;
  const char* doc;
  double (*get)(const sim::Snapshot&);
};

const std::array<AxisOutputSpec, 10> kAxisOutputs{{
    {"_mm", "mm", "measured (encoder) position", [](const sim::AxisSnapshot& s) { return s.x_mm; }, true},
    {"_ref_out_mm", "mm", "reference the position loop followed", [](const sim::AxisSnapshot& s) { return s.x_ref_mm; }},
    {"_u_V", "V", "amplifier command", [](const sim::AxisSnapshot& s) { return s.u_V; }},
    {"_i_A", "A", "motor current", [](const sim::AxisSnapshot& s) { return s.i_A; }},
    {"_err_mm", "mm", "tracking error reference - measured", [](const sim::AxisSnapshot& s) { return s.e_mm; }, true},
    {"_true_mm", "mm", "true tool position on the axis", [](const sim::AxisSnapshot& s) { return s.x_true_mm; }},
    {"_v_mm_per_s", "mm/s", "true axis speed", [](const sim::AxisSnapshot& s) { return s.v_mm_per_s; }},
    {"_Tm_Nm", "N m", "motor torque", [](const sim::AxisSnapshot& s) { return s.Tm_Nm; }},
    {"_Td_Nm", "N m", "cutting load torque", [](const sim::AxisSnapshot& s) { return s.Td_Nm; }},
    {"_saturated", "1", "1 when the command is clamped at u_max", [](const sim::AxisSnapshot& s) { return s.saturated ? 1.0 : 0.0; }},
}};

const std::array<OutputSpec, 15> kOutputs{{
    {"fx_N", "N", "force on the workpiece, x, at the tick", [](const sim::Snapshot& s) { return s.F_N[0]; }},
    {"fy_N", "N", "force on the workpiece, y, at the tick", [](const sim::Snapshot& s) { return s.F_N[1]; }},
    {"fz_N", "N", "force on the workpiece, z, at the tick", [](const sim::Snapshot& s) { return s.F_N[2]; }},
    {"fx_avg_N", "N", "force on the workpiece, x, tick average", [](const sim::Snapshot& s) { return s.F_avg_N[0]; }},
    {"fy_avg_N", "N", "force on the workpiece, y, tick average", [](const sim::Snapshot& s) { return s.F_avg_N[1]; }},
    {"fz_avg_N", "N", "force on the workpiece, z, tick average", [](const sim::Snapshot& s) { return s.F_avg_N[2]; }},
    {"spindle_speed_rpm", "rpm", "spindle speed in use", [](const sim::Snapshot& s) { return s.spindle_rpm; }},
    {"feed_programmed_mm_per_min", "mm/min", "programmed feed of the current block", [](const sim::Snapshot& s) { return s.feed_programmed_mm_per_min; }},
    {"feed_ref_mm_per_min", "mm/min", "speed of the reference along the path", [](const sim::Snapshot& s) { return s.feed_ref_mm_per_min; }},
    {"feed_mm_per_min", "mm/min", "speed of the real tool", [](const sim::Snapshot& s) { return s.feed_real_mm_per_min; }},
    {"contour_error_mm", "mm", "distance of the real tool from the reference path", [](const sim::Snapshot& s) { return s.contour_error_mm; }},
    {"engagement_deg", "deg", "engaged arc of the tool", [](const sim::Snapshot& s) { return s.engagement_deg; }},
    {"chip_mm", "mm", "largest uncut chip thickness", [](const sim::Snapshot& s) { return s.chip_mm; }},
    {"spindle_torque_Nm", "N m", "cutting torque about the tool axis", [](const sim::Snapshot& s) { return s.spindle_torque_Nm; }},
    {"cutting_power_W", "W", "cutting power", [](const sim::Snapshot& s) { return s.cutting_power_W; }},
}};

/// Outputs of a tool that vibrates in the cut (the trace's tool columns).
const std::array<OutputSpec, 3> kToolOutputs{{
    {"tool_dx_um", "um", "the tool tip's deflection, x", [](const sim::Snapshot& s) { return s.tool_deflection_um[0]; }},
    {"tool_dy_um", "um", "the tool tip's deflection, y", [](const sim::Snapshot& s) { return s.tool_deflection_um[1]; }},
    {"sle_um", "um", "surface location error at the finished wall (last sampled)", [](const sim::Snapshot& s) { return s.sle_um; }},
}};

/// Twin unit text -> FMI unit name.
struct UnitAlias {
  std::string_view twin;
  std::string_view fmi;
};
constexpr std::array<UnitAlias, 32> kUnitAliases{{
    {"A/V", "A/V"},          {"N m/A", "N.m/A"},         {"kg m^2", "kg.m2"},   {"kg m^2/s", "kg.m2/s"},
    {"mm/rad", "mm/rad"},    {"V/mm", "V/mm"},           {"V/(s mm)", "V/(s.mm)"}, {"V s/mm", "V.s/mm"},
    {"V s^2/mm", "V.s2/mm"}, {"N m", "N.m"},             {"V", "V"},            {"mm/s", "mm/s"},
    {"mm/s^2", "mm/s2"},     {"mm/s^3", "mm/s3"},        {"mm", "mm"},          {"rad/s", "rad/s"},
    {"1", "1"},              {"rad", "rad"},             {"s", "s"},            {"N m/rad", "N.m/rad"},
    {"N m s/rad", "N.m.s/rad"}, {"A", "A"},              {"mm/min", "mm/min"},  {"rpm", "rev/min"},
    {"deg", "deg"},          {"N", "N"},                 {"W", "W"},
    // The cascade law's gains (torque in N m on a machine the FMU exports).
    {"1/s", "1/s"},          {"torque unit", "N.m"},     {"torque unit s/rad", "N.m.s/rad"},
    {"torque unit s^2/rad", "N.m.s2/rad"}, {"um", "um"},
}};

}  // namespace

const std::vector<UnitDefinition>& unit_definitions() {
  // Volt = kg m^2 s^-3 A^-1; newton = kg m s^-2.
  static const std::vector<UnitDefinition> kUnits{
      {"A/V", -1, -2, 3, 2, 0, 1.0},
      {"N.m/A", 1, 2, -2, -1, 0, 1.0},
      {"kg.m2", 1, 2, 0, 0, 0, 1.0},
      {"kg.m2/s", 1, 2, -1, 0, 0, 1.0},
      {"mm/rad", 0, 1, 0, 0, -1, 1e-3},
      {"V/mm", 1, 1, -3, -1, 0, 1e3},
      {"V/(s.mm)", 1, 1, -4, -1, 0, 1e3},
      {"V.s/mm", 1, 1, -2, -1, 0, 1e3},
      {"V.s2/mm", 1, 1, -1, -1, 0, 1e3},
      {"N.m", 1, 2, -2, 0, 0, 1.0},
      {"V", 1, 2, -3, -1, 0, 1.0},
      {"mm/s", 0, 1, -1, 0, 0, 1e-3},
      {"mm/s2", 0, 1, -2, 0, 0, 1e-3},
      {"mm/s3", 0, 1, -3, 0, 0, 1e-3},
      {"mm", 0, 1, 0, 0, 0, 1e-3},
      {"um", 0, 1, 0, 0, 0, 1e-6},
      {"rad/s", 0, 0, -1, 0, 1, 1.0},
      {"1", 0, 0, 0, 0, 0, 1.0},
      {"rad", 0, 0, 0, 0, 1, 1.0},
      {"s", 0, 0, 1, 0, 0, 1.0},
      {"N.m/rad", 1, 2, -2, 0, -1, 1.0},
      {"N.m.s/rad", 1, 2, -1, 0, -1, 1.0},
      {"A", 0, 0, 0, 1, 0, 1.0},
      {"mm/min", 0, 1, -1, 0, 0, 1e-3 / 60.0},
      {"rev/min", 0, 0, -1, 0, 1, 2.0 * kPi / 60.0},
      {"deg", 0, 0, 0, 0, 1, kPi / 180.0},
      {"N", 1, 1, -2, 0, 0, 1.0},
      {"W", 1, 2, -3, 0, 0, 1.0},
      {"1/s", 0, 0, -1, 0, 0, 1.0},
      {"N.m.s2/rad", 1, 2, 0, 0, -1, 1.0},
  };
  return kUnits;
}

std::string fmi_unit(std::string_view twin_unit) {
  if (twin_unit.empty()) return {};
  for (const auto& a : kUnitAliases)
    if (a.twin == twin_unit) return std::string(a.fmi);
  throw InternalError(fmt::format("fmu: no FMI unit for '{}' (add it to kUnitAliases and unit_definitions)", twin_unit));
}

double get_parameter(const Variable& v, const sim::MachineDefinition& machine) {
  if (v.kind == VarKind::kMachineParam) return v.machine_param->ref(const_cast<sim::MachineDefinition&>(machine));
  return sim::get_axis_param(machine.axes[v.axis], *v.axis_param);
}

bool is_tunable_axis_param(const sim::AxisParamSpec& spec) {
  const std::string_view n = spec.name;
  return n == "Kp" || n == "Ki" || n == "Kd" || n == "K1" || n == "K2";
}

namespace {

/// A Real variable of `kind` (type, variability and the rest set by the caller where they differ).
Variable variable(std::string name, Causality causality, std::string unit, std::string description, VarKind kind) {
  Variable v;
  v.name = std::move(name);
  v.causality = causality;
  v.unit = std::move(unit);
  v.description = std::move(description);
  v.kind = kind;
  return v;
}

/// A variable without a unit of `type` (Integer or Boolean) and `variability`.
Variable unitless(std::string name, VarType type, Causality causality, Variability variability, std::string description,
                  VarKind kind) {
  Variable v = variable(std::move(name), causality, "", std::move(description), kind);
  v.type = type;
  v.variability = variability;
  return v;
}

/// The mode switch and the machine's and the present axes' parameters.
void add_parameters(std::vector<Variable>& v, const sim::MachineDefinition& machine, const std::vector<Axis>& axes) {
  v.push_back(unitless("mode", VarType::kInteger, Causality::kParameter, Variability::kFixed,
                       "1: follow the x_ref_mm inputs; 2: run the built-in part program", VarKind::kMode));
  for (const auto& spec : sim::machine_param_specs()) {
    Variable p = variable(std::string(spec.name), Causality::kParameter, fmi_unit(spec.unit), std::string(spec.doc),
                          VarKind::kMachineParam);
    p.variability = Variability::kFixed;
    p.machine_param = &spec;
    v.push_back(p);
  }
  for (Axis a : axes) {
    for (const auto& spec : sim::axis_param_specs()) {
      if (spec.law && *spec.law != machine.axes[index(a)].loop.law) continue;  // the other loop law's gains
      Variable p = variable(std::string(axis_name(a)) + "." + std::string(spec.name), Causality::kParameter,
                            fmi_unit(spec.unit), std::string(spec.doc), VarKind::kAxisParam);
      p.variability = is_tunable_axis_param(spec) ? Variability::kTunable : Variability::kFixed;
      p.axis = index(a);
      p.axis_param = &spec;
      v.push_back(p);
    }
  }
}

/// The references, the spindle override and the external forces.
void add_inputs(std::vector<Variable>& v, const std::vector<Axis>& axes) {
  for (Axis a : axes) {
    Variable in = variable(std::string(axis_name(a)) + "_ref_mm", Causality::kInput, "mm",
                           "position reference of the axis (mode 1), held over each communication step",
                           VarKind::kRefInput);
    in.axis = index(a);
    v.push_back(in);
  }
  v.push_back(unitless("spindle_override", VarType::kBoolean, Causality::kInput, Variability::kDiscrete,
                       "true: the spindle turns at spindle_rpm instead of the program's speed",
                       VarKind::kSpindleOverride));
  v.push_back(variable("spindle_rpm", Causality::kInput, fmi_unit("rpm"),
                       "spindle speed used when spindle_override is true (> 0 clockwise)", VarKind::kSpindleInput));
  for (std::size_t i = 0; i < 3; ++i) {
    Variable in = variable("f" + std::string(axis_name(i)) + "_ext_N", Causality::kInput, "N",
                           "external force on the workpiece, added to the cutting force", VarKind::kForceInput);
    in.axis = i;
    v.push_back(in);
  }
}

/// The axes' and the process's outputs, the tool's when it vibrates, the block and the end of the program.
void add_outputs(std::vector<Variable>& v, const std::vector<Axis>& axes, bool vibrating_tool) {
  for (Axis a : axes) {
    for (const auto& o : kAxisOutputs) {
      Variable out = variable(std::string(axis_name(a)) + o.suffix, Causality::kOutput, fmi_unit(o.unit), o.doc,
                              VarKind::kAxisOutput);
      out.axis = index(a);
      out.axis_output = o.get;
      out.measured = o.measured;
      v.push_back(out);
    }
  }
  const auto add_output = [&v](const OutputSpec& o) {
    Variable out = variable(o.name, Causality::kOutput, fmi_unit(o.unit), o.doc, VarKind::kOutput);
    out.output = o.get;
    v.push_back(out);
  };
  for (const auto& o : kOutputs) add_output(o);
  if (vibrating_tool)
    for (const auto& o : kToolOutputs) add_output(o);
  v.push_back(unitless("block", VarType::kInteger, Causality::kOutput, Variability::kDiscrete,
                       "index of the program block in progress (-1 none)", VarKind::kBlockOutput));
  v.push_back(unitless("reference_done", VarType::kBoolean, Causality::kOutput, Variability::kDiscrete,
                       "true once the program's motion has finished", VarKind::kDoneOutput));
}

}  // namespace

std::vector<Variable> make_variables(const sim::MachineDefinition& machine, bool vibrating_tool) {
  std::vector<Variable> v;
  const std::vector<Axis> axes = machine.present_axes();
  add_parameters(v, machine, axes);
  add_inputs(v, axes);
  add_outputs(v, axes, vibrating_tool);
  return v;
}

}  // namespace twin::fmu
