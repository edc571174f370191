#pragma once
/// The feed drives of all present axes, advanced together over one control
/// tick with u and Td held (zero-order hold). This is the interface the
/// co-simulation loop, replay, calibration, tuning and the FMU use.
/// SUNDIALS appears only in feeddrive/*.cpp.
#include <cstddef>
#include <memory>
#include <vector>

#include "feeddrive/drive_params.hpp"

namespace twin::feeddrive {

/// Continuous and discrete state of one axis. Plain data: copying it (with
/// DriveBank::state()) is how the FMU saves and restores its state.
struct DriveState {
  double x_mm{0.0};              ///< position (motor side times rg)
  double w_rad_per_s{0.0};       ///< motor speed
  bool stuck{true};              ///< held by static friction
  // Effect states (used only when the effect is on).
  double x_load_mm{0.0};         ///< compliance: load-side position
  double w_load_rad_per_s{0.0};  ///< compliance: load-side speed
  double x_table_mm{0.0};        ///< backlash: table position after the play
  bool load_stuck{true};         ///< compliance: load side held by static friction
  std::vector<double> u_delay_V; ///< delay: ring buffer of past commands
  std::size_t u_delay_head{0};
  // Energy accounting since reset, for the energy balance oracle (J = N m rad).
  double work_electrical_J{0.0};  ///< integral of Tm w dt (motor shaft power)
  double work_friction_J{0.0};    ///< integral of Tf w dt (>= 0)
  double work_damping_J{0.0};     ///< integral of B w^2 dt (+ C (w_m - w_l)^2 dt with compliance)
  double work_load_J{0.0};        ///< integral of (Td + constant load) w_load dt + cogging work
};

/// Held over one tick.
struct DriveInput {
  double u_V{0.0};    ///< amplifier command
  double Td_Nm{0.0};  ///< disturbance torque (cutting load), positive opposes +
};

/// What the drive reports at a tick boundary.
struct DriveOutput {
  double x_mm{0.0};            ///< true axis position (what the tool does)
  double x_meas_mm{0.0};       ///< position the sensor sees before quantisation (screw error, backlash)
  double w_rad_per_s{0.0};
  double v_mm_per_s{0.0};      ///< rg w (load side when compliant)
  double i_A{0.0};             ///< motor current for the command held over the last tick
  double Tm_Nm{0.0};           ///< motor torque
};

/// How the ODE is stepped. The default (ARKODE ERK, one fixed step of Ts per
/// tick, one instance for all axes, restarted every tick) is what
/// docs/feeddrive.md measured fastest and most accurate.
struct IntegratorOptions {
  enum class Method { kCvodeAdams, kCvodeBdf, kArkodeErk };
  Method method{Method::kArkodeErk};
  double rtol{1e-10};            ///< adaptive methods only
  double atol_mm{1e-8};          ///< on the position deviation within a segment
  double atol_rad_per_s{1e-9};
  bool reinit_every_tick{true};  ///< restart the multistep history at each ZOH jump
  /// One SUNDIALS instance integrating every moving axis together (true), or
  /// one instance per axis (false). Either way an axis held by static friction
  /// for a whole tick is not integrated at all, and with fixed ERK steps an
  /// axis whose smooth friction asks a finer step near rest has its own.
  bool one_instance_for_all_axes{true};
  /// ARKODE ERK only: 0 = adaptive steps under rtol/atol; n > 0 = fixed steps
  /// of Ts/n, refined further if an axis's fastest rate (compliance, Stribeck
  /// slope) would make Ts/n longer than 0.25 / rate. Smooth friction's slope
  /// Tc / (ws J) counts only on ticks where the axis can come within 10 ws
  /// of rest; on the others the step is the one without it.
  int erk_fixed_steps_per_tick{1};
  /// Advance a rigid axis that slides through the whole tick with no
  /// nonlinear effect in closed form (the zero-order-hold matrix exponential
  /// of its linear drive, precomputed for Ts) instead of handing it to
  /// SUNDIALS. Ticks with an event (start from rest, a stop or reversal
  /// anywhere near the tick, a current clamp) and axes with Stribeck,
  /// cogging, compliance or position-dependent friction always go to SUNDIALS.
  /// docs/feeddrive.md gives the test that holds both paths to 1e-9 mm.
  bool exact_linear_ticks{true};
};

class DriveBank {
 public:
  /// One entry per present axis, in the caller's order. Validates params.
  DriveBank(std::vector<DriveParams> axes, double Ts_s, IntegratorOptions options = {});
  ~DriveBank();
  DriveBank(DriveBank&&) noexcept;
  DriveBank& operator=(DriveBank&&) noexcept;
  DriveBank(const DriveBank&) = delete;
  DriveBank& operator=(const DriveBank&) = delete;

  std::size_t size() const noexcept;
  /// Puts every axis at rest (stuck) at the given positions; clears energies.
  void reset(const std::vector<double>& x0_mm);
  /// Advances all axes from t_from_s to t_to_s with inputs held. Throws
  /// SolverError (axis, time, flag) if the integrator fails and ModelError
  /// if a state becomes non-finite.
  void advance(double t_from_s, double t_to_s, const std::vector<DriveInput>& inputs);
  /// Output of axis i for the inputs held over the tick just integrated.
  DriveOutput output(std::size_t i) const;
  const DriveState& state(std::size_t i) const;
  const std::vector<DriveState>& states() const;
  void set_states(const std::vector<DriveState>& states);
  const DriveParams& params(std::size_t i) const;
  /// Integrator statistics since construction (steps, rhs evaluations).
  long num_steps() const noexcept;
  long num_rhs_evals() const noexcept;
  /// Axis-ticks advanced in closed form (IntegratorOptions::exact_linear_ticks)
  /// and axis-ticks handed to SUNDIALS, since construction. Axes stuck for a
  /// whole tick count in neither.
  long num_closed_form_ticks() const noexcept;
  long num_sundials_ticks() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Kinetic energy of axis i (0.5 J w^2 plus load side), for the energy balance.
double kinetic_energy_J(const DriveParams& p, const DriveState& s);
/// Elastic energy of the compliance spring, 0.5 K (theta_m - theta_l)^2 (0 when
/// compliance is off). Energy balance:
/// work_electrical = work_friction + work_damping + work_load + delta(kinetic + spring).
double spring_energy_J(const DriveParams& p, const DriveState& s);

}  // namespace twin::feeddrive
