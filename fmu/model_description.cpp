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

/// The text with the GUID placeholder.
std::string xml_template(const FmuModel& model) {
  const std::vector<Variable> vars = make_variables(model.machine);
  const double Ts = model.machine.Ts_s;
  // The stop time on the tick grid: the end of the program plus settle_s,
  // rounded up to a whole tick, so that steps of any whole number of ticks
  // reach it exactly.
  const double stop_s = model.has_program() ? model.program_duration_s() : 1.0;
  const auto stop_ticks = static_cast<std::int64_t>(std::ceil(stop_s / Ts - 1e-9));
  std::string x;
  x += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  x += fmt::format(
      "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"{}\" guid=\"{}\"\n"
      "  description=\"{}\"\n"
      "  generationTool=\"twin export-fmu\" variableNamingConvention=\"flat\" numberOfEventIndicators=\"0\">\n",
      xml_escape("MachineTwin " + model.scenario_name), kGuidPlaceholder,
      xml_escape(fmt::format("Digital twin of the {} milling machine (feed drives, position loops, interpolator, "
                             "cutting process), scenario {}. The controller samples its inputs every Ts = {} s; communication steps "
                             "may end between its ticks.",
                             model.machine.name, model.scenario_name, Ts)));
  x += fmt::format(
      "  <CoSimulation modelIdentifier=\"{}\" needsExecutionTool=\"false\" "
      "canHandleVariableCommunicationStepSize=\"true\" canInterpolateInputs=\"false\" "
      "maxOutputDerivativeOrder=\"0\" canRunAsynchronuously=\"false\" canBeInstantiatedOnlyOncePerProcess=\"false\" "
      "canNotUseMemoryManagementFunctions=\"true\" canGetAndSetFMUstate=\"true\" canSerializeFMUstate=\"{}\" "
      "providesDirectionalDerivative=\"false\"/>\n",
      kModelIdentifier, model.has_process() ? "false" : "true");
  std::set<std::string> units;
  for (const auto& v : vars)
    if (!v.unit.empty()) units.insert(v.unit);
  x += "  <UnitDefinitions>\n";
  for (const auto& u : units) {
    const UnitDefinition* def = nullptr;
    for (const auto& d : unit_definitions())
      if (d.name == u) def = &d;
    if (def == nullptr) throw InternalError(fmt::format("fmu: unit '{}' has no definition", u));
    x += fmt::format("    <Unit name=\"{}\">{}</Unit>\n", xml_escape(u), base_unit(*def));
  }
  x += "  </UnitDefinitions>\n";
  x += "  <LogCategories>\n"
       "    <Category name=\"logStatusError\" description=\"errors: the failing call, the value and the reason\"/>\n"
       "    <Category name=\"logStatusFatal\" description=\"fatal errors: the model failed inside\"/>\n"
       "    <Category name=\"logStatusDiscard\" description=\"calls refused without a change (too long a step, "
       "a status not provided)\"/>\n"
       "    <Category name=\"logStatusWarning\" description=\"warnings (inputs the mode ignores)\"/>\n"
       "    <Category name=\"logCalls\" description=\"every fmi2 call that changes the state, with its "
       "arguments\"/>\n"
       "  </LogCategories>\n";
  x += fmt::format("  <DefaultExperiment startTime=\"0\" stopTime=\"{}\" stepSize=\"{}\"/>\n",
                   on_tick_grid(stop_ticks, Ts), on_tick_grid(10, Ts));
  x += "  <ModelVariables>\n";
  std::vector<std::size_t> outputs;
  for (std::size_t i = 0; i < vars.size(); ++i) {
    const Variable& v = vars[i];
    std::string attrs = fmt::format("name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{}\" variability=\"{}\"",
                                    xml_escape(v.name), i, xml_escape(v.description), causality_name(v.causality),
                                    variability_name(v.variability));
    if (v.causality == Causality::kParameter) attrs += " initial=\"exact\"";
    if (v.causality == Causality::kOutput) {
      attrs += " initial=\"calculated\"";
      outputs.push_back(i + 1);
    }
    const std::string start = start_attribute(v, model);
    std::string element;
    switch (v.type) {
      case VarType::kReal:
        element = "<Real" + (v.unit.empty() ? std::string() : " unit=\"" + xml_escape(v.unit) + "\"") + start + "/>";
        break;
      case VarType::kInteger: element = "<Integer" + start + "/>"; break;
      case VarType::kBoolean: element = "<Boolean" + start + "/>"; break;
    }
    x += fmt::format("    <!-- {} -->\n    <ScalarVariable {}>\n      {}\n    </ScalarVariable>\n", i + 1, attrs,
                     element);
  }
  x += "  </ModelVariables>\n";
  // Dependencies. After a step the outputs are the row of a tick computed in
  // that step, from the inputs set before it: no output depends on an input
  // set at the same communication point (no direct feedthrough), so each
  // lists none. Before the first step (initialization) the outputs are the
  // axes at rest at start_mm: the measured position and the tracking error
  // depend on the encoder resolution, the others on nothing.
  std::size_t encoder_index = 0;
  for (std::size_t i = 0; i < vars.size(); ++i)
    if (vars[i].kind == VarKind::kMachineParam && vars[i].name == "encoder_resolution") encoder_index = i + 1;
  if (encoder_index == 0) throw InternalError("fmu: no encoder_resolution parameter");
  auto initial_dependencies = [&](const Variable& v) {
    return v.measured ? std::to_string(encoder_index) : std::string();
  };
  x += "  <ModelStructure>\n    <Outputs>\n";
  for (std::size_t idx : outputs) x += fmt::format("      <Unknown index=\"{}\" dependencies=\"\"/>\n", idx);
  x += "    </Outputs>\n    <InitialUnknowns>\n";
  for (std::size_t idx : outputs)
    x += fmt::format("      <Unknown index=\"{}\" dependencies=\"{}\"/>\n", idx, initial_dependencies(vars[idx - 1]));
  x += "    </InitialUnknowns>\n  </ModelStructure>\n";
  x += "</fmiModelDescription>\n";
  return x;
}

std::string guid_of(const std::string& xml_template_text, const FmuModel& model) {
  const std::uint64_t a = fnv1a(model.model_json, fnv1a(xml_template_text, 14695981039346656037ull));
  const std::uint64_t b = fnv1a(xml_template_text, fnv1a(model.model_json, 0x84222325cbf29ce4ull ^ 0x5bd1e995ull));
  return fmt::format("{{{:08x}-{:04x}-{:04x}-{:04x}-{:012x}}}", a >> 32, (a >> 16) & 0xffffu, a & 0xffffu,
                     b >> 48, b & 0xffffffffffffull);
}

}  // namespace

std::string model_guid(const FmuModel& model) { return guid_of(xml_template(model), model); }

std::string model_description_xml(const FmuModel& model) {
  std::string x = xml_template(model);
  const std::string guid = guid_of(x, model);
  x.replace(x.find(kGuidPlaceholder), kGuidPlaceholder.size(), guid);
  return x;
}

}  // namespace twin::fmu
