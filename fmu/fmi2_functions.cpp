// The exported FMI 2.0 Co-Simulation entry points: a thin adapter over the
// slave (fmu/slave.hpp) through the shared instance (fmu/host.hpp). Each call
// goes through guarded(): no exception crosses the C boundary; a failed call
// logs one line (category logStatusError, always) and moves the instance to
// the error state; a refused call (fmi2Discard, category logStatusDiscard)
// changes nothing; warnings go to logStatusWarning and calls that change the
// state to logCalls, each when enabled (loggingOn, fmi2SetDebugLogging).
#include <cstring>
#include <memory>
#include <string>

#include <fmt/format.h>

#include "fmu/fmi2_api.h"
#include "fmu/host.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::fmu::Instance;
using twin::fmu::Slave;
using twin::fmu::with_function;

/// fmi2Status has the numbers of twin::fmu::Status (fmi2Pending is never returned).
fmi2Status status(twin::fmu::Status s) { return static_cast<fmi2Status>(s); }

template <class F>
fmi2Status guarded(fmi2Component c, const char* function, F&& f) noexcept {
  return status(twin::fmu::guarded(static_cast<Instance*>(c), function, [&](Instance& inst) {
    return static_cast<twin::fmu::Status>(f(inst));
  }));
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

template <class T, class Get>
fmi2Status get_values(fmi2Component c, const char* function, const fmi2ValueReference vr[], size_t nvr, T value[],
                      Get get) {
  return guarded(c, function, [&](Instance& inst) {
    twin::fmu::get_values(inst, vr, nvr, value, get);
    return fmi2OK;
  });
}

template <class T, class Set>
fmi2Status set_values(fmi2Component c, const char* function, const fmi2ValueReference vr[], size_t nvr, const T value[],
                      Set set) {
  return guarded(c, function, [&](Instance& inst) {
    twin::fmu::set_values(inst, function, vr, nvr, value, set);
    return fmi2OK;
  });
}

/// An optional function the FMU does not provide: fmi2Error and a log line,
/// the instance stays usable.
fmi2Status unsupported(fmi2Component c, const char* function, const char* why) noexcept {
  auto* inst = static_cast<Instance*>(c);
  if (inst != nullptr) inst->log_error(twin::fmu::Status::kError, function, std::string("not supported: ") + why);
  return fmi2Error;
}

const char* status_kind_name(fmi2StatusKind s) {
  switch (s) {
    case fmi2DoStepStatus: return "fmi2DoStepStatus";
    case fmi2PendingStatus: return "fmi2PendingStatus";
    case fmi2LastSuccessfulTime: return "fmi2LastSuccessfulTime";
    case fmi2Terminated: return "fmi2Terminated";
  }
  return "an unknown status kind";
}

/// fmi2Get*Status for a kind the FMU does not provide: fmi2Discard (FMI
/// 2.0.2, section 4.2.3), logged in logStatusDiscard; nothing changes.
fmi2Status status_not_provided(fmi2Component c, const char* function, fmi2StatusKind s, const char* provided) {
  return guarded(c, function, [&](Instance&) -> fmi2Status {
    throw twin::fmu::Discard(fmt::format("{} is not provided ({})", status_kind_name(s), provided));
  });
}

std::string time_text(double t) { return fmt::format("{:.17g}", t); }

/// Logs an instantiation failure through the master's logger (no instance yet).
void log_instantiate_error(const fmi2CallbackFunctions* cb, const char* name, const std::string& message) {
  if (cb == nullptr || cb->logger == nullptr) return;
  cb->logger(cb->componentEnvironment, name, fmi2Error, "logStatusError", "%s", message.c_str());
}

}  // namespace

extern "C" {

const char* fmi2GetTypesPlatform(void) { return "default"; }
const char* fmi2GetVersion(void) { return "2.0"; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
  return guarded(c, "fmi2SetDebugLogging", [&](Instance& inst) {
    const bool on = loggingOn != fmi2False;
    inst.set_logging(on, twin::fmu::category_bits(nCategories, categories));
    inst.log_call("fmi2SetDebugLogging", fmt::format("loggingOn = {}, {} categories", on, nCategories));
    return fmi2OK;
  });
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions, fmi2Boolean,
                              fmi2Boolean loggingOn) {
  const char* name = instanceName != nullptr ? instanceName : "";
  try {
    if (instanceName == nullptr || instanceName[0] == '\0') throw twin::ConfigError("instanceName is empty");
    if (fmuType != fmi2CoSimulation)
      throw twin::ConfigError("fmuType " + std::to_string(static_cast<int>(fmuType)) +
                              " is not fmi2CoSimulation (the FMU is Co-Simulation only)");
    if (fmuGUID == nullptr) throw twin::ConfigError("fmuGUID is null");
    if (fmuResourceLocation == nullptr) throw twin::ConfigError("fmuResourceLocation is null");
    auto slave = twin::fmu::make_slave(path_from_uri(fmuResourceLocation), fmuGUID, "GUID", &twin::fmu::model_guid);
    twin::fmu::LogSink sink;
    if (functions != nullptr && functions->logger != nullptr)
      sink = [cb = *functions, instance = std::string(name)](twin::fmu::Status s, const char* category,
                                                             const std::string& message) {
        cb.logger(cb.componentEnvironment, instance.c_str(), status(s), category, "%s", message.c_str());
      };
    auto inst = std::make_unique<Instance>(name, std::move(sink), loggingOn != fmi2False, std::move(slave));
    inst->log_call("fmi2Instantiate", fmt::format("scenario {}, GUID {}, resources {}",
                                                  inst->slave().model().name, inst->slave().identity(),
                                                  fmuResourceLocation));
    return inst.release();
  } catch (const std::exception& e) {
    log_instantiate_error(functions, name, with_function("fmi2Instantiate", e.what()));
  } catch (...) {
    log_instantiate_error(functions, name, "fmi2Instantiate: unknown exception");
  }
  return nullptr;
}

void fmi2FreeInstance(fmi2Component c) { delete static_cast<Instance*>(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean, fmi2Real, fmi2Real startTime, fmi2Boolean stopTimeDefined,
                               fmi2Real stopTime) {
  return guarded(c, "fmi2SetupExperiment", [&](Instance& inst) {
    const bool stop_defined = stopTimeDefined != fmi2False;
    inst.set_experiment(startTime, stop_defined ? std::optional<double>(stopTime) : std::nullopt);
    inst.log_call("fmi2SetupExperiment",
                  fmt::format("startTime = {} s, {}", time_text(startTime),
                              stop_defined ? "stopTime = " + time_text(stopTime) + " s" : "no stop time"));
    return fmi2OK;
  });
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2EnterInitializationMode", [&](Instance& inst) {
    inst.enter_initialization();
    inst.log_call("fmi2EnterInitializationMode", "initialization mode");
    return fmi2OK;
  });
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2ExitInitializationMode", [&](Instance& inst) {
    inst.exit_initialization();
    inst.log_call("fmi2ExitInitializationMode", "step mode");
    return fmi2OK;
  });
}

fmi2Status fmi2Terminate(fmi2Component c) {
  return guarded(c, "fmi2Terminate", [&](Instance& inst) {
    inst.terminate();
    inst.log_call("fmi2Terminate", fmt::format("terminated at t = {} s", time_text(inst.slave().time_s())));
    return fmi2OK;
  });
}

fmi2Status fmi2Reset(fmi2Component c) {
  return guarded(c, "fmi2Reset", [&](Instance& inst) {
    inst.reset();
    inst.log_call("fmi2Reset", "instantiated");
    return fmi2OK;
  });
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  return get_values(c, "fmi2GetReal", vr, nvr, value, [](const Slave& f, fmi2ValueReference r) { return f.get_real(r); });
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
  return get_values(c, "fmi2GetInteger", vr, nvr, value,
                    [](const Slave& f, fmi2ValueReference r) { return f.get_integer(r); });
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
  return get_values(c, "fmi2GetBoolean", vr, nvr, value, [](const Slave& f, fmi2ValueReference r) {
    return f.get_boolean(r) ? fmi2True : fmi2False;
  });
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  return get_values(c, "fmi2GetString", vr, nvr, value, [](const Slave& f, fmi2ValueReference r) -> fmi2String {
    throw twin::ConfigError("unknown valueReference " + std::to_string(r) + " (the FMU has no String variables; " +
                            std::to_string(f.variables().size()) + " variables)");
  });
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
  return set_values(c, "fmi2SetReal", vr, nvr, value,
                    [](Slave& f, fmi2ValueReference r, fmi2Real v) { f.set_real(r, v); });
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
  return set_values(c, "fmi2SetInteger", vr, nvr, value,
                    [](Slave& f, fmi2ValueReference r, fmi2Integer v) { f.set_integer(r, v); });
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
  return set_values(c, "fmi2SetBoolean", vr, nvr, value,
                    [](Slave& f, fmi2ValueReference r, fmi2Boolean v) { f.set_boolean(r, v != fmi2False); });
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
  return guarded(c, "fmi2SetString", [&](Instance& inst) -> fmi2Status {
    inst.require_set();
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError("null array");
    if (nvr == 0) return fmi2OK;
    throw twin::ConfigError("unknown valueReference " + std::to_string(vr[0]) +
                            " (the FMU has no String variables; " + std::to_string(inst.slave().variables().size()) +
                            " variables)");
  });
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2GetFMUstate", [&](Instance& inst) {
    twin::fmu::get_state(inst, state);
    return fmi2OK;
  });
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
  return guarded(c, "fmi2SetFMUstate", [&](Instance& inst) {
    twin::fmu::set_state(inst, state);
    inst.log_call("fmi2SetFMUstate", fmt::format("restored t = {} s", time_text(inst.slave().time_s())));
    return fmi2OK;
  });
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2FreeFMUstate", [&](Instance&) {
    twin::fmu::free_state(state);
    return fmi2OK;
  });
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
  return guarded(c, "fmi2SerializedFMUstateSize", [&](Instance&) {
    if (size == nullptr) throw twin::ConfigError("size pointer is null");
    *size = twin::fmu::serialized_state_size(state);
    return fmi2OK;
  });
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
  return guarded(c, "fmi2SerializeFMUstate", [&](Instance&) {
    twin::fmu::serialize_state(state, bytes, size);
    return fmi2OK;
  });
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state) {
  return guarded(c, "fmi2DeSerializeFMUstate", [&](Instance& inst) {
    twin::fmu::deserialize_state(inst, bytes, size, state);
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
  return guarded(c, "fmi2DoStep", [&](Instance& inst) {
    const std::int64_t n = inst.do_step(currentCommunicationPoint, communicationStepSize);
    inst.log_call("fmi2DoStep",
                  fmt::format("t = {} s, h = {} s: {} ticks run, {} in all", time_text(currentCommunicationPoint),
                              time_text(communicationStepSize), n, inst.slave().ticks()));
    return fmi2OK;
  });
}

fmi2Status fmi2CancelStep(fmi2Component c) {
  return unsupported(c, "fmi2CancelStep", "fmi2DoStep never returns fmi2Pending");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status*) {
  return status_not_provided(c, "fmi2GetStatus", s, "fmi2DoStep is synchronous and never returns fmi2Pending");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
  if (s != fmi2LastSuccessfulTime) return status_not_provided(c, "fmi2GetRealStatus", s, "only fmi2LastSuccessfulTime is");
  return guarded(c, "fmi2GetRealStatus", [&](Instance& inst) {
    if (value == nullptr) throw twin::ConfigError("value pointer is null");
    *value = inst.slave().time_s();
    return fmi2OK;
  });
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer*) {
  return status_not_provided(c, "fmi2GetIntegerStatus", s, "the FMU has no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
  if (s != fmi2Terminated) return status_not_provided(c, "fmi2GetBooleanStatus", s, "only fmi2Terminated is");
  return guarded(c, "fmi2GetBooleanStatus", [&](Instance&) {
    if (value == nullptr) throw twin::ConfigError("value pointer is null");
    *value = fmi2False;
    return fmi2OK;
  });
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String*) {
  return status_not_provided(c, "fmi2GetStringStatus", s, "the FMU has no string status");
}

}  // extern "C"
