#pragma once
// A minimal FMI 3.0 Co-Simulation importer for the tests, as fmu_importer.hpp
// is for FMI 2.0: unzips an .fmu, reads modelDescription.xml with regular
// expressions (independent of the generator in fmu/), dlopens
// binaries/x86_64-linux/<modelIdentifier>.so with RTLD_NOW and resolves
// every function of the FMI 3.0 common and Co-Simulation interface.
#include <map>
#include <string>
#include <vector>

#include "fmu/fmi3_api.h"
#include "fmu_importer.hpp"

namespace twin::fmu_test {

/// The function names an FMI 3.0 Co-Simulation FMU exports (common and
/// Co-Simulation functions of the standard; 64 in all).
const std::vector<std::string>& fmi3_function_names();

struct Fmi3Functions {
#define TWIN_FMI3_FN(name) decltype(&::name) name{nullptr};
  TWIN_FMI3_FN(fmi3GetVersion) TWIN_FMI3_FN(fmi3SetDebugLogging) TWIN_FMI3_FN(fmi3InstantiateCoSimulation)
  TWIN_FMI3_FN(fmi3InstantiateModelExchange) TWIN_FMI3_FN(fmi3FreeInstance)
  TWIN_FMI3_FN(fmi3EnterInitializationMode) TWIN_FMI3_FN(fmi3ExitInitializationMode) TWIN_FMI3_FN(fmi3EnterEventMode)
  TWIN_FMI3_FN(fmi3EnterStepMode) TWIN_FMI3_FN(fmi3Terminate) TWIN_FMI3_FN(fmi3Reset) TWIN_FMI3_FN(fmi3GetFloat64)
  TWIN_FMI3_FN(fmi3SetFloat64) TWIN_FMI3_FN(fmi3GetInt32) TWIN_FMI3_FN(fmi3SetInt32) TWIN_FMI3_FN(fmi3GetBoolean)
  TWIN_FMI3_FN(fmi3SetBoolean) TWIN_FMI3_FN(fmi3GetFloat32) TWIN_FMI3_FN(fmi3GetFMUState)
  TWIN_FMI3_FN(fmi3SetFMUState) TWIN_FMI3_FN(fmi3FreeFMUState) TWIN_FMI3_FN(fmi3SerializedFMUStateSize)
  TWIN_FMI3_FN(fmi3SerializeFMUState) TWIN_FMI3_FN(fmi3DeserializeFMUState) TWIN_FMI3_FN(fmi3DoStep)
#undef TWIN_FMI3_FN
};

/// The loaded FMU. Throws std::runtime_error when anything is missing.
class LoadedFmu3 {
 public:
  explicit LoadedFmu3(const std::string& fmu_path);
  ~LoadedFmu3();
  LoadedFmu3(const LoadedFmu3&) = delete;
  LoadedFmu3& operator=(const LoadedFmu3&) = delete;

  const Fmi3Functions& fn() const { return fn_; }
  const std::string& dir() const { return dir_; }
  const std::string& xml() const { return xml_; }
  const std::string& token() const { return token_; }
  const std::string& model_identifier() const { return model_identifier_; }
  std::string so_path() const;
  /// resources/ as a folder path with a trailing slash (FMI 3.0, 2.2.1).
  std::string resource_path() const { return dir_ + "/resources/"; }
  /// Variables in document order; `type` is the element name (Float64, Int32, Boolean).
  const std::vector<VarInfo>& variables() const { return vars_; }
  const VarInfo& var(const std::string& name) const;
  bool has(const std::string& name) const { return by_name_.count(name) != 0; }
  std::string default_experiment(const std::string& attribute) const;

  /// Instantiates for Co-Simulation with the file's token (or `token`).
  fmi3Instance instantiate(const std::string& name, const char* token = nullptr, bool logging_on = false);
  const std::vector<std::string>& log() const { return log_; }
  void clear_log() { log_.clear(); }

 private:
  std::string dir_;
  std::string xml_;
  std::string token_;
  std::string model_identifier_;
  std::vector<VarInfo> vars_;
  std::map<std::string, std::size_t> by_name_;
  void* handle_{nullptr};
  Fmi3Functions fn_;
  std::vector<std::string> log_;
};

}  // namespace twin::fmu_test
