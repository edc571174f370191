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
///   error           Get*, Reset; FreeInstance everywhere.
/// DoStep(t, h): t must be t_start + k Ts (k = ticks run so far), within
/// 1e-9 max(1, |t|); h must be n Ts with n >= 1 whole, within 1e-9 max(1, h).
/// It runs n ticks of the co-simulation with the inputs held. The outputs
/// afterwards are the row of the last tick run (time t + h - Ts).
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fmu/model.hpp"
#include "fmu/variables.hpp"
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::fmu {

enum class FmuMode { kInstantiated, kInitialization, kStepMode, kTerminated, kError };

/// Values of the inputs (held over each communication step).
struct InputValues {
  AxisArray<double> x_ref_mm{};
  std::array<double, 3> F_ext_N{};
  double spindle_rpm{0.0};
  bool spindle_override{false};
};

/// What fmi2GetFMUstate saves.
struct SavedState {
  FmuMode mode{FmuMode::kInstantiated};
  int reference_mode{kModeProgram};
  std::vector<double> parameters;     ///< Real parameters in table order
  InputValues inputs;
  double t_start_s{0.0};
  bool has_cosim{false};
  sim::CoSimState cosim;
};

/// Bytes of a SavedState (no process: an air cut), and back.
std::vector<char> serialize_state(const SavedState& s);
/// @throws ConfigError when the bytes are not a state of this format.
SavedState deserialize_state(const char* data, std::size_t size);

class FmuInstance {
 public:
  /// @throws ConfigError when the model cannot be read.
  FmuInstance(std::string instance_name, FmuModel model);

  const std::string& name() const noexcept { return name_; }
  const FmuModel& model() const noexcept { return model_; }
  const std::vector<Variable>& variables() const noexcept { return vars_; }
  FmuMode mode() const noexcept { return mode_; }
  double Ts_s() const noexcept { return machine_.Ts_s; }
  /// Time of the next communication point.
  double time_s() const noexcept;

  // Each throws ConfigError (bad argument: logged, fmi2Error) with the numbers.
  void setup_experiment(double start_s);
  void enter_initialization();
  void exit_initialization();
  void do_step(double t_s, double h_s);
  void terminate();
  void reset();

  double get_real(std::size_t vr) const;
  int get_integer(std::size_t vr) const;
  bool get_boolean(std::size_t vr) const;
  void set_real(std::size_t vr, double value);
  void set_integer(std::size_t vr, int value);
  void set_boolean(std::size_t vr, bool value);
  /// The row of `vr` checked against `type`; throws ConfigError naming the reference.
  const Variable& variable(std::size_t vr, VarType type, const char* function) const;

  SavedState save() const;
  void restore(const SavedState& s);

  /// Moves the instance to the error state (after any failed call).
  void fail() noexcept { mode_ = FmuMode::kError; }
  void require(const char* function, std::initializer_list<FmuMode> allowed) const;

 private:
  std::vector<double> parameter_values() const;
  void apply_parameter_values(const std::vector<double>& values);
  void build_cosim();
  sim::Snapshot current_row() const;

  std::string name_;
  FmuModel model_;
  std::vector<Variable> vars_;
  sim::MachineDefinition machine_;
  FmuMode mode_{FmuMode::kInstantiated};
  int reference_mode_{kModeProgram};
  InputValues inputs_;
  double t_start_s_{0.0};
  bool machine_changed_{false};
  std::shared_ptr<sim::ExternalReference> external_;
  std::unique_ptr<sim::CoSimulation> cosim_;
};

const char* mode_name(FmuMode m);

}  // namespace twin::fmu
