#include "fmu/model_description.hpp"

#include <cmath>
#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <string_view>

#include <fmt/format.h>

#include "fmu/variables.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {
namespace {

constexpr std::string_view kGuidPlaceholder = "@GUID@";

std::string xml_escape(std::string_view s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

/// FNV-1a, 64 bit, from a given offset basis.
std::uint64_t fnv1a(std::string_view s, std::uint64_t h) {
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

const char* causality_name(Causality c) {
  switch (c) {
    case Causality::kParameter: return "parameter";
    case Causality::kInput: return "input";
    case Causality::kOutput: return "output";
  }
  return "local";
}
const char* variability_name(Variability v) {
  switch (v) {
    case Variability::kFixed: return "fixed";
    case Variability::kTunable: return "tunable";
    case Variability::kDiscrete: return "discrete";
    case Variability::kContinuous: return "continuous";
  }
  return "continuous";
}

std::string real(double v) { return fmt::format("{}", v); }

/// n Ts as text that reads back as n whole ticks: the shortest of 12
/// significant digits ("8.802" for 88020 x 1e-4) and the exact double.
std::string on_tick_grid(std::int64_t n, double Ts) {
  const double t = static_cast<double>(n) * Ts;
  const std::string short_text = fmt::format("{:.12g}", t);
  const double back = std::stod(short_text);
  return std::abs(back / Ts - static_cast<double>(n)) < 1e-6 ? short_text : real(t);
}

/// The text of a BaseUnit element for `u` (SI exponents and factor).
std::string base_unit(const UnitDefinition& u) {
  std::string a;
  const std::pair<const char*, int> exps[] = {{"kg", u.kg}, {"m", u.m}, {"s", u.s}, {"A", u.A}, {"rad", u.rad}};
  for (const auto& [name, e] : exps)
    if (e != 0) a += fmt::format(" {}=\"{}\"", name, e);
  if (u.factor != 1.0) a += fmt::format(" factor=\"{}\"", u.factor);
  return "<BaseUnit" + a + "/>";
}

std::string start_attribute(const Variable& v, const FmuModel& model) {
  switch (v.kind) {
    case VarKind::kMode: return fmt::format(" start=\"{}\"", model.has_program() ? kModeProgram : kModeExternal);
    case VarKind::kMachineParam:
    case VarKind::kAxisParam: return " start=\"" + real(get_parameter(v, model.machine)) + "\"";
    case VarKind::kRefInput: return " start=\"" + real(model.start_mm[v.axis]) + "\"";
    case VarKind::kSpindleOverride: return " start=\"false\"";
    case VarKind::kSpindleInput:
    case VarKind::kForceInput: return " start=\"0\"";
    default: return {};
  }
}

/// UnitDefinitions: every unit a variable uses, with its SI base units
/// (the same element in FMI 2.0 and 3.0).
std::string unit_definitions_xml(const std::vector<Variable>& vars) {
  std::set<std::string> units;
  for (const auto& v : vars)
    if (!v.unit.empty()) units.insert(v.unit);
  std::string x = "  <UnitDefinitions>\n";
  for (const auto& u : units) {
    const UnitDefinition* def = nullptr;
    for (const auto& d : unit_definitions())
      if (d.name == u) def = &d;
    if (def == nullptr) throw InternalError(fmt::format("fmu: unit '{}' has no definition", u));
    x += fmt::format("    <Unit name=\"{}\">{}</Unit>\n", xml_escape(u), base_unit(*def));
  }
  return x + "  </UnitDefinitions>\n";
}

std::string log_categories_xml(const char* prefix) {
  return fmt::format(
      "  <LogCategories>\n"
      "    <Category name=\"logStatusError\" description=\"errors: the failing call, the value and the reason\"/>\n"
      "    <Category name=\"logStatusFatal\" description=\"fatal errors: the model failed inside\"/>\n"
      "    <Category name=\"logStatusDiscard\" description=\"calls refused without a change (too long a step, "
      "a status not provided)\"/>\n"
      "    <Category name=\"logStatusWarning\" description=\"warnings (inputs the mode ignores)\"/>\n"
      "    <Category name=\"logCalls\" description=\"every {} call that changes the state, with its "
      "arguments\"/>\n"
      "  </LogCategories>\n",
      prefix);
}

/// DefaultExperiment: the stop time on the tick grid (the end of the program
/// plus settle_s, rounded up to a whole tick, so that steps of any whole
/// number of ticks reach it exactly), steps of 10 ticks.
std::string default_experiment_xml(const FmuModel& model) {
  const double Ts = model.machine.Ts_s;
  const double stop_s = model.has_program() ? model.program_duration_s() : 1.0;
  const auto stop_ticks = static_cast<std::int64_t>(std::ceil(stop_s / Ts - 1e-9));
  return fmt::format("  <DefaultExperiment startTime=\"0\" stopTime=\"{}\" stepSize=\"{}\"/>\n",
                     on_tick_grid(stop_ticks, Ts), on_tick_grid(10, Ts));
}

/// The XML declaration and the opening fmiModelDescription element (the
/// identity attribute `token_name` holds the placeholder).
std::string xml_head(const FmuModel& model, const char* version, const char* token_name, const char* steps,
                     const char* extra) {
  return fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<fmiModelDescription fmiVersion=\"{}\" modelName=\"{}\" {}=\"{}\"\n"
      "  description=\"{}\"\n"
      "  generationTool=\"twin export-fmu\" variableNamingConvention=\"flat\"{}>\n",
      version, xml_escape("MachineTwin " + model.name), token_name, kGuidPlaceholder,
      xml_escape(fmt::format("Digital twin of the {} milling machine (feed drives, position loops, interpolator, "
                             "cutting process), scenario {}. The controller samples its inputs every Ts = {} s; {}.",
                             model.machine.name, model.name, model.machine.Ts_s, steps)),
      extra);
}

/// The attributes every variable has in both versions (value reference = row).
std::string variable_attributes(const Variable& v, std::size_t vr) {
  std::string a = fmt::format("name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{}\" variability=\"{}\"",
                              xml_escape(v.name), vr, xml_escape(v.description), causality_name(v.causality),
                              variability_name(v.variability));
  if (v.causality == Causality::kParameter) a += " initial=\"exact\"";
  if (v.causality == Causality::kOutput) a += " initial=\"calculated\"";
  return a;
}

/// Dependencies at initialization. After a step the outputs are the row of
/// a tick computed in that step, from the inputs set before it: no output
/// depends on an input set at the same communication point (no direct
/// feedthrough), so each lists none. Before the first step (initialization)
/// the outputs are the axes at rest at start_mm: the measured position and
/// the tracking error depend on the encoder resolution (the row returned),
/// the others on nothing.
std::size_t encoder_row(const std::vector<Variable>& vars) {
  for (std::size_t i = 0; i < vars.size(); ++i)
    if (vars[i].kind == VarKind::kMachineParam && vars[i].name == "encoder_resolution") return i;
  throw InternalError("fmu: no encoder_resolution parameter");
}

/// FMI 2.0: ScalarVariable elements, ModelStructure by index (row + 1).
std::string xml_template_fmi2(const FmuModel& model) {
  const std::vector<Variable> vars = make_variables(model.machine, sim::vibrating_tool(model));
  std::string x = xml_head(model, "2.0", "guid", "communication steps may end between its ticks",
                           " numberOfEventIndicators=\"0\"");
  x += fmt::format(
      "  <CoSimulation modelIdentifier=\"{}\" needsExecutionTool=\"false\" "
      "canHandleVariableCommunicationStepSize=\"true\" canInterpolateInputs=\"false\" "
      "maxOutputDerivativeOrder=\"0\" canRunAsynchronuously=\"false\" canBeInstantiatedOnlyOncePerProcess=\"false\" "
      "canNotUseMemoryManagementFunctions=\"true\" canGetAndSetFMUstate=\"true\" canSerializeFMUstate=\"{}\" "
      "providesDirectionalDerivative=\"false\"/>\n",
      kModelIdentifier, model.has_process() ? "false" : "true");
  x += unit_definitions_xml(vars) + log_categories_xml("fmi2") + default_experiment_xml(model);
  x += "  <ModelVariables>\n";
  std::vector<std::size_t> outputs;
  for (std::size_t i = 0; i < vars.size(); ++i) {
    const Variable& v = vars[i];
    if (v.causality == Causality::kOutput) outputs.push_back(i + 1);
    const std::string start = start_attribute(v, model);
    std::string element;
    switch (v.type) {
      case VarType::kReal:
        element = "<Real" + (v.unit.empty() ? std::string() : " unit=\"" + xml_escape(v.unit) + "\"") + start + "/>";
        break;
      case VarType::kInteger: element = "<Integer" + start + "/>"; break;
      case VarType::kBoolean: element = "<Boolean" + start + "/>"; break;
    }
    x += fmt::format("    <!-- {} -->\n    <ScalarVariable {}>\n      {}\n    </ScalarVariable>\n", i + 1,
                     variable_attributes(v, i), element);
  }
  x += "  </ModelVariables>\n";
  const std::string encoder_index = std::to_string(encoder_row(vars) + 1);
  x += "  <ModelStructure>\n    <Outputs>\n";
  for (std::size_t idx : outputs) x += fmt::format("      <Unknown index=\"{}\" dependencies=\"\"/>\n", idx);
  x += "    </Outputs>\n    <InitialUnknowns>\n";
  for (std::size_t idx : outputs)
    x += fmt::format("      <Unknown index=\"{}\" dependencies=\"{}\"/>\n", idx,
                     vars[idx - 1].measured ? encoder_index : std::string());
  x += "    </InitialUnknowns>\n  </ModelStructure>\n";
  x += "</fmiModelDescription>\n";
  return x;
}

/// FMI 3.0: one element per type (Float64, Int32, Boolean) in value
/// reference order, the independent variable `time` after the table, and
/// ModelStructure by value reference.
std::string xml_template_fmi3(const FmuModel& model) {
  const std::vector<Variable> vars = make_variables(model.machine, sim::vibrating_tool(model));
  const double Ts = model.machine.Ts_s;
  std::string x =
      xml_head(model, "3.0", "instantiationToken", "every communication step is a whole number of its ticks", "");
  x += fmt::format(
      "  <CoSimulation modelIdentifier=\"{}\" needsExecutionTool=\"false\" "
      "canBeInstantiatedOnlyOncePerProcess=\"false\" canGetAndSetFMUState=\"true\" canSerializeFMUState=\"{}\" "
      "providesDirectionalDerivatives=\"false\" providesAdjointDerivatives=\"false\" "
      "canHandleVariableCommunicationStepSize=\"true\" fixedInternalStepSize=\"{}\" maxOutputDerivativeOrder=\"0\" "
      "providesIntermediateUpdate=\"false\" mightReturnEarlyFromDoStep=\"false\" hasEventMode=\"false\"/>\n",
      kModelIdentifier, model.has_process() ? "false" : "true", real(Ts));
  x += unit_definitions_xml(vars) + log_categories_xml("fmi3") + default_experiment_xml(model);
  x += "  <ModelVariables>\n";
  std::vector<std::size_t> outputs;
  for (std::size_t i = 0; i < vars.size(); ++i) {
    const Variable& v = vars[i];
    if (v.causality == Causality::kOutput) outputs.push_back(i);
    const char* element = v.type == VarType::kReal ? "Float64" : (v.type == VarType::kInteger ? "Int32" : "Boolean");
    const std::string unit = v.unit.empty() ? std::string() : " unit=\"" + xml_escape(v.unit) + "\"";
    x += fmt::format("    <{} {}{}{}/>\n", element, variable_attributes(v, i), unit, start_attribute(v, model));
  }
  x += fmt::format("    <Float64 name=\"time\" valueReference=\"{}\" description=\"simulation time\" "
                   "causality=\"independent\" variability=\"continuous\" unit=\"s\"/>\n",
                   time_value_reference(model));
  x += "  </ModelVariables>\n";
  const std::string encoder_vr = std::to_string(encoder_row(vars));
  x += "  <ModelStructure>\n";
  for (std::size_t vr : outputs) x += fmt::format("    <Output valueReference=\"{}\" dependencies=\"\"/>\n", vr);
  for (std::size_t vr : outputs)
    x += fmt::format("    <InitialUnknown valueReference=\"{}\" dependencies=\"{}\"/>\n", vr,
                     vars[vr].measured ? encoder_vr : std::string());
  x += "  </ModelStructure>\n";
  x += "</fmiModelDescription>\n";
  return x;
}

std::string xml_template(const FmuModel& model, FmiVersion version) {
  return version == FmiVersion::k3 ? xml_template_fmi3(model) : xml_template_fmi2(model);
}

std::string guid_of(const std::string& xml_template_text, const FmuModel& model) {
  const std::uint64_t a = fnv1a(model.model_json, fnv1a(xml_template_text, 14695981039346656037ull));
  const std::uint64_t b = fnv1a(xml_template_text, fnv1a(model.model_json, 0x84222325cbf29ce4ull ^ 0x5bd1e995ull));
  return fmt::format("{{{:08x}-{:04x}-{:04x}-{:04x}-{:012x}}}", a >> 32, (a >> 16) & 0xffffu, a & 0xffffu,
                     b >> 48, b & 0xffffffffffffull);
}

}  // namespace

std::size_t time_value_reference(const FmuModel& model) {
  return make_variables(model.machine, sim::vibrating_tool(model)).size();
}

std::string model_guid(const FmuModel& model) { return guid_of(xml_template(model, FmiVersion::k2), model); }

std::string instantiation_token(const FmuModel& model) {
  return guid_of(xml_template(model, FmiVersion::k3), model);
}

std::string model_description_xml(const FmuModel& model, FmiVersion version) {
  std::string x = xml_template(model, version);
  const std::string guid = guid_of(x, model);
  x.replace(x.find(kGuidPlaceholder), kGuidPlaceholder.size(), guid);
  return x;
}

}  // namespace twin::fmu
