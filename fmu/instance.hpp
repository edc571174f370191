#pragma once
/// One FMU instance: the call-sequence state machine of FMI 2.0 Co-Simulation
/// around one twin::sim::CoSimulation. Everything an instance uses it owns;
/// two instances share nothing.
///
/// States and the calls each allows (others return fmi2Error with a log line):
///   instantiated    SetupExperiment, Set* (parameters, inputs), EnterInitializationMode
///   initialization  Set*, Get*, ExitInitializationMode (builds the co-simulation)
///   step mode       Set* (inputs, tunable gains), Get*, DoStep, Get/Set FMU state, Terminate
///   terminated      Get*, Get/Set FMU state
///   error           Get*, Reset, SetFMUstate; FreeInstance everywhere.
/// DoStep(t, h): t must be the communication point reached by the last step
/// (the start time before the first), within 1e-9 max(1, |t|); h > 0 need
/// not be a whole number of ticks. The step runs every controller tick that
/// starts in [t, t + h) (tick start times within 1e-9 max(1, |t + h|) of
/// t + h count as t + h), each with the inputs set at the last communication
/// point at or before its start. The outputs afterwards are the row of the
/// last tick started before t + h. A step that would run more than
/// kMaxTicksPerStep ticks is refused (Discard, nothing changes); a step
/// ending past a stop time given to SetupExperiment is an error.
#include <array>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "fmu/model.hpp"
#include "fmu/variables.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::fmu {

enum class FmuMode { kInstantiated, kInitialization, kStepMode, kTerminated, kError };

/// The most controller ticks one fmi2DoStep runs (1e6: 100 s of machine time
/// at Ts = 1e-4 s). A longer step is refused before anything runs, so that a
/// master's mistaken step (1e5 s) returns at once instead of computing for
/// hours (docs/fmu.md gives the cost per tick).
inline constexpr std::int64_t kMaxTicksPerStep = 1'000'000;

/// A call the FMU refuses without changing anything (fmi2Discard): the
/// instance stays usable and the master may retry differently.
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

/// Marks a SavedState made by this FMU (the first member of every state).
inline constexpr std::uint64_t kStateMagic = 0x54574e4653544132ull;  // "TWNFSTA2"

/// What fmi2GetFMUstate saves. `guid` ties it to the FMU that made it:
/// another FMU's state (another scenario, machine or parameter set) is
/// refused on set and deserialize.
struct SavedState {
  std::uint64_t magic{kStateMagic};
  std::string guid;
  FmuMode mode{FmuMode::kInstantiated};
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
/// origin and consistency are checked by FmuInstance::check_state).
SavedState deserialize_state(const char* data, std::size_t size);

class FmuInstance {
 public:
  /// @throws ConfigError when the model cannot be read. `guid` is the FMU's
  /// GUID (model_guid(model) when empty).
  FmuInstance(std::string instance_name, FmuModel model, std::string guid = {});

  const std::string& name() const noexcept { return name_; }
  const std::string& guid() const noexcept { return guid_; }
  const FmuModel& model() const noexcept { return model_; }
  const std::vector<Variable>& variables() const noexcept { return vars_; }
  FmuMode mode() const noexcept { return mode_; }
  double Ts_s() const noexcept { return machine_.Ts_s; }
  /// The communication point reached (fmi2LastSuccessfulTime).
  double time_s() const noexcept { return t_comm_s_; }
  /// Ticks run so far.
  std::int64_t ticks() const noexcept;

  // Each throws ConfigError (bad argument: logged, fmi2Error) with the numbers.
  void setup_experiment(double start_s, bool stop_defined, double stop_s);
  void enter_initialization();
  void exit_initialization();
  /// Returns the number of ticks run. Throws Discard for a step the FMU
  /// refuses without changing anything (too many ticks).
  std::int64_t do_step(double t_s, double h_s);
  void terminate();
  void reset();

  double get_real(std::size_t vr) const;
  int get_integer(std::size_t vr) const;
  bool get_boolean(std::size_t vr) const;
  void set_real(std::size_t vr, double value);
  void set_integer(std::size_t vr, int value);
  void set_boolean(std::size_t vr, bool value);
  /// The row of `vr` checked against `type`; throws ConfigError naming the reference.
  const Variable& variable(std::size_t vr, VarType type) const;

  SavedState save() const;
  void restore(const SavedState& s);
  /// Throws ConfigError unless `s` was made by this FMU
  /// and is consistent: its GUID, a known call state, mode 1 or 2, the
  /// parameter table's size with finite values the machine accepts, tick
  /// counter >= 0 matching the times, one drive and loop state per axis.
  void check_state(const SavedState& s) const;

  /// Warnings collected since the last call (logged by the caller, which
  /// then returns fmi2Warning).
  std::vector<std::string> take_warnings() { return std::exchange(warnings_, {}); }

  /// Moves the instance to the error state (after any failed call).
  void fail() noexcept { mode_ = FmuMode::kError; }
  /// Throws ConfigError unless the instance is in one of `allowed`.
  void require(std::initializer_list<FmuMode> allowed) const;

 private:
  std::vector<double> parameter_values() const;
  void apply_parameter_values(const std::vector<double>& values);
  void build_cosim();
  sim::Snapshot current_row() const;
  void warn_ignored_reference(const char* when);

  std::string name_;
  FmuModel model_;
  std::string guid_;
  std::vector<Variable> vars_;
  sim::MachineDefinition machine_;
  FmuMode mode_{FmuMode::kInstantiated};
  int reference_mode_{kModeProgram};
  InputValues inputs_;
  double t_start_s_{0.0};
  double t_comm_s_{0.0};
  bool stop_defined_{false};
  double stop_s_{0.0};
  bool machine_changed_{false};
  std::vector<std::string> warnings_;
  std::shared_ptr<sim::ExternalReference> external_;
  std::unique_ptr<sim::CoSimulation> cosim_;
};

const char* mode_name(FmuMode m);

}  // namespace twin::fmu
