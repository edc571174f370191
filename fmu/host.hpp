#pragma once
/// What the FMI 2.0 and FMI 3.0 Co-Simulation adapters share around a
/// Slave: the call states both standards define for Co-Simulation (and the
/// calls each state allows), the log categories, one-line logging of every
/// failed call, and guarded(), which keeps every exception on this side of
/// the C boundary. An adapter only converts its C types and names.
///
/// States and the calls each allows (others are errors with a log line):
///   instantiated    set experiment, Set* (parameters, inputs), enter initialization
///   initialization  Set*, Get*, exit initialization (starts the slave)
///   step mode       Set* (inputs, tunable gains), Get*, DoStep, Get/Set FMU state, Terminate
///   terminated      Get*, Get/Set FMU state
///   error           Get*, Reset, Set FMU state; FreeInstance everywhere.
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "fmu/slave.hpp"
#include "twin/core/error.hpp"

namespace twin::fmu {

enum class CallState : std::int32_t { kInstantiated, kInitialization, kStepMode, kTerminated, kError };
const char* call_state_name(CallState s);

/// Call results, numbered as fmi2Status and fmi3Status number them.
enum class Status { kOk = 0, kWarning = 1, kDiscard = 2, kError = 3, kFatal = 4 };

/// The log categories of modelDescription.xml, as bits.
enum LogCategory : unsigned {
  kLogCalls = 1u,
  kLogStatusWarning = 2u,
  kLogStatusDiscard = 4u,
  kLogStatusError = 8u,
  kLogStatusFatal = 16u,
};
inline constexpr unsigned kAllCategories =
    kLogCalls | kLogStatusWarning | kLogStatusDiscard | kLogStatusError | kLogStatusFatal;
/// The bits of `n` category names (all of them for n = 0). Throws
/// ConfigError naming an unknown one.
unsigned category_bits(std::size_t n, const char* const names[]);

/// Where an instance's log lines go: status, category name, message.
using LogSink = std::function<void(Status, const char* category, const std::string& message)>;

/// "function: what", without repeating a "function: " that `what` already starts with.
std::string with_function(const char* function, const std::string& what);

class Instance {
 public:
  Instance(std::string name, LogSink sink, bool logging_on, std::unique_ptr<Slave> slave)
      : name_(std::move(name)), sink_(std::move(sink)), categories_(logging_on ? kAllCategories : 0u),
        slave_(std::move(slave)) {}

  const std::string& name() const noexcept { return name_; }
  Slave& slave() noexcept { return *slave_; }
  const Slave& slave() const noexcept { return *slave_; }
  CallState state() const noexcept { return state_; }

  /// Throws ConfigError unless the instance is in one of `allowed`.
  void require(std::initializer_list<CallState> allowed) const;
  /// Moves the instance to the error state (after any failed call).
  void fail() noexcept;

  void set_logging(bool on, unsigned bits) { categories_ = on ? (categories_ | bits) : (categories_ & ~bits); }
  /// Errors and fatal errors are always logged (a failed call without its
  /// reason helps nobody); the other categories only when enabled.
  void emit(Status status, unsigned category, const std::string& message) const;
  void log_error(Status status, const char* function, const std::string& what) const;
  /// A call that changed the state, for category logCalls.
  void log_call(const char* function, const std::string& what) const;
  bool logs_calls() const noexcept { return (categories_ & kLogCalls) != 0; }

  // The calls both standards have, each checking the call state.
  void set_experiment(double start_s, std::optional<double> stop_s);
  void enter_initialization();
  void exit_initialization();
  std::int64_t do_step(double t_s, double h_s);
  void terminate();
  void reset();
  /// Get* are allowed from initialization on, Set* until step mode.
  void require_get() const;
  void require_set() const;

  std::unique_ptr<SavedState> save() const;
  void restore(const SavedState& s);
  /// Throws ConfigError unless `s` is a state this instance can restore.
  void check_state(const SavedState& s) const;

 private:
  std::string name_;
  LogSink sink_;
  unsigned categories_{0};
  CallState state_{CallState::kInstantiated};
  std::unique_ptr<Slave> slave_;
};

/// The saved state behind an FMI state handle; throws ConfigError for a
/// null one or one not made by this FMU.
const SavedState& saved_state(const void* handle);

// The FMU-state calls of both standards over opaque handles (fmi2FMUstate,
// fmi3FMUState): each throws ConfigError for a null pointer or a handle
// that is not this FMU's (never freed or overwritten then).
void get_state(const Instance& inst, void** handle);
void set_state(Instance& inst, const void* handle);
void free_state(void** handle);
std::size_t serialized_state_size(const void* handle);
void serialize_state(const void* handle, char* bytes, std::size_t size);
void deserialize_state(const Instance& inst, const char* bytes, std::size_t size, void** handle);

/// Runs `f(instance)`; turns its exceptions into a status and one log line
/// (Discard: nothing changed; ConfigError and others: the error state;
/// InternalError: fatal) and the slave's warnings into Warning.
template <class F>
Status guarded(Instance* inst, const char* function, F&& f) noexcept {
  if (inst == nullptr) return Status::kError;
  try {
    Status status = f(*inst);
    for (const std::string& w : inst->slave().take_warnings()) {
      inst->emit(Status::kWarning, kLogStatusWarning, with_function(function, w));
      if (status == Status::kOk) status = Status::kWarning;
    }
    return status;
  } catch (const Discard& e) {
    inst->slave().take_warnings();
    inst->emit(Status::kDiscard, kLogStatusDiscard, with_function(function, e.what()));
    return Status::kDiscard;
  } catch (const InternalError& e) {
    inst->fail();
    inst->log_error(Status::kFatal, function, e.what());
    return Status::kFatal;
  } catch (const std::exception& e) {
    inst->fail();
    inst->log_error(Status::kError, function, e.what());
    return Status::kError;
  } catch (...) {
    inst->fail();
    inst->log_error(Status::kFatal, function, "unknown exception");
    return Status::kFatal;
  }
}

/// A value as the logCalls lines write it.
inline std::string value_text(double v) { return fmt::format("{}", v); }
inline std::string value_text(int v) { return std::to_string(v); }
inline std::string value_text(bool v) { return v ? "true" : "false"; }

/// Get*: value[i] = get(slave, vr[i]) for each of the nvr references.
template <class VR, class T, class Get>
void get_values(const Instance& inst, const VR vr[], std::size_t nvr, T value[], Get get) {
  inst.require_get();
  if (nvr > 0 && (vr == nullptr || value == nullptr)) throw ConfigError("null array");
  for (std::size_t i = 0; i < nvr; ++i) value[i] = get(inst.slave(), vr[i]);
}

/// Set*: set(slave, vr[i], value[i]) for each of the nvr references, then
/// one logCalls line naming them.
template <class VR, class T, class Set>
void set_values(Instance& inst, const char* function, const VR vr[], std::size_t nvr, const T value[], Set set) {
  inst.require_set();
  if (nvr > 0 && (vr == nullptr || value == nullptr)) throw ConfigError("null array");
  for (std::size_t i = 0; i < nvr; ++i) set(inst.slave(), vr[i], value[i]);
  if (inst.logs_calls() && nvr > 0) {
    std::string what;
    for (std::size_t i = 0; i < nvr; ++i)
      what += fmt::format("{}{} = {}", i > 0 ? ", " : "", inst.slave().variables()[vr[i]].name, value_text(value[i]));
    inst.log_call(function, what);
  }
}

/// The text of a file (resources/model.json); throws IoError.
std::string read_text(const std::string& path);

/// The FMU's model read from `resources` (a folder) and checked against the
/// identity the master passed (`what` names it in the message: "GUID",
/// "instantiationToken"); `expected` computes this FMU's identity.
/// Returns the slave. Throws ConfigError on a mismatch.
std::unique_ptr<Slave> make_slave(const std::string& resources, const char* given, const char* what,
                                  std::string (*expected)(const FmuModel&));

}  // namespace twin::fmu
