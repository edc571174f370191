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

/// Every fmi2 function of the standard, as X(name): the table below and its loader.
#define TWIN_FMI2_FUNCTIONS(X)                                                                                   \
  X(fmi2GetTypesPlatform) X(fmi2GetVersion) X(fmi2SetDebugLogging) X(fmi2Instantiate) X(fmi2FreeInstance)         \
  X(fmi2SetupExperiment) X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate)            \
  X(fmi2Reset) X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal)                 \
  X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate)                      \
  X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate)           \
  X(fmi2GetDirectionalDerivative) X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep)    \
  X(fmi2CancelStep) X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus)         \
  X(fmi2GetStringStatus)

/// A pointer per function, resolved by name.
#define TWIN_FMU_FUNCTION_POINTER(name) decltype(&::name) name{nullptr};

struct Fmi2Functions {
  TWIN_FMI2_FUNCTIONS(TWIN_FMU_FUNCTION_POINTER)
};

/// What the FMI 2.0 and 3.0 importers share: the FMU unzipped into a fresh
/// folder (removed again with the object), its modelDescription.xml, the
/// variables read from it, the binary loaded with RTLD_NOW and what the FMU
/// logged. Throws std::runtime_error when anything is missing.
class UnzippedFmu {
 public:
  ~UnzippedFmu();
  UnzippedFmu(const UnzippedFmu&) = delete;
  UnzippedFmu& operator=(const UnzippedFmu&) = delete;

  const std::string& dir() const { return dir_; }
  const std::string& model_identifier() const { return model_identifier_; }
  const std::string& xml() const { return xml_; }
  const std::vector<VarInfo>& variables() const { return vars_; }
  const VarInfo& var(const std::string& name) const;
  bool has(const std::string& name) const { return by_name_.count(name) != 0; }

  /// DefaultExperiment attribute (stopTime, stepSize, ...) as text; empty when absent.
  std::string default_experiment(const std::string& attribute) const;

  const std::vector<std::string>& log() const { return log_; }
  void clear_log() { log_.clear(); }

 protected:
  explicit UnzippedFmu(const std::string& fmu_path);
  /// The opening tag of the first `tag` element of the model description.
  std::string element(const std::string& tag) const;
  void add_variable(const VarInfo& v);
  /// dlopens the binary at `so_path`.
  void load_binary(const std::string& so_path);
  /// The exported function `name`; throws when the binary does not export it.
  void* symbol(const std::string& name) const;

  std::string model_identifier_;
  std::vector<std::string> log_;

 private:
  std::string dir_;
  std::string xml_;
  std::vector<VarInfo> vars_;
  std::map<std::string, std::size_t> by_name_;
  void* handle_{nullptr};
};

/// Expects resources/ of the FMU to hold the scenario it was exported with
/// (model.json, machine.yaml, scenario.yaml).
void expect_scenario_resources(const UnzippedFmu& fmu);

/// Expects the FMU's modelDescription.xml to validate against the schema `xsd`.
void expect_valid_model_description(const UnzippedFmu& fmu, const std::string& xsd);

/// Expects the binary at `so_path` to need only the C and C++ runtime (ldd),
/// as on a machine without the project's dependencies.
void expect_only_the_c_runtime_needed(const std::string& so_path);

/// `bytes` := state `st` of instance `c` serialized (both calls fmi2OK).
void serialize_state(const Fmi2Functions& f, fmi2Component c, fmi2FMUstate st, std::vector<fmi2Byte>& bytes);

/// The loaded FMU.
class LoadedFmu : public UnzippedFmu {
 public:
  explicit LoadedFmu(const std::string& fmu_path);

  const Fmi2Functions& fn() const { return fn_; }
  const std::string& guid() const { return guid_; }
  std::string so_path() const;
  std::string resource_uri() const { return "file://" + dir() + "/resources"; }

  /// Instantiates with the file's GUID (or `guid`) and its resources (or
  /// those at the file: URI `resources`); messages go to log().
  fmi2Component instantiate(const std::string& name, const char* guid = nullptr, bool logging_on = false,
                            const std::string& resources = {});

 private:
  std::string guid_;
  Fmi2Functions fn_;
  fmi2CallbackFunctions callbacks_{};
};

}  // namespace twin::fmu_test
