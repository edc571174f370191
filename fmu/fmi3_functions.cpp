// The exported FMI 3.0 Co-Simulation entry points: a thin adapter over the
// slave (fmu/slave.hpp) through the shared instance (fmu/host.hpp), as
// fmi2_functions.cpp is for FMI 2.0. Each call goes through guarded(): no
// exception crosses the C boundary; a failed call logs one line (category
// logStatusError, always) and moves the instance to the error state; a
// refused call (fmi3Discard) changes nothing.
//
// What differs from the FMI 2.0 adapter: resourcePath is a folder, not a
// URI; the experiment comes with fmi3EnterInitializationMode; a step must be
// a whole number of controller ticks (fixedInternalStepSize = Ts); value
// reference N (after the table's rows 0..N-1) is the independent variable
// `time`; the FMU has no event mode, clocks or intermediate update.
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "fmu/fmi3_api.h"
#include "fmu/host.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::fmu::Instance;
using twin::fmu::Slave;
using twin::fmu::with_function;

/// fmi3Status has the numbers of twin::fmu::Status.
fmi3Status status(twin::fmu::Status s) { return static_cast<fmi3Status>(s); }

template <class F>
fmi3Status guarded(fmi3Instance c, const char* function, F&& f) noexcept {
  return status(twin::fmu::guarded(static_cast<Instance*>(c), function, [&](Instance& inst) {
    return static_cast<twin::fmu::Status>(f(inst));
  }));
}

/// The value reference of `time`: the first after the variable table.
bool is_time(const Slave& s, fmi3ValueReference vr) { return vr == s.variables().size(); }

void check_count(size_t nvr, size_t nValues) {
  if (nValues != nvr)
    throw twin::ConfigError(fmt::format("nValues = {} for {} value references (every variable is a scalar)", nValues, nvr));
}

template <class T, class Get>
fmi3Status get_values(fmi3Instance c, const char* function, const fmi3ValueReference vr[], size_t nvr, T value[],
                      size_t nValues, Get get) {
  return guarded(c, function, [&](Instance& inst) {
    check_count(nvr, nValues);
    twin::fmu::get_values(inst, vr, nvr, value, get);
    return fmi3OK;
  });
}

template <class T, class Set>
fmi3Status set_values(fmi3Instance c, const char* function, const fmi3ValueReference vr[], size_t nvr,
                      const T value[], size_t nValues, Set set) {
  return guarded(c, function, [&](Instance& inst) {
    check_count(nvr, nValues);
    twin::fmu::set_values(inst, function, vr, nvr, value, set);
    return fmi3OK;
  });
}

/// A value reference read or written through a type the FMU has no
/// variable of: an error naming it (none at all: nothing to do).
fmi3Status no_such_type(fmi3Instance c, const char* function, const char* type, const fmi3ValueReference vr[],
                        size_t nvr) {
  return guarded(c, function, [&](Instance& inst) {
    if (nvr == 0) return fmi3OK;
    if (vr == nullptr) throw twin::ConfigError("null array");
    throw twin::ConfigError(fmt::format("valueReference {} is not a {} variable (the FMU has Float64, Int32 and "
                                        "Boolean variables, references 0..{})",
                                        vr[0], type, inst.slave().variables().size()));
  });
}

/// An optional function the FMU does not provide: fmi3Error and a log line,
/// the instance stays usable.
fmi3Status unsupported(fmi3Instance c, const char* function, const char* why) noexcept {
  auto* inst = static_cast<Instance*>(c);
  if (inst != nullptr) inst->log_error(twin::fmu::Status::kError, function, std::string("not supported: ") + why);
  return fmi3Error;
}

std::string time_text(double t) { return fmt::format("{:.17g}", t); }

/// Logs an instantiation failure through the master's callback (no instance yet).
std::nullptr_t refuse_instance(fmi3LogMessageCallback log, fmi3InstanceEnvironment env, const std::string& message) {
  if (log != nullptr) log(env, fmi3Error, "logStatusError", message.c_str());
  return nullptr;
}

/// "/a/b/resources/" or "/a/b/resources" -> "/a/b/resources".
std::string folder(const char* path) {
  std::string p = path;
  if (p.empty() || p.front() != '/')
    throw twin::ConfigError("resourcePath '" + p + "' is not an absolute path (FMI 3.0 passes a folder, not a URI)");
  while (p.size() > 1 && p.back() == '/') p.pop_back();
  return p;
}

}  // namespace

extern "C" {

const char* fmi3GetVersion(void) { return "3.0"; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
  return guarded(c, "fmi3SetDebugLogging", [&](Instance& inst) {
    inst.set_logging(loggingOn, twin::fmu::category_bits(nCategories, categories));
    inst.log_call("fmi3SetDebugLogging", fmt::format("loggingOn = {}, {} categories", loggingOn, nCategories));
    return fmi3OK;
  });
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String, fmi3String, fmi3String, fmi3Boolean, fmi3Boolean,
                                          fmi3InstanceEnvironment env, fmi3LogMessageCallback log) {
  return refuse_instance(log, env, "fmi3InstantiateModelExchange: the FMU is Co-Simulation only");
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String, fmi3String, fmi3String, fmi3Boolean, fmi3Boolean,
                                               fmi3InstanceEnvironment env, fmi3LogMessageCallback log,
                                               fmi3ClockUpdateCallback, fmi3LockPreemptionCallback,
                                               fmi3UnlockPreemptionCallback) {
  return refuse_instance(log, env, "fmi3InstantiateScheduledExecution: the FMU is Co-Simulation only");
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean, const fmi3ValueReference[],
                                         size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment env,
                                         fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback) {
  const char* name = instanceName != nullptr ? instanceName : "";
  try {
    if (instanceName == nullptr || instanceName[0] == '\0') throw twin::ConfigError("instanceName is empty");
    if (instantiationToken == nullptr) throw twin::ConfigError("instantiationToken is null");
    if (resourcePath == nullptr) throw twin::ConfigError("resourcePath is null");
    if (eventModeUsed) throw twin::ConfigError("eventModeUsed = true: the FMU has no event mode (hasEventMode=false)");
    if (nRequiredIntermediateVariables > 0)
      throw twin::ConfigError(fmt::format("{} requiredIntermediateVariables: the FMU provides no intermediate update",
                                          nRequiredIntermediateVariables));
    auto slave = twin::fmu::make_slave(folder(resourcePath), instantiationToken, "instantiationToken",
                                       &twin::fmu::instantiation_token);
    twin::fmu::LogSink sink;
    if (log != nullptr)
      sink = [log, env](twin::fmu::Status s, const char* category, const std::string& message) {
        log(env, status(s), category, message.c_str());
      };
    auto inst = std::make_unique<Instance>(name, std::move(sink), loggingOn, std::move(slave));
    inst->log_call("fmi3InstantiateCoSimulation",
                   fmt::format("scenario {}, instantiationToken {}, resources {}", inst->slave().model().name,
                               inst->slave().identity(), resourcePath));
    return inst.release();
  } catch (const std::exception& e) {
    return refuse_instance(log, env, with_function("fmi3InstantiateCoSimulation", e.what()));
  } catch (...) {
    return refuse_instance(log, env, "fmi3InstantiateCoSimulation: unknown exception");
  }
}

void fmi3FreeInstance(fmi3Instance c) { delete static_cast<Instance*>(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean, fmi3Float64, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
  return guarded(c, "fmi3EnterInitializationMode", [&](Instance& inst) {
    inst.set_experiment(startTime, stopTimeDefined ? std::optional<double>(stopTime) : std::nullopt);
    inst.enter_initialization();
    inst.log_call("fmi3EnterInitializationMode",
                  fmt::format("startTime = {} s, {}", time_text(startTime),
                              stopTimeDefined ? "stopTime = " + time_text(stopTime) + " s" : "no stop time"));
    return fmi3OK;
  });
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
  return guarded(c, "fmi3ExitInitializationMode", [&](Instance& inst) {
    inst.exit_initialization();
    inst.log_call("fmi3ExitInitializationMode", "step mode");
    return fmi3OK;
  });
}

fmi3Status fmi3EnterEventMode(fmi3Instance c) {
  return unsupported(c, "fmi3EnterEventMode", "the FMU has no event mode (hasEventMode=false)");
}

fmi3Status fmi3Terminate(fmi3Instance c) {
  return guarded(c, "fmi3Terminate", [&](Instance& inst) {
    inst.terminate();
    inst.log_call("fmi3Terminate", fmt::format("terminated at t = {} s", time_text(inst.slave().time_s())));
    return fmi3OK;
  });
}

fmi3Status fmi3Reset(fmi3Instance c) {
  return guarded(c, "fmi3Reset", [&](Instance& inst) {
    inst.reset();
    inst.log_call("fmi3Reset", "instantiated");
    return fmi3OK;
  });
}

// ---- values ------------------------------------------------------------------

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
  return get_values(c, "fmi3GetFloat64", vr, nvr, values, nValues, [](const Slave& s, fmi3ValueReference r) {
    return is_time(s, r) ? s.time_s() : s.get_real(r);
  });
}
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Int32 values[], size_t nValues) {
  return get_values(c, "fmi3GetInt32", vr, nvr, values, nValues,
                    [](const Slave& s, fmi3ValueReference r) { return s.get_integer(r); });
}
fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
  return get_values(c, "fmi3GetBoolean", vr, nvr, values, nValues,
                    [](const Slave& s, fmi3ValueReference r) { return s.get_boolean(r); });
}
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues) {
  return set_values(c, "fmi3SetFloat64", vr, nvr, values, nValues, [](Slave& s, fmi3ValueReference r, double v) {
    if (is_time(s, r)) throw twin::ConfigError("time (valueReference " + std::to_string(r) + ") is the independent variable and cannot be set");
    s.set_real(r, v);
  });
}
fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 values[],
                        size_t nValues) {
  return set_values(c, "fmi3SetInt32", vr, nvr, values, nValues,
                    [](Slave& s, fmi3ValueReference r, fmi3Int32 v) { s.set_integer(r, v); });
}
fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[],
                          size_t nValues) {
  return set_values(c, "fmi3SetBoolean", vr, nvr, values, nValues,
                    [](Slave& s, fmi3ValueReference r, fmi3Boolean v) { s.set_boolean(r, v); });
}

// The types the FMU has no variable of.
#define TWIN_FMI3_NO_TYPE(T)                                                                                     \
  fmi3Status fmi3Get##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3##T[], size_t) {          \
    return no_such_type(c, "fmi3Get" #T, #T, vr, nvr);                                                            \
  }                                                                                                               \
  fmi3Status fmi3Set##T(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3##T[], size_t) {    \
    return no_such_type(c, "fmi3Set" #T, #T, vr, nvr);                                                           \
  }
TWIN_FMI3_NO_TYPE(Float32)
TWIN_FMI3_NO_TYPE(Int8)
TWIN_FMI3_NO_TYPE(UInt8)
TWIN_FMI3_NO_TYPE(Int16)
TWIN_FMI3_NO_TYPE(UInt16)
TWIN_FMI3_NO_TYPE(UInt32)
TWIN_FMI3_NO_TYPE(Int64)
TWIN_FMI3_NO_TYPE(UInt64)
TWIN_FMI3_NO_TYPE(String)
#undef TWIN_FMI3_NO_TYPE

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t[], fmi3Binary[], size_t) {
  return no_such_type(c, "fmi3GetBinary", "Binary", vr, nvr);
}
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t[], const fmi3Binary[],
                         size_t) {
  return no_such_type(c, "fmi3SetBinary", "Binary", vr, nvr);
}
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock[]) {
  return no_such_type(c, "fmi3GetClock", "Clock", vr, nvr);
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock[]) {
  return no_such_type(c, "fmi3SetClock", "Clock", vr, nvr);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference, size_t*) {
  return unsupported(c, "fmi3GetNumberOfVariableDependencies", "ModelStructure in modelDescription.xml lists them");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference, size_t[], fmi3ValueReference[], size_t[],
                                       fmi3DependencyKind[], size_t) {
  return unsupported(c, "fmi3GetVariableDependencies", "ModelStructure in modelDescription.xml lists them");
}

// ---- FMU state -----------------------------------------------------------------

fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState* state) {
  return guarded(c, "fmi3GetFMUState", [&](Instance& inst) {
    twin::fmu::get_state(inst, state);
    return fmi3OK;
  });
}

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state) {
  return guarded(c, "fmi3SetFMUState", [&](Instance& inst) {
    twin::fmu::set_state(inst, state);
    inst.log_call("fmi3SetFMUState", fmt::format("restored t = {} s", time_text(inst.slave().time_s())));
    return fmi3OK;
  });
}

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState* state) {
  return guarded(c, "fmi3FreeFMUState", [&](Instance&) {
    twin::fmu::free_state(state);
    return fmi3OK;
  });
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t* size) {
  return guarded(c, "fmi3SerializedFMUStateSize", [&](Instance&) {
    if (size == nullptr) throw twin::ConfigError("size pointer is null");
    *size = twin::fmu::serialized_state_size(state);
    return fmi3OK;
  });
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte bytes[], size_t size) {
  return guarded(c, "fmi3SerializeFMUState", [&](Instance&) {
    twin::fmu::serialize_state(state, reinterpret_cast<char*>(bytes), size);
    return fmi3OK;
  });
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte bytes[], size_t size, fmi3FMUState* state) {
  return guarded(c, "fmi3DeserializeFMUState", [&](Instance& inst) {
    twin::fmu::deserialize_state(inst, reinterpret_cast<const char*>(bytes), size, state);
    return fmi3OK;
  });
}

// ---- what the FMU does not provide -------------------------------------------------

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3ValueReference[],
                                        size_t, const fmi3Float64[], size_t, fmi3Float64[], size_t) {
  return unsupported(c, "fmi3GetDirectionalDerivative", "providesDirectionalDerivatives=false");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3ValueReference[],
                                    size_t, const fmi3Float64[], size_t, fmi3Float64[], size_t) {
  return unsupported(c, "fmi3GetAdjointDerivative", "providesAdjointDerivatives=false");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) {
  return unsupported(c, "fmi3EnterConfigurationMode", "the FMU has no structural parameters");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) {
  return unsupported(c, "fmi3ExitConfigurationMode", "the FMU has no structural parameters");
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference[], size_t, fmi3Float64[],
                                  fmi3IntervalQualifier[]) {
  return unsupported(c, "fmi3GetIntervalDecimal", "the FMU has no clocks");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference[], size_t, fmi3UInt64[], fmi3UInt64[],
                                   fmi3IntervalQualifier[]) {
  return unsupported(c, "fmi3GetIntervalFraction", "the FMU has no clocks");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference[], size_t, fmi3Float64[]) {
  return unsupported(c, "fmi3GetShiftDecimal", "the FMU has no clocks");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference[], size_t, fmi3UInt64[], fmi3UInt64[]) {
  return unsupported(c, "fmi3GetShiftFraction", "the FMU has no clocks");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Float64[]) {
  return unsupported(c, "fmi3SetIntervalDecimal", "the FMU has no clocks");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3UInt64[],
                                   const fmi3UInt64[]) {
  return unsupported(c, "fmi3SetIntervalFraction", "the FMU has no clocks");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Float64[]) {
  return unsupported(c, "fmi3SetShiftDecimal", "the FMU has no clocks");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3UInt64[],
                                const fmi3UInt64[]) {
  return unsupported(c, "fmi3SetShiftFraction", "the FMU has no clocks");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) {
  return unsupported(c, "fmi3EvaluateDiscreteStates", "the FMU has no event mode (hasEventMode=false)");
}
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean*, fmi3Boolean*, fmi3Boolean*, fmi3Boolean*,
                                    fmi3Boolean*, fmi3Float64*) {
  return unsupported(c, "fmi3UpdateDiscreteStates", "the FMU has no event mode (hasEventMode=false)");
}
fmi3Status fmi3EnterStepMode(fmi3Instance c) {
  return unsupported(c, "fmi3EnterStepMode",
                     "the FMU has no event mode (hasEventMode=false): fmi3ExitInitializationMode enters step mode");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference[], size_t, const fmi3Int32[],
                                    fmi3Float64[], size_t) {
  return unsupported(c, "fmi3GetOutputDerivatives", "maxOutputDerivativeOrder=0");
}

// ---- the step ------------------------------------------------------------------

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean, fmi3Boolean* eventHandlingNeeded, fmi3Boolean* terminateSimulation,
                      fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime) {
  return guarded(c, "fmi3DoStep", [&](Instance& inst) {
    inst.require({twin::fmu::CallState::kStepMode});
    const Slave& s = inst.slave();
    const double h = communicationStepSize;
    // h <= 0 or not a number: the slave's own message.
    if (h > 0.0 && !s.whole_ticks(currentCommunicationPoint, h))
      throw twin::ConfigError(fmt::format(
          "communicationStepSize = {:.17g} s is not a whole number of controller ticks of Ts = {} s "
          "(fixedInternalStepSize): {:.6g} ticks",
          h, s.Ts_s(), h / s.Ts_s()));
    const std::int64_t n = inst.do_step(currentCommunicationPoint, h);
    if (eventHandlingNeeded != nullptr) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation != nullptr) *terminateSimulation = fmi3False;
    if (earlyReturn != nullptr) *earlyReturn = fmi3False;
    if (lastSuccessfulTime != nullptr) *lastSuccessfulTime = s.time_s();
    inst.log_call("fmi3DoStep", fmt::format("t = {} s, h = {} s: {} ticks run, {} in all",
                                            time_text(currentCommunicationPoint), time_text(h), n, s.ticks()));
    return fmi3OK;
  });
}

}  // extern "C"
