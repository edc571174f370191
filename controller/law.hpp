#pragma once
/// A position-loop law: everything the twin asks of one (see docs/architecture.md,
/// "The position-loop law"):
///  - its step at a tick (controller::PositionLoop calls it, no allocation);
///  - the validation of its gains;
///  - its gains as a named vector (the machine file, the report and `twin tune`);
///  - its controller at Ts as a discrete state-space system (the linear analysis,
///    twin/tune/linear_analysis.hpp).
/// Each law lives in controller/laws/<name>.{hpp,cpp}; law_of() (law.cpp) registers it.
#include <initializer_list>
#include <span>
#include <utility>
#include <string>
#include <string_view>

#include <Eigen/Dense>

#include "controller/position_loop.hpp"

namespace twin::controller {

/// The linearised drive a law's controller is analysed against: only the terms that
/// survive linearisation (Ozcan 2017 Fig. 1: J dw/dt = Ka Kt u - B w, dx/dt = rg w),
/// and a dead time on the command and a compliant coupling where the drive has them.
struct LinearPlant {
  double Ka_A_per_V{0.0};
  double Kt_Nm_per_A{0.0};
  double J_kg_m2{0.0};
  double B_kg_m2_per_s{0.0};
  double rg_mm_per_rad{0.0};
  /// A dead time on the command (the drive's `delay` effect), whole drive steps.
  double command_delay_s{0.0};
  /// A compliant coupling (the drive's `compliance` effect): the share of J on the
  /// load side behind a torsional spring and damper; 0: a rigid drive. The loop
  /// measures the motor's side.
  double load_fraction{0.0};
  double K_Nm_per_rad{0.0};
  double C_Nm_s_per_rad{0.0};
  /// Throws ConfigError naming `where` and the field when a value is not finite or not physical.
  void validate(const std::string& where) const;
};

/// One gain of a law, as the machine file, the report and the tuning name it.
struct LawGain {
  std::string_view name;      ///< machine-file name: Kp, Kv, ...
  std::string_view json_key;  ///< report name with its unit: Kp_V_per_mm, Kv_per_s, ...
  std::string_view unit;
  /// A feedforward gain acts outside the loop: it moves neither poles nor margins.
  bool feedforward{false};
  /// Whether `twin tune` searches it (feedback: in log ratio to its start; feedforward:
  /// as a fraction of its model value).
  bool searched{false};
  double& (*ref)(PositionLoopParams&){nullptr};
  /// Feedforward only: the value that cancels the linear plant.
  double (*model)(const LinearPlant&){nullptr};
  /// Feedback only: the base of the log search when the start is 0 (nullptr: a gain
  /// that is 0 stays 0, e.g. no integral).
  double (*base_when_zero)(const PositionLoopParams&){nullptr};
  double get(PositionLoopParams g) const { return ref(g); }
};

/// A law's controller at Ts as a discrete linear system (limits out):
///   c[k+1] = Ac c[k] + By p[k] + Br r[k],   m[k] = Cc c[k] + Dy p[k] + Dr r[k],
/// p = [w, x] at tick k, r = x_ref[k], m the command held over the tick. The last
/// `reference_states` states (x_ref[k-1], v_ref[k-1]) are driven by r only: they
/// are not modes of the loop. A start at rest at x = 0 with x_ref[0] = r0 has
/// c[0] = start r0 (the law's start-up convention: v_ref, a_ref 0, e[-1] = e[0]).
///
/// A law whose inner loop runs inner_ticks > 1 times a period (the cascade's
/// velocity loop at Tv = Ts / n) is periodic: the system above is then its first
/// tick of a period, the command held over Tv, and `inner` its n - 1 ticks after
/// it, in the same states, reading the plant at that tick and no reference
/// (c[q+1] = inner.Ac c[q] + inner.By p[q], m[q] = inner.Cc c[q] + inner.Dy p[q]).
struct ControllerRealisation {
  Eigen::MatrixXd Ac;
  Eigen::MatrixXd By;         ///< n x 2
  Eigen::VectorXd Br;
  Eigen::RowVectorXd Cc;
  Eigen::RowVector2d Dy;
  double Dr{0.0};
  Eigen::VectorXd start;
  int reference_states{0};
  int inner_ticks{1};
  struct InnerTick {
    Eigen::MatrixXd Ac;
    Eigen::MatrixXd By;  ///< n x 2
    Eigen::RowVectorXd Cc;
    Eigen::RowVector2d Dy;
  } inner;
};

/// An axis in steady motion: the reference at v_ref, the motor at w, the drive needing
/// the torque B w + Tc to hold it.
struct SteadyMotion {
  double Ts_s{1e-4};
  double v_ref_mm_per_s{0.0};
  double w_rad_per_s{0.0};
  double torque_needed{0.0};
  DriveScale drive;
};

class Law {
 public:
  virtual ~Law() = default;
  virtual LoopLaw id() const noexcept = 0;
  /// The machine-file name: fadal, cascade.
  virtual std::string_view name() const noexcept = 0;
  /// ConfigError "<where>: <gain> = <value> must ..." for a gain out of range.
  virtual void validate(const PositionLoopParams& g, std::string_view where) const = 0;
  /// What the step needs beyond the gains (the period is validated by the caller).
  virtual LawSetup setup(const PositionLoopParams& g, double Ts_s, const DriveScale& drive) const;
  /// One tick: `out` holds e, v_ref and a_ref; the law fills the command and its terms
  /// and updates its own part of `s`.
  virtual void step(const PositionLoopParams& g, const LawSetup& setup, double x_meas_mm, double v_meas_mm_per_s,
                    PositionLoopState& s, PositionLoopOutput& out) const = 0;
  /// An inner tick after the first of a period (setup.inner_ticks > 1 only):
  /// the command again from the speed of that instant, the rest of `out` held.
  virtual void inner_step(const PositionLoopParams& g, const LawSetup& setup, double v_meas_mm_per_s,
                          PositionLoopState& s, PositionLoopOutput& out) const;

  /// The state that holds `m` with no transient at the reference x_ref_mm (the
  /// integrators giving what the feedforward does not); returns the position error
  /// e = x_ref - x_meas the law holds there. Sets the law's own part of `s`.
  virtual double steady_state(const PositionLoopParams& g, const SteadyMotion& m, double x_ref_mm,
                              PositionLoopState& s) const = 0;

  /// Its gains, feedback first; `twin tune` changes those marked searched.
  virtual std::span<const LawGain> gains() const noexcept = 0;
  /// The command it gives the drive: "u" in "V" (FADAL) or "torque" in the torque unit.
  virtual std::string_view command_name() const noexcept = 0;
  virtual std::string_view command_unit() const noexcept = 0;
  /// The machine-file name of its limit: u_max, T_max.
  virtual std::string_view command_limit_name() const noexcept = 0;
  /// Motor torque per unit of command (Ka Kt for V, 1 for a torque).
  virtual double torque_per_command(const LinearPlant& plant) const = 0;
  /// The limit of the command (u_max, T_max).
  virtual double command_limit(const PositionLoopParams& g) const = 0;
  /// Its controller at Ts from [w, x, x_ref] to the command (with its inner ticks
  /// where it runs several a period).
  virtual ControllerRealisation realise(const PositionLoopParams& g, double Ts_s, const LinearPlant& plant) const = 0;

  /// The gains with every feedforward gain at 0.
  PositionLoopParams feedback_only(const PositionLoopParams& g) const;
  /// "Kp 500 V/mm, Ki 70 V/(s mm), ..." (all gains, with `units`).
  std::string gains_text(const PositionLoopParams& g, bool units = false) const;
};

/// ConfigError "<where>: <name> = <value> must be finite" for the first value that is not.
void require_finite(std::string_view where, std::initializer_list<std::pair<const char*, double>> values);

/// The registered law of that id.
const Law& law_of(LoopLaw law) noexcept;

}  // namespace twin::controller
