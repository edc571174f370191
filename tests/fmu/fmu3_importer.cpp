#include "fmu3_importer.hpp"

#include <dlfcn.h>

#include <filesystem>
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

LoadedFmu3::LoadedFmu3(const std::string& fmu_path) {
  dir_ = extract_fmu(fmu_path);
  xml_ = read_text_file(dir_ + "/modelDescription.xml");
  std::smatch m;
  if (!std::regex_search(xml_, m, std::regex("<fmiModelDescription[^>]*>")))
    throw std::runtime_error("no fmiModelDescription element");
  if (xml_attribute(m[0], "fmiVersion") != "3.0") throw std::runtime_error("fmiVersion is not 3.0");
  token_ = xml_attribute(m[0], "instantiationToken");
  if (!std::regex_search(xml_, m, std::regex("<CoSimulation[^>]*>"))) throw std::runtime_error("no CoSimulation element");
  model_identifier_ = xml_attribute(m[0], "modelIdentifier");
  const std::regex var("<(Float64|Int32|Boolean|Float32|String)\\s([^>]*)/>");
  for (auto it = std::sregex_iterator(xml_.begin(), xml_.end(), var); it != std::sregex_iterator(); ++it) {
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
    by_name_[v.name] = vars_.size();
    vars_.push_back(v);
  }
  handle_ = ::dlopen(so_path().c_str(), RTLD_NOW | RTLD_LOCAL);
  if (handle_ == nullptr) throw std::runtime_error(std::string("dlopen: ") + ::dlerror());
  for (const auto& name : fmi3_function_names())
    if (::dlsym(handle_, name.c_str()) == nullptr) throw std::runtime_error("the FMU does not export " + name);
#define TWIN_FMI3_LOAD(name) fn_.name = reinterpret_cast<decltype(fn_.name)>(::dlsym(handle_, #name));
  TWIN_FMI3_LOAD(fmi3GetVersion) TWIN_FMI3_LOAD(fmi3SetDebugLogging) TWIN_FMI3_LOAD(fmi3InstantiateCoSimulation)
  TWIN_FMI3_LOAD(fmi3InstantiateModelExchange) TWIN_FMI3_LOAD(fmi3FreeInstance)
  TWIN_FMI3_LOAD(fmi3EnterInitializationMode) TWIN_FMI3_LOAD(fmi3ExitInitializationMode)
  TWIN_FMI3_LOAD(fmi3EnterEventMode) TWIN_FMI3_LOAD(fmi3EnterStepMode) TWIN_FMI3_LOAD(fmi3Terminate)
  TWIN_FMI3_LOAD(fmi3Reset) TWIN_FMI3_LOAD(fmi3GetFloat64) TWIN_FMI3_LOAD(fmi3SetFloat64) TWIN_FMI3_LOAD(fmi3GetInt32)
  TWIN_FMI3_LOAD(fmi3SetInt32) TWIN_FMI3_LOAD(fmi3GetBoolean) TWIN_FMI3_LOAD(fmi3SetBoolean)
  TWIN_FMI3_LOAD(fmi3GetFloat32) TWIN_FMI3_LOAD(fmi3GetFMUState) TWIN_FMI3_LOAD(fmi3SetFMUState)
  TWIN_FMI3_LOAD(fmi3FreeFMUState) TWIN_FMI3_LOAD(fmi3SerializedFMUStateSize) TWIN_FMI3_LOAD(fmi3SerializeFMUState)
  TWIN_FMI3_LOAD(fmi3DeserializeFMUState) TWIN_FMI3_LOAD(fmi3DoStep)
#undef TWIN_FMI3_LOAD
}

LoadedFmu3::~LoadedFmu3() {
  if (handle_ != nullptr) ::dlclose(handle_);
  std::error_code ec;
  std::filesystem::remove_all(dir_, ec);
}

std::string LoadedFmu3::so_path() const { return dir_ + "/binaries/x86_64-linux/" + model_identifier_ + ".so"; }

const VarInfo& LoadedFmu3::var(const std::string& name) const {
  const auto it = by_name_.find(name);
  if (it == by_name_.end()) throw std::runtime_error("no variable " + name);
  return vars_[it->second];
}

std::string LoadedFmu3::default_experiment(const std::string& attribute) const {
  return default_experiment_attribute(xml_, attribute);
}

fmi3Instance LoadedFmu3::instantiate(const std::string& name, const char* token, bool logging_on) {
  return fn_.fmi3InstantiateCoSimulation(name.c_str(), token ? token : token_.c_str(), resource_path().c_str(),
                                         fmi3False, logging_on, fmi3False, fmi3False, nullptr, 0, &log_, &logger,
                                         nullptr);
}

}  // namespace twin::fmu_test
