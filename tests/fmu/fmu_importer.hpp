#pragma once
// A minimal FMI 2.0 Co-Simulation importer for the tests: unzips an .fmu,
// reads modelDescription.xml with regular expressions (independent of the
// generator in fmu/), dlopens the binary with RTLD_NOW and resolves every
// fmi2 function, as a system-level master would.
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "fmu/fmi2_api.h"

namespace twin::fmu_test {

struct VarInfo {
  std::string name;
  unsigned vr{0};
  std::string type;        // Real, Integer, Boolean
  std::string causality;
  std::string variability;
  std::string initial;
  std::string unit;
  std::string start;
};

/// Unzips `fmu` into a fresh folder and returns it.
std::string extract_fmu(const std::string& fmu);

/// What `twin export-fmu` said when it failed to write `fmu` at build time
/// (tests/fmu/export_fmu.cmake leaves it in FMU.error); empty when it worked.
std::string export_error(const std::string& fmu);

/// Fails the test (with the export's message) unless `path` was exported.
#define REQUIRE_EXPORTED(path)                                                 \
  do {                                                                         \
    const std::string err = ::twin::fmu_test::export_error(path);              \
    ASSERT_TRUE(err.empty()) << err;                                           \
    ASSERT_TRUE(std::filesystem::exists(path)) << path << " was not exported"; \
  } while (false)

/// Runs a shell command; returns its exit status and fills `out` (stdout+stderr).
int run(const std::string& cmd, std::string& out);

/// Validates `xml_file` with xmllint against `xsd` (a path); returns the exit
/// status (0: valid) and fills `out` with what xmllint said.
int validate_with_xsd(const std::string& xsd, const std::string& xml_file, std::string& out);

/// The command that runs python3 on an FMU. In the sanitizer build the FMU
/// takes its sanitizer runtime from the host, so python3 gets the shared one
/// preloaded (python's own allocations are not the project's: no leak check).
std::string python3();

/// The value of attribute `name` in the text of one XML element ("" if absent).
std::string xml_attribute(const std::string& element, const std::string& name);
/// Attribute `name` of the DefaultExperiment element of `xml` ("" if absent).
std::string default_experiment_attribute(const std::string& xml, const std::string& name);
/// The text of a file ("" when it cannot be read).
std::string read_text_file(const std::string& path);

struct Fmi2Functions {
#define TWIN_FMI2_FN(name) decltype(&::name) name{nullptr};
  TWIN_FMI2_FN(fmi2GetTypesPlatform) TWIN_FMI2_FN(fmi2GetVersion) TWIN_FMI2_FN(fmi2SetDebugLogging)
  TWIN_FMI2_FN(fmi2Instantiate) TWIN_FMI2_FN(fmi2FreeInstance) TWIN_FMI2_FN(fmi2SetupExperiment)
  TWIN_FMI2_FN(fmi2EnterInitializationMode) TWIN_FMI2_FN(fmi2ExitInitializationMode) TWIN_FMI2_FN(fmi2Terminate)
  TWIN_FMI2_FN(fmi2Reset) TWIN_FMI2_FN(fmi2GetReal) TWIN_FMI2_FN(fmi2GetInteger) TWIN_FMI2_FN(fmi2GetBoolean)
  TWIN_FMI2_FN(fmi2GetString) TWIN_FMI2_FN(fmi2SetReal) TWIN_FMI2_FN(fmi2SetInteger) TWIN_FMI2_FN(fmi2SetBoolean)
  TWIN_FMI2_FN(fmi2SetString) TWIN_FMI2_FN(fmi2GetFMUstate) TWIN_FMI2_FN(fmi2SetFMUstate)
  TWIN_FMI2_FN(fmi2FreeFMUstate) TWIN_FMI2_FN(fmi2SerializedFMUstateSize) TWIN_FMI2_FN(fmi2SerializeFMUstate)
  TWIN_FMI2_FN(fmi2DeSerializeFMUstate) TWIN_FMI2_FN(fmi2GetDirectionalDerivative)
  TWIN_FMI2_FN(fmi2SetRealInputDerivatives) TWIN_FMI2_FN(fmi2GetRealOutputDerivatives) TWIN_FMI2_FN(fmi2DoStep)
  TWIN_FMI2_FN(fmi2CancelStep) TWIN_FMI2_FN(fmi2GetStatus) TWIN_FMI2_FN(fmi2GetRealStatus)
  TWIN_FMI2_FN(fmi2GetIntegerStatus) TWIN_FMI2_FN(fmi2GetBooleanStatus) TWIN_FMI2_FN(fmi2GetStringStatus)
#undef TWIN_FMI2_FN
};

/// The loaded FMU. Throws std::runtime_error when anything is missing.
class LoadedFmu {
 public:
  explicit LoadedFmu(const std::string& fmu_path);
  ~LoadedFmu();
  LoadedFmu(const LoadedFmu&) = delete;
  LoadedFmu& operator=(const LoadedFmu&) = delete;

  const Fmi2Functions& fn() const { return fn_; }
  const std::string& dir() const { return dir_; }
  const std::string& guid() const { return guid_; }
  const std::string& model_identifier() const { return model_identifier_; }
  const std::string& xml() const { return xml_; }
  std::string so_path() const;
  std::string resource_uri() const { return "file://" + dir_ + "/resources"; }
  const std::vector<VarInfo>& variables() const { return vars_; }
  const VarInfo& var(const std::string& name) const;
  bool has(const std::string& name) const { return by_name_.count(name) != 0; }

  /// DefaultExperiment attribute (stopTime, stepSize, ...) as text; empty when absent.
  std::string default_experiment(const std::string& attribute) const;

  /// Instantiates with the file's GUID (or `guid`) and its resources (or
  /// those at the file: URI `resources`); messages go to log().
  fmi2Component instantiate(const std::string& name, const char* guid = nullptr, bool logging_on = false,
                            const std::string& resources = {});
  const std::vector<std::string>& log() const { return log_; }
  void clear_log() { log_.clear(); }

 private:
  std::string dir_;
  std::string xml_;
  std::string guid_;
  std::string model_identifier_;
  std::vector<VarInfo> vars_;
  std::map<std::string, std::size_t> by_name_;
  void* handle_{nullptr};
  Fmi2Functions fn_;
  fmi2CallbackFunctions callbacks_{};
  std::vector<std::string> log_;
};

}  // namespace twin::fmu_test
