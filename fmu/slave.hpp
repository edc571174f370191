#pragma once
/// The twin as a co-simulation slave, with no FMI version in it: the
/// variable table, get/set by value reference, communication steps over the
/// controller's ticks, state save/restore and its bytes. The FMI 2.0 and FMI
/// 3.0 adapters (fmi2_functions.cpp, fmi3_functions.cpp, over fmu/host.hpp)
/// translate their C calls into these; everything a slave uses it owns, so
/// two slaves share nothing.
///
/// Life: configure (parameters, `mode`, inputs, set_experiment), start()
/// (builds the co-simulation at the start time), step() any number of
/// times; reset() goes back to the model's values. Before start() every
/// parameter may be set; while running only the tunable ones (the loop
/// gains) and the inputs.
///
/// step(t, h): t must be the communication point reached by the last step
/// (the start time before the first), within 1e-9 max(1, |t|); h > 0 need
/// not be a whole number of ticks (whole_ticks() says whether it is). The
/// step runs every controller tick that starts in [t, t + h) (tick start
/// times within 1e-9 max(1, |t + h|) of t + h count as t + h), each with the
/// inputs set at the last communication point at or before its start. The
/// outputs afterwards are the row of the last tick started before t + h. A
/// step that would run more than kMaxTicksPerStep ticks is refused (Discard,
/// nothing changes); a step ending past the experiment's stop time is an
/// error.
///
/// Errors: every refused call throws ConfigError with the numbers (the
/// adapter logs it and returns its Error status), Discard when nothing
/// changed and the caller may retry differently, InternalError for a fault
/// of the model itself.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "fmu/model.hpp"
#include "fmu/variables.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::fmu {

/// The most controller ticks one communication step runs (1e6: 100 s of
/// machine time at Ts = 1e-4 s). A longer step is refused before anything
/// runs, so that a master's mistaken step (1e5 s) returns at once instead of
/// computing for hours (docs/fmu.md gives the cost per tick).
inline constexpr std::int64_t kMaxTicksPerStep = 1'000'000;

/// A call refused without changing anything: the slave stays usable and the
/// master may retry differently.
class Discard : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Values of the inputs (held over each communication step).
struct InputValues {
  AxisArray<double> x_ref_mm{};
  std::array<double, 3> F_ext_N{};
  double spindle_rpm{0.0};
  bool spindle_override{false};
};

/// Marks a SavedState made by a slave (the first member of every state).
inline constexpr std::uint64_t kStateMagic = 0x54574e4653544132ull;  // "TWNFSTA2"

/// What Slave::save() keeps. `identity` ties it to the FMU that made it:
/// another FMU's state (another scenario, machine or parameter set) is
/// refused on restore and deserialize. `host_state` belongs to the adapter
/// (its call state); the slave keeps it with the state without reading it.
struct SavedState {
  std::uint64_t magic{kStateMagic};
  std::string identity;
  std::int32_t host_state{0};
  int reference_mode{kModeProgram};
  std::vector<double> parameters;     ///< Real parameters in table order
  InputValues inputs;
  double t_start_s{0.0};
  double t_comm_s{0.0};               ///< communication point reached
  bool stop_defined{false};
  double stop_s{0.0};
  bool has_cosim{false};
  sim::CoSimState cosim;
};

/// Bytes of a SavedState (no process: an air cut), and back.
std::vector<char> serialize_state(const SavedState& s);
/// @throws ConfigError when the bytes are not a state of this format (the
/// origin and consistency are checked by Slave::check_state).
SavedState deserialize_state(const char* data, std::size_t size);

class Slave {
 public:
  /// @throws ConfigError when the model cannot be read. `identity` names the
  /// FMU in its saved states (the GUID or instantiation token).
  Slave(FmuModel model, std::string identity);

  const std::string& identity() const noexcept { return identity_; }
  const FmuModel& model() const noexcept { return model_; }
  const std::vector<Variable>& variables() const noexcept { return vars_; }
  double Ts_s() const noexcept { return machine_.Ts_s; }
  /// True between start() and reset(): the co-simulation exists.
  bool running() const noexcept { return cosim_ != nullptr; }
  /// The communication point reached (the start time before the first step).
  double time_s() const noexcept { return t_comm_s_; }
  /// Ticks run so far.
  std::int64_t ticks() const noexcept;

  // Each throws ConfigError (a bad argument or a call out of turn) with the numbers.
  /// Start and optional stop time; before start() only.
  void set_experiment(double start_s, std::optional<double> stop_s);
  /// Builds the co-simulation with the parameters and mode as set now.
  void start();
  /// Returns the number of ticks run. Throws Discard for a step the slave
  /// refuses without changing anything (too many ticks).
  std::int64_t step(double t_s, double h_s);
  /// True when h_s is a whole number (>= 1) of controller ticks, within the
  /// tolerance step() gives the end of a step.
  bool whole_ticks(double t_s, double h_s) const;
  /// Back to the model's values, not running.
  void reset();

  double get_real(std::size_t vr) const;
  int get_integer(std::size_t vr) const;
  bool get_boolean(std::size_t vr) const;
  void set_real(std::size_t vr, double value);
  void set_integer(std::size_t vr, int value);
  void set_boolean(std::size_t vr, bool value);
  /// The row of `vr` checked against `type`; throws ConfigError naming the reference.
  const Variable& variable(std::size_t vr, VarType type) const;

  SavedState save(std::int32_t host_state) const;
  void restore(const SavedState& s);
  /// Throws ConfigError unless `s` was made by this FMU and is consistent:
  /// its identity, mode 1 or 2, the parameter table's size with finite
  /// values the machine accepts, tick counter >= 0 matching the times, one
  /// drive and loop state per axis.
  void check_state(const SavedState& s) const;

  /// Warnings collected since the last call (logged by the caller, which
  /// then returns its Warning status).
  std::vector<std::string> take_warnings() { return std::exchange(warnings_, {}); }
  /// Called after a call that failed part-way: the co-simulation may hold
  /// half a tick, so the next restore() builds it afresh.
  void mark_failed() noexcept { failed_ = true; }

 private:
  std::vector<double> parameter_values() const;
  void apply_parameter_values(const std::vector<double>& values);
  void build_cosim();
  sim::Snapshot current_row() const;
  void warn_ignored_reference(const char* when);
  /// Ticks to run so that every tick starting before t_end_s has run.
  double ticks_to(double t_end_s) const;

  FmuModel model_;
  std::string identity_;
  std::vector<Variable> vars_;
  sim::MachineDefinition machine_;
  int reference_mode_{kModeProgram};
  InputValues inputs_;
  double t_start_s_{0.0};
  double t_comm_s_{0.0};
  bool stop_defined_{false};
  double stop_s_{0.0};
  bool machine_changed_{false};
  bool failed_{false};
  std::vector<std::string> warnings_;
  std::shared_ptr<sim::ExternalReference> external_;
  std::unique_ptr<sim::CoSimulation> cosim_;
};

}  // namespace twin::fmu
