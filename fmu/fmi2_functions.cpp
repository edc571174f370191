// The exported FMI 2.0 Co-Simulation entry points. Each goes through
// guarded(): no exception crosses the C boundary; a failed call logs one line
// (category logStatusError, always) and moves the instance to the error
// state; a refused call (fmi2Discard, category logStatusDiscard) changes
// nothing; warnings go to logStatusWarning and calls that change the state to
// logCalls, each when enabled (loggingOn, fmi2SetDebugLogging).
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>
#include <string>

#include <fmt/format.h>

#include "fmu/fmi2_api.h"
#include "fmu/instance.hpp"
#include "fmu/model_description.hpp"
#include "twin/core/error.hpp"

namespace {

using twin::fmu::FmuInstance;
using twin::fmu::FmuMode;
using twin::fmu::SavedState;

/// The log categories of modelDescription.xml, as bits.
enum LogCategory : unsigned {
  kLogCalls = 1u,
  kLogStatusWarning = 2u,
  kLogStatusDiscard = 4u,
  kLogStatusError = 8u,
  kLogStatusFatal = 16u,
};
struct CategoryName {
  const char* name;
  unsigned bit;
};
constexpr CategoryName kCategories[] = {{"logCalls", kLogCalls},
                                        {"logStatusWarning", kLogStatusWarning},
                                        {"logStatusDiscard", kLogStatusDiscard},
                                        {"logStatusError", kLogStatusError},
                                        {"logStatusFatal", kLogStatusFatal}};
constexpr unsigned kAllCategories = kLogCalls | kLogStatusWarning | kLogStatusDiscard | kLogStatusError | kLogStatusFatal;

const char* category_name(unsigned bit) {
  for (const auto& c : kCategories)
    if (c.bit == bit) return c.name;
  return "logStatusError";
}

struct Component {
  std::string name;
  fmi2CallbackFunctions callbacks{};
  unsigned categories{0};  ///< enabled log categories (loggingOn and fmi2SetDebugLogging)
  std::unique_ptr<FmuInstance> fmu;
};

void log_message(const fmi2CallbackFunctions* cb, const char* instance, fmi2Status status, const char* category,
                 const std::string& message) {
  if (cb == nullptr || cb->logger == nullptr) return;
  cb->logger(cb->componentEnvironment, instance, status, category, "%s", message.c_str());
}

/// Errors and fatal errors are always logged (a failed call without its
/// reason helps nobody); the other categories only when enabled.
void emit(const Component& c, fmi2Status status, unsigned category, const std::string& message) {
  const bool always = category == kLogStatusError || category == kLogStatusFatal;
  if (!always && (c.categories & category) == 0) return;
  log_message(&c.callbacks, c.name.c_str(), status, category_name(category), message);
}

/// "function: what", without repeating a "function: " that `what` already starts with.
std::string with_function(const char* function, const std::string& what) {
  const std::string prefix = std::string(function) + ": ";
  return what.rfind(prefix, 0) == 0 ? what : prefix + what;
}

void log_error(const Component& c, fmi2Status status, const char* function, const std::string& what) {
  emit(c, status, status == fmi2Fatal ? kLogStatusFatal : kLogStatusError, with_function(function, what));
}

/// A call that changed the state, for category logCalls.
void log_call(const Component& c, const char* function, const std::string& what) {
  if ((c.categories & kLogCalls) == 0) return;
  emit(c, fmi2OK, kLogCalls, with_function(function, what));
}

template <class F>
fmi2Status guarded(fmi2Component handle, const char* function, F&& f) noexcept {
  auto* c = static_cast<Component*>(handle);
  if (c == nullptr) return fmi2Error;
  try {
    fmi2Status status = f(*c);
    for (const std::string& w : c->fmu->take_warnings()) {
      emit(*c, fmi2Warning, kLogStatusWarning, with_function(function, w));
      if (status == fmi2OK) status = fmi2Warning;
    }
    return status;
  } catch (const twin::fmu::Discard& e) {
    c->fmu->take_warnings();
    emit(*c, fmi2Discard, kLogStatusDiscard, with_function(function, e.what()));
    return fmi2Discard;
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
    comp.fmu->require({FmuMode::kInitialization, FmuMode::kStepMode, FmuMode::kTerminated, FmuMode::kError});
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError("null array");
    for (size_t i = 0; i < nvr; ++i) value[i] = get(*comp.fmu, vr[i]);
    return fmi2OK;
  });
}

std::string value_text(double v) { return fmt::format("{}", v); }
std::string value_text(int v) { return std::to_string(v); }

template <class T, class Set>
fmi2Status set_values(fmi2Component c, const char* function, const fmi2ValueReference vr[], size_t nvr, const T value[],
                      Set set) {
  return guarded(c, function, [&](Component& comp) {
    comp.fmu->require({FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode});
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError("null array");
    for (size_t i = 0; i < nvr; ++i) set(*comp.fmu, vr[i], value[i]);
    if ((comp.categories & kLogCalls) != 0 && nvr > 0) {
      std::string what;
      for (size_t i = 0; i < nvr; ++i)
        what += fmt::format("{}{} = {}", i > 0 ? ", " : "", comp.fmu->variables()[vr[i]].name, value_text(value[i]));
      log_call(comp, function, what);
    }
    return fmi2OK;
  });
}

/// An optional function the FMU does not provide: fmi2Error and a log line,
/// the instance stays usable.
fmi2Status unsupported(fmi2Component c, const char* function, const char* why) noexcept {
  auto* comp = static_cast<Component*>(c);
  if (comp != nullptr) log_error(*comp, fmi2Error, function, std::string("not supported: ") + why);
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
  return guarded(c, function, [&](Component&) -> fmi2Status {
    throw twin::fmu::Discard(fmt::format("{} is not provided ({})", status_kind_name(s), provided));
  });
}

const SavedState& saved_state(fmi2FMUstate state) {
  if (state == nullptr) throw twin::ConfigError("FMUstate is null");
  const auto* s = static_cast<const SavedState*>(state);
  if (s->magic != twin::fmu::kStateMagic) throw twin::ConfigError("FMUstate was not made by this FMU");
  return *s;
}

std::string time_text(double t) { return fmt::format("{:.17g}", t); }

}  // namespace

extern "C" {

const char* fmi2GetTypesPlatform(void) { return "default"; }
const char* fmi2GetVersion(void) { return "2.0"; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
  return guarded(c, "fmi2SetDebugLogging", [&](Component& comp) {
    const bool on = loggingOn != fmi2False;
    unsigned bits = 0;
    if (nCategories == 0) {
      bits = kAllCategories;
    } else {
      if (categories == nullptr) throw twin::ConfigError(fmt::format("nCategories = {} with a null array", nCategories));
      for (size_t i = 0; i < nCategories; ++i) {
        const char* name = categories[i];
        unsigned bit = 0;
        for (const auto& cat : kCategories)
          if (name != nullptr && std::strcmp(name, cat.name) == 0) bit = cat.bit;
        if (bit == 0)
          throw twin::ConfigError(fmt::format(
              "category '{}' is not one of the FMU's (logCalls, logStatusWarning, logStatusDiscard, logStatusError, "
              "logStatusFatal)",
              name != nullptr ? name : "(null)"));
        bits |= bit;
      }
    }
    comp.categories = on ? (comp.categories | bits) : (comp.categories & ~bits);
    log_call(comp, "fmi2SetDebugLogging", fmt::format("loggingOn = {}, {} categories", on, nCategories));
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
    const std::string model_path = path_from_uri(fmuResourceLocation) + "/model.json";
    twin::fmu::FmuModel model = twin::fmu::model_from_json(read_text(model_path), model_path);
    std::string guid = twin::fmu::model_guid(model);
    if (guid != fmuGUID)
      throw twin::ConfigError("GUID " + std::string(fmuGUID) + " does not match this FMU's " + guid +
                              " (modelDescription.xml and binary or resources/model.json differ)");
    auto comp = std::make_unique<Component>();
    comp->name = name;
    if (functions != nullptr) comp->callbacks = *functions;
    comp->categories = loggingOn != fmi2False ? kAllCategories : 0u;
    comp->fmu = std::make_unique<FmuInstance>(name, std::move(model), std::move(guid));
    log_call(*comp, "fmi2Instantiate",
             fmt::format("scenario {}, GUID {}, resources {}", comp->fmu->model().scenario_name, comp->fmu->guid(),
                         fmuResourceLocation));
    return comp.release();
  } catch (const std::exception& e) {
    log_message(functions, name, fmi2Error, "logStatusError", with_function("fmi2Instantiate", e.what()));
  } catch (...) {
    log_message(functions, name, fmi2Error, "logStatusError", "fmi2Instantiate: unknown exception");
  }
  return nullptr;
}

void fmi2FreeInstance(fmi2Component c) { delete static_cast<Component*>(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean, fmi2Real, fmi2Real startTime, fmi2Boolean stopTimeDefined,
                               fmi2Real stopTime) {
  return guarded(c, "fmi2SetupExperiment", [&](Component& comp) {
    comp.fmu->setup_experiment(startTime, stopTimeDefined != fmi2False, stopTime);
    log_call(comp, "fmi2SetupExperiment",
             fmt::format("startTime = {} s, {}", time_text(startTime),
                         stopTimeDefined != fmi2False ? "stopTime = " + time_text(stopTime) + " s" : "no stop time"));
    return fmi2OK;
  });
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2EnterInitializationMode", [&](Component& comp) {
    comp.fmu->enter_initialization();
    log_call(comp, "fmi2EnterInitializationMode", "initialization mode");
    return fmi2OK;
  });
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  return guarded(c, "fmi2ExitInitializationMode", [&](Component& comp) {
    comp.fmu->exit_initialization();
    log_call(comp, "fmi2ExitInitializationMode", "step mode");
    return fmi2OK;
  });
}

fmi2Status fmi2Terminate(fmi2Component c) {
  return guarded(c, "fmi2Terminate", [&](Component& comp) {
    comp.fmu->terminate();
    log_call(comp, "fmi2Terminate", fmt::format("terminated at t = {} s", time_text(comp.fmu->time_s())));
    return fmi2OK;
  });
}

fmi2Status fmi2Reset(fmi2Component c) {
  return guarded(c, "fmi2Reset", [&](Component& comp) {
    comp.fmu->reset();
    log_call(comp, "fmi2Reset", "instantiated");
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
    throw twin::ConfigError("unknown valueReference " + std::to_string(r) + " (the FMU has no String variables; " +
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
  return guarded(c, "fmi2SetString", [&](Component& comp) -> fmi2Status {
    comp.fmu->require({FmuMode::kInstantiated, FmuMode::kInitialization, FmuMode::kStepMode});
    if (nvr > 0 && (vr == nullptr || value == nullptr)) throw twin::ConfigError("null array");
    if (nvr == 0) return fmi2OK;
    throw twin::ConfigError("unknown valueReference " + std::to_string(vr[0]) +
                            " (the FMU has no String variables; " + std::to_string(comp.fmu->variables().size()) +
                            " variables)");
  });
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2GetFMUstate", [&](Component& comp) {
    if (state == nullptr) throw twin::ConfigError("FMUstate pointer is null");
    auto saved = std::make_unique<SavedState>(comp.fmu->save());
    if (*state != nullptr) {
      saved_state(*state);  // refuse to overwrite what is not ours
      delete static_cast<SavedState*>(*state);
    }
    *state = saved.release();
    return fmi2OK;
  });
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
  return guarded(c, "fmi2SetFMUstate", [&](Component& comp) {
    comp.fmu->restore(saved_state(state));
    log_call(comp, "fmi2SetFMUstate", fmt::format("restored t = {} s", time_text(comp.fmu->time_s())));
    return fmi2OK;
  });
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
  return guarded(c, "fmi2FreeFMUstate", [&](Component&) {
    if (state != nullptr && *state != nullptr) {
      saved_state(*state);
      delete static_cast<SavedState*>(*state);
      *state = nullptr;
    }
    return fmi2OK;
  });
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
  return guarded(c, "fmi2SerializedFMUstateSize", [&](Component&) {
    if (size == nullptr) throw twin::ConfigError("size pointer is null");
    *size = twin::fmu::serialize_state(saved_state(state)).size();
    return fmi2OK;
  });
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
  return guarded(c, "fmi2SerializeFMUstate", [&](Component&) {
    if (bytes == nullptr) throw twin::ConfigError("byte array is null");
    const std::vector<char> b = twin::fmu::serialize_state(saved_state(state));
    if (b.size() != size)
      throw twin::ConfigError("buffer of " + std::to_string(size) + " bytes, the state has " + std::to_string(b.size()));
    std::memcpy(bytes, b.data(), b.size());
    return fmi2OK;
  });
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate* state) {
  return guarded(c, "fmi2DeSerializeFMUstate", [&](Component& comp) {
    if (bytes == nullptr || state == nullptr) throw twin::ConfigError("null argument");
    auto s = std::make_unique<SavedState>(twin::fmu::deserialize_state(bytes, size));
    comp.fmu->check_state(*s);
    if (*state != nullptr) {
      saved_state(*state);
      delete static_cast<SavedState*>(*state);
    }
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
    const std::int64_t n = comp.fmu->do_step(currentCommunicationPoint, communicationStepSize);
    log_call(comp, "fmi2DoStep",
             fmt::format("t = {} s, h = {} s: {} ticks run, {} in all", time_text(currentCommunicationPoint),
                         time_text(communicationStepSize), n, comp.fmu->ticks()));
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
  return guarded(c, "fmi2GetRealStatus", [&](Component& comp) {
    if (value == nullptr) throw twin::ConfigError("value pointer is null");
    *value = comp.fmu->time_s();
    return fmi2OK;
  });
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer*) {
  return status_not_provided(c, "fmi2GetIntegerStatus", s, "the FMU has no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
  if (s != fmi2Terminated) return status_not_provided(c, "fmi2GetBooleanStatus", s, "only fmi2Terminated is");
  return guarded(c, "fmi2GetBooleanStatus", [&](Component&) {
    if (value == nullptr) throw twin::ConfigError("value pointer is null");
    *value = fmi2False;
    return fmi2OK;
  });
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String*) {
  return status_not_provided(c, "fmi2GetStringStatus", s, "the FMU has no string status");
}

}  // extern "C"
