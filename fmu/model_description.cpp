#include "fmu/model_description.hpp"

#include <cstdint>
#include <set>
#include <string_view>

#include <fmt/format.h>

#include "fmu/variables.hpp"

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
  const double stop = model.has_program() ? model.program_duration_s() : 1.0;
  std::string x;
  x += "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  x += fmt::format(
      "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"{}\" guid=\"{}\"\n"
      "  description=\"{}\"\n"
      "  generationTool=\"twin export-fmu\" variableNamingConvention=\"flat\" numberOfEventIndicators=\"0\">\n",
      xml_escape("MachineTwin " + model.scenario_name), kGuidPlaceholder,
      xml_escape(fmt::format("Digital twin of the {} milling machine (feed drives, position loops, interpolator, "
                             "cutting process), scenario {}. Communication steps are whole multiples of Ts = {} s.",
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
  for (const auto& u : units) x += fmt::format("    <Unit name=\"{}\"/>\n", xml_escape(u));
  x += "  </UnitDefinitions>\n";
  x += "  <LogCategories>\n"
       "    <Category name=\"logStatusError\" description=\"errors: the failing call, the value and the reason\"/>\n"
       "    <Category name=\"logStatusWarning\" description=\"warnings\"/>\n"
       "    <Category name=\"logCalls\" description=\"every fmi2 call that changes the state\"/>\n"
       "  </LogCategories>\n";
  x += fmt::format("  <DefaultExperiment startTime=\"0\" stopTime=\"{}\" stepSize=\"{}\"/>\n", real(stop),
                   real(10.0 * Ts));
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
  x += "  <ModelStructure>\n    <Outputs>\n";
  for (std::size_t idx : outputs) x += fmt::format("      <Unknown index=\"{}\"/>\n", idx);
  x += "    </Outputs>\n    <InitialUnknowns>\n";
  for (std::size_t idx : outputs) x += fmt::format("      <Unknown index=\"{}\"/>\n", idx);
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
