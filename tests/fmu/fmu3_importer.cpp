#include "fmu3_importer.hpp"

#include <regex>
#include <stdexcept>

namespace twin::fmu_test {
namespace {

void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
  auto* log = static_cast<std::vector<std::string>*>(env);
  log->push_back("[" + std::to_string(static_cast<int>(status)) + "] " + (category ? category : "") + ": " +
                 (message ? message : ""));
}

}  // namespace

const std::vector<std::string>& fmi3_function_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n{"fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateModelExchange",
                               "fmi3InstantiateCoSimulation", "fmi3InstantiateScheduledExecution",
                               "fmi3FreeInstance", "fmi3EnterInitializationMode", "fmi3ExitInitializationMode",
                               "fmi3EnterEventMode", "fmi3Terminate", "fmi3Reset"};
    for (const char* t : {"Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64",
                          "UInt64", "Boolean", "String", "Binary", "Clock"}) {
      n.push_back(std::string("fmi3Get") + t);
      n.push_back(std::string("fmi3Set") + t);
    }
    for (const char* f : {"GetNumberOfVariableDependencies", "GetVariableDependencies", "GetFMUState", "SetFMUState",
                          "FreeFMUState", "SerializedFMUStateSize", "SerializeFMUState", "DeserializeFMUState",
                          "GetDirectionalDerivative", "GetAdjointDerivative", "EnterConfigurationMode",
                          "ExitConfigurationMode", "GetIntervalDecimal", "GetIntervalFraction", "GetShiftDecimal",
                          "GetShiftFraction", "SetIntervalDecimal", "SetIntervalFraction", "SetShiftDecimal",
                          "SetShiftFraction", "EvaluateDiscreteStates", "UpdateDiscreteStates", "EnterStepMode",
                          "GetOutputDerivatives", "DoStep"})
      n.push_back(std::string("fmi3") + f);
    return n;
  }();
  return names;
}

LoadedFmu3::LoadedFmu3(const std::string& fmu_path) : UnzippedFmu(fmu_path) {
  const std::string root = element("fmiModelDescription");
  if (xml_attribute(root, "fmiVersion") != "3.0") throw std::runtime_error("fmiVersion is not 3.0");
  token_ = xml_attribute(root, "instantiationToken");
  model_identifier_ = xml_attribute(element("CoSimulation"), "modelIdentifier");
  const std::regex var("<(Float64|Int32|Boolean|Float32|String)\\s([^>]*)/>");
  for (auto it = std::sregex_iterator(xml().begin(), xml().end(), var); it != std::sregex_iterator(); ++it) {
    const std::string a = " " + (*it)[2].str();
    VarInfo v;
    v.type = (*it)[1];
    v.name = xml_attribute(a, "name");
    v.vr = static_cast<unsigned>(std::stoul(xml_attribute(a, "valueReference")));
    v.causality = xml_attribute(a, "causality");
    v.variability = xml_attribute(a, "variability");
    v.initial = xml_attribute(a, "initial");
    v.unit = xml_attribute(a, "unit");
    v.start = xml_attribute(a, "start");
    add_variable(v);
  }
  load_binary(so_path());
  for (const auto& name : fmi3_function_names()) symbol(name);
#define TWIN_FMI3_LOAD(name) fn_.name = reinterpret_cast<decltype(fn_.name)>(symbol(#name));
  TWIN_FMI3_FUNCTIONS(TWIN_FMI3_LOAD)
#undef TWIN_FMI3_LOAD
}

std::string LoadedFmu3::so_path() const { return dir() + "/binaries/x86_64-linux/" + model_identifier_ + ".so"; }

fmi3Instance LoadedFmu3::instantiate(const std::string& name, const char* token, bool logging_on) {
  return fn_.fmi3InstantiateCoSimulation(name.c_str(), token ? token : token_.c_str(), resource_path().c_str(),
                                         fmi3False, logging_on, fmi3False, fmi3False, nullptr, 0, &log_, &logger,
                                         nullptr);
}

}  // namespace twin::fmu_test
