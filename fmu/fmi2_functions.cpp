// The exported FMI 2.0 Co-Simulation entry points. Each goes through
// guarded(): no exception crosses the C boundary; a failed call logs one line
// and moves the instance to the error state.
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <string>

#include "fmu/fmi2_api.h"
#include "fmu/instance.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::fmu::FmuInstance;
using twin::fmu::FmuMode;
using twin::fmu::SavedState;

struct Component {
  std::string name;
  fmi2CallbackFunctions callbacks{};
  bool logging{false};
  std::unique_ptr<FmuInstance> fmu;
};

void log_message(const fmi2CallbackFunctions* cb, const char* instance, fmi2Status status, const char* category,
                 const std::string& message) {
  if (cb == nullptr || cb->logger == nullptr) return;
  cb->logger(cb->componentEnvironment, instance, status, category, "%s", message.c_str());
}

void log_error(Component& c, fmi2Status status, const char* function, const char* what) {
  log_message(&c.callbacks, c.name.c_str(), status, "logStatusError", std::string(function) + ": " + what);
}

template <class F>
fmi2Status guarded(fmi2Component handle, const char* function, F&& f) noexcept {
  auto* c = static_cast<Component*>(handle);
  if (c == nullptr) return fmi2Error;
  try {
    return f(*c);
  } catch (const twin::InternalError& e) {
    c->fmu->fail();
    log_error(*c, fmi2Fatal, function, e.what());
    return fmi2Fatal;
  } catch (const std::exception& e) {
    c->fmu->fail();
    log_error(*c, fmi2Error, function, e.what());
    return fmi2Error;
  } catch (...) {
    c->fmu->fail();
    log_error(*c, fmi2Fatal, function, "unknown exception");
    return fmi2Fatal;
  }
}

/// "file:///a/b/resources", "file:/a/b/resources/", "file://localhost/a/b" -> "/a/b/...".
std::string path_from_uri(const std::string& uri) {
  std::string p = uri;
  if (p.rfind("file://localhost/", 0) == 0) p = p.substr(16);
  else if (p.rfind("file:///", 0) == 0) p = p.substr(7);
  else if (p.rfind("file:/", 0) == 0) p = p.substr(5);
  else if (p.rfind("file:", 0) == 0 || p.find("://") != std::string::npos)
    throw twin::ConfigError("fmuResourceLocation '" + uri + "' is not a file: URI");
  std::string out;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p[i] == '%' && i + 2 < p.size()) {
      out += static_cast<char>(std::stoi(p.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += p[i];
    }
  }
  while (out.size() > 1 && out.back() == '/') out.pop_back();
  return out;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw twin::IoError("cannot read " + path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

template <class T, class Get>
fmi2Status get_values(fmi2Component c, const char* function, const fmi2ValueReference vr[], size_t nvr, T value[],
                      Get get) {
  return guarded(c, function, [&](Component& comp) {
    comp.fmu->require(function, {FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated, FmuMode::kError});
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError(std::string(function) + ": null array");
    for (size_t i = 0; i < nvr; ++i) value[i] = get(*comp.fmu, vr[i]);
    return fmi2OK;
  });
}

template <class T, class Set>
fmi2Status set_values(fmi2Component c, const char* function, const fmi2ValueReference vr[], size_t nvr, const T value[],
                      Set set) {
  return guarded(c, function, [&](Component& comp) {
    comp.fmu->require(function, {FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode});
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError(std::string(function) + ": null array");
    for (size_t i = 0; i < nvr; ++i) set(*comp.fmu, vr[i], value[i]);
    return fmi2OK;
  });
}

/// An optional function the FMU does not provide: fmi2Error and a log line,
/// the instance stays usable.
fmi2Status unsupported(fmi2Component c, const char* function, const char* why) noexcept {
  auto* comp = static_cast<Component*>(c);
  if (comp != nullptr) log_error(*comp, fmi2Error, function, (std::string("not supported: ") + why).c_str());
  return fmi2Error;
}

std::size_t num_parameters(const FmuInstance& f) {
  std::size_t n = 0;
  for (const auto& v : f.variables())
    if (v.kind == twin::fmu::VarKind::kMachineParam || v.kind == twin::fmu::VarKind::kAxisParam) ++n;
  return n;
}

}  // namespace

extern "C" {

const char* fmi2GetTypesPlatform(void) { return "default"; }
const char* fmi2GetVersion(void) { return "2.0"; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t, const fmi2String[]) {
  return guarded(c, "fmi2SetDebugLogging", [&](Component& comp) {
    comp.logging = loggingOn != fmi2False;
    return fmi2OK;
  });
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions, fmi2Boolean,
                              fmi2Boolean loggingOn) {
  const char* name = instanceName != nullptr ? instanceName : "";
  try {
    if (instanceName == nullptr || instanceName[0] == '\0')
      throw twin::ConfigError("fmi2Instantiate: instanceName is empty");
    if (fmuType != fmi2CoSimulation)
      throw twin::ConfigError("fmi2Instantiate: fmuType " + std::to_string(static_cast<int>(fmuType)) +
                              " is not fmi2CoSimulation (the FMU is Co-Simulation only)");
    if (fmuGUID == nullptr) throw twin::ConfigError("fmi2Instantiate: fmuGUID is null");
    if (fmuResourceLocation == nullptr) throw twin::ConfigError("fmi2Instantiate: fmuResourceLocation is null");
    const std::string model_path = path_from_uri(fmuResourceLocation) + "/model.json";
    twin::fmu::FmuModel model = twin::fmu::model_from_json(read_text(model_path), model_path);
    const std::string guid = twin::fmu::model_guid(model);
    if (guid != fmuGUID)
      throw twin::ConfigError("fmi2Instantiate: GUID " + std::string(fmuGUID) + " does not match this FMU's " + guid +
                              " (modelDescription.xml and binary or resources/model.json differ)");
    auto comp = std::make_unique<Component>();
    comp->name = name;
    if (functions != nullptr) comp->callbacks = *functions;
    comp->logging = loggingOn != fmi2False;
    comp->fmu = std::make_unique<FmuInstance>(name, std::move(model));
    return comp.release();
  } catch (const std::exception& e) {
    log_message(functions, name, fmi2Error, "logStatusError", e.what());
  } catch (...) {
    log_message(functions, name, fmi2Error, "logStatusError", "fmi2Instantiate: unknown exception");
  }
  return nullptr;
}

void fmi2FreeInstance(fmi2Component c) { delete static_cast<Component*>(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean, fmi2Real, fmi2Real startTime, fmi2Boolean, fmi2Real) {
  return guarded(c, "fmi2SetupExperiment", [&](Component& comp) {
    comp.fmu->setup_experiment(startTime);
    return fmi2OK;
  });
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2EnterInitializationMode", [&](Component& comp) {
    comp.fmu->enter_initialization();
    return fmi2OK;
  });
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2ExitInitializationMode", [&](Component& comp) {
    comp.fmu->exit_initialization();
    return fmi2OK;
  });
}

fmi2Status fmi2Terminate(fmi2Component c) {
  return guarded(c, "fmi2Terminate", [&](Component& comp) {
    comp.fmu->terminate();
    return fmi2OK;
  });
}

fmi2Status fmi2Reset(fmi2Component c) {
  return guarded(c, "fmi2Reset", [&](Component& comp) {
    comp.fmu->reset();
    return fmi2OK;
  });
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  return get_values(c, "fmi2GetReal", vr, nvr, value, [](FmuInstance& f, fmi2ValueReference r) { return f.get_real(r); });
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
  return get_values(c, "fmi2GetInteger", vr, nvr, value,
                    [](FmuInstance& f, fmi2ValueReference r) { return f.get_integer(r); });
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
  return get_values(c, "fmi2GetBoolean", vr, nvr, value, [](FmuInstance& f, fmi2ValueReference r) {
    return f.get_boolean(r) ? fmi2True : fmi2False;
  });
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  return get_values(c, "fmi2GetString", vr, nvr, value, [](FmuInstance& f, fmi2ValueReference r) -> fmi2String {
    throw twin::ConfigError("fmi2GetString: unknown valueReference " + std::to_string(r) + " (the FMU has no String variables; " +
                            std::to_string(f.variables().size()) + " variables)");
  });
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
  return set_values(c, "fmi2SetReal", vr, nvr, value,
                    [](FmuInstance& f, fmi2ValueReference r, fmi2Real v) { f.set_real(r, v); });
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
  return set_values(c, "fmi2SetInteger", vr, nvr, value,
                    [](FmuInstance& f, fmi2ValueReference r, fmi2Integer v) { f.set_integer(r, v); });
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
  return set_values(c, "fmi2SetBoolean", vr, nvr, value,
                    [](FmuInstance& f, fmi2ValueReference r, fmi2Boolean v) { f.set_boolean(r, v != fmi2False); });
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
  return set_values(c, "fmi2SetString", vr, nvr, value, [](FmuInstance& f, fmi2ValueReference r, fmi2String) {
    throw twin::ConfigError("fmi2SetString: unknown valueReference " + std::to_string(r) + " (the FMU has no String variables; " +
                            std::to_string(f.variables().size()) + " variables)");
  });
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2GetFMUstate", [&](Component& comp) {
    if (state == nullptr) throw twin::ConfigError("fmi2GetFMUstate: FMUstate pointer is null");
    auto saved = std::make_unique<SavedState>(comp.fmu->save());
    if (*state != nullptr) delete static_cast<SavedState*>(*state);
    *state = saved.release();
    return fmi2OK;
  });
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
  return guarded(c, "fmi2SetFMUstate", [&](Component& comp) {
    if (state == nullptr) throw twin::ConfigError("fmi2SetFMUstate: FMUstate is null");
    comp.fmu->restore(*static_cast<const SavedState*>(state));
    return fmi2OK;
  });
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2FreeFMUstate", [&](Component&) {
    if (state != nullptr) {
      delete static_cast<SavedState*>(*state);
      *state = nullptr;
    }
    return fmi2OK;
  });
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
  return guarded(c, "fmi2SerializedFMUstateSize", [&](Component&) {
    if (state == nullptr || size == nullptr) throw twin::ConfigError("fmi2SerializedFMUstateSize: null argument");
    *size = twin::fmu::serialize_state(*static_cast<const SavedState*>(state)).size();
    return fmi2OK;
  });
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
  return guarded(c, "fmi2SerializeFMUstate", [&](Component&) {
    if (state == nullptr || bytes == nullptr) throw twin::ConfigError("fmi2SerializeFMUstate: null argument");
    const std::vector<char> b = twin::fmu::serialize_state(*static_cast<const SavedState*>(state));
    if (b.size() != size)
      throw twin::ConfigError("fmi2SerializeFMUstate: buffer of " + std::to_string(size) + " bytes, the state has " +
                              std::to_string(b.size()));
    std::memcpy(bytes, b.data(), b.size());
    return fmi2OK;
  });
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state) {
  return guarded(c, "fmi2DeSerializeFMUstate", [&](Component& comp) {
    if (bytes == nullptr || state == nullptr) throw twin::ConfigError("fmi2DeSerializeFMUstate: null argument");
    auto s = std::make_unique<SavedState>(twin::fmu::deserialize_state(bytes, size));
    if (s->parameters.size() != num_parameters(*comp.fmu))
      throw twin::ConfigError("fmi2DeSerializeFMUstate: the state has " + std::to_string(s->parameters.size()) +
                              " parameters, this FMU " + std::to_string(num_parameters(*comp.fmu)));
    if (*state != nullptr) delete static_cast<SavedState*>(*state);
    *state = s.release();
    return fmi2OK;
  });
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference[], size_t, const fmi2ValueReference[],
                                        size_t, const fmi2Real[], fmi2Real[]) {
  return unsupported(c, "fmi2GetDirectionalDerivative", "providesDirectionalDerivative=false");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                       const fmi2Real[]) {
  return unsupported(c, "fmi2SetRealInputDerivatives", "canInterpolateInputs=false");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                        fmi2Real[]) {
  return unsupported(c, "fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder=0");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean) {
  return guarded(c, "fmi2DoStep", [&](Component& comp) {
    comp.fmu->do_step(currentCommunicationPoint, communicationStepSize);
    return fmi2OK;
  });
}

fmi2Status fmi2CancelStep(fmi2Component c) {
  return unsupported(c, "fmi2CancelStep", "fmi2DoStep never returns fmi2Pending");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind, fmi2Status*) {
  return unsupported(c, "fmi2GetStatus", "fmi2DoStep is synchronous and never returns fmi2Pending");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
  return guarded(c, "fmi2GetRealStatus", [&](Component& comp) {
    if (s != fmi2LastSuccessfulTime || value == nullptr)
      throw twin::ConfigError("fmi2GetRealStatus: only fmi2LastSuccessfulTime is available");
    *value = comp.fmu->time_s();
    return fmi2OK;
  });
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind, fmi2Integer*) {
  return unsupported(c, "fmi2GetIntegerStatus", "the FMU has no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
  return guarded(c, "fmi2GetBooleanStatus", [&](Component&) {
    if (s != fmi2Terminated || value == nullptr)
      throw twin::ConfigError("fmi2GetBooleanStatus: only fmi2Terminated is available");
    *value = fmi2False;
    return fmi2OK;
  });
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind, fmi2String*) {
  return unsupported(c, "fmi2GetStringStatus", "the FMU has no string status");
}

}  // extern "C"
