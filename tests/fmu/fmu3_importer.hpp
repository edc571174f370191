#pragma once
// A minimal FMI 3.0 Co-Simulation importer for the tests, as fmu_importer.hpp
// is for FMI 2.0: unzips an .fmu, reads modelDescription.xml with regular
// expressions (independent of the generator in fmu/), dlopens
// binaries/x86_64-linux/<modelIdentifier>.so with RTLD_NOW and resolves
// every function of the FMI 3.0 common and Co-Simulation interface.
#include <string>
#include <vector>

#include "fmu/fmi3_api.h"
#include "fmu_importer.hpp"

namespace twin::fmu_test {

/// The function names an FMI 3.0 Co-Simulation FMU exports (common and
/// Co-Simulation functions of the standard; 64 in all).
const std::vector<std::string>& fmi3_function_names();

/// The functions the tests call, as X(name): the table below and its loader.
#define TWIN_FMI3_FUNCTIONS(X)                                                                                     \
  X(fmi3GetVersion) X(fmi3SetDebugLogging) X(fmi3InstantiateCoSimulation) X(fmi3InstantiateModelExchange)           \
  X(fmi3FreeInstance) X(fmi3EnterInitializationMode) X(fmi3ExitInitializationMode) X(fmi3EnterEventMode)            \
  X(fmi3EnterStepMode) X(fmi3Terminate) X(fmi3Reset) X(fmi3GetFloat64) X(fmi3SetFloat64) X(fmi3GetInt32)            \
  X(fmi3SetInt32) X(fmi3GetBoolean) X(fmi3SetBoolean) X(fmi3GetFloat32) X(fmi3GetFMUState) X(fmi3SetFMUState)       \
  X(fmi3FreeFMUState) X(fmi3SerializedFMUStateSize) X(fmi3SerializeFMUState) X(fmi3DeserializeFMUState)             \
  X(fmi3DoStep)

struct Fmi3Functions {
  TWIN_FMI3_FUNCTIONS(TWIN_FMU_FUNCTION_POINTER)
};

/// The loaded FMU.
class LoadedFmu3 : public UnzippedFmu {
 public:
  explicit LoadedFmu3(const std::string& fmu_path);

  const Fmi3Functions& fn() const { return fn_; }
  const std::string& token() const { return token_; }
  std::string so_path() const;
  /// resources/ as a folder path with a trailing slash (FMI 3.0, 2.2.1).
  std::string resource_path() const { return dir() + "/resources/"; }

  /// Instantiates for Co-Simulation with the file's token (or `token`).
  fmi3Instance instantiate(const std::string& name, const char* token = nullptr, bool logging_on = false);

 private:
  std::string token_;
  Fmi3Functions fn_;
};

}  // namespace twin::fmu_test
