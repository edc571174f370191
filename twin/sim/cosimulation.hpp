#pragma once
/// The co-simulation loop: the single owner of time (t = t0 + k Ts). Per tick
/// k, in this fixed order (docs/architecture.md):
///   1. read the drives at t_k: true position, sensor position, quantised by the encoder;
///   2. sample the reference r_k;
///   3. process: force over [t_k, t_k+1) from the tool's real pose and velocity at t_k;
///   4. position loops: u_k from r_k and the measured position;
///   5. drives: integrate [t_k, t_k+1) with u_k and Td_k = F_workpiece * rg / 1000 held;
///   6. record row k (currents and torques are those held over the tick); k <- k + 1.
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "controller/encoder.hpp"
#include "controller/position_loop.hpp"
#include "feeddrive/drive_bank.hpp"
#include "process/process_model.hpp"
#include "twin/sim/machine.hpp"
#include "twin/sim/reference.hpp"

namespace twin::sim {

/// An axis's current, torque and commanded torque, each its mean over a
/// position-loop period's inner ticks (AxisSnapshot::period_mean).
struct PeriodMean {
  double i_A{0.0}, Tm_Nm{0.0}, Tcmd_Nm{0.0};
};

/// Everything the twin reports at tick k: one row of trace.csv.
struct AxisSnapshot {
  double x_ref_mm{0.0};
  double x_mm{0.0};          ///< measured (encoder) position fed back
  double x_true_mm{0.0};     ///< true tool position on this axis
  double e_mm{0.0};          ///< tracking error x_ref - x_mm (as the loop sees it)
  double u_V{0.0};
  double i_A{0.0};
  double Tm_Nm{0.0};
  double Tcmd_Nm{0.0};       ///< the torque the loop commands, before the current loop and any delay
  double Td_Nm{0.0};         ///< cutting load torque held over the tick
  double v_mm_per_s{0.0};    ///< true axis speed
  double vcmd_mm_per_s{0.0}; ///< cascade law: the position loop's velocity command (0 for the FADAL law)
  /// i_A, Tm_Nm and Tcmd_Nm as their means over the position-loop period
  /// that ends at t_k, over its inner (velocity-loop) ticks: what a drive
  /// that logs a period's mean gives at this row. At k = 0 (no period
  /// before it), the row's own.
  PeriodMean period_mean;
  bool saturated{false};
};
struct Snapshot {
  std::int64_t k{0};
  double t_s{0.0};
  AxisArray<AxisSnapshot> axes{};
  std::array<double, 3> F_N{};       ///< force on the workpiece, instantaneous at t_k
  std::array<double, 3> F_avg_N{};   ///< tick average (what the drives see)
  double spindle_rpm{0.0};
  double engagement_deg{0.0};
  double chip_mm{0.0};
  double spindle_torque_Nm{0.0};
  double cutting_power_W{0.0};
  /// A vibrating tool (a machine with structure and tool-tip modes): the
  /// tool's deflection at t_k and the last surface location error (process/milling_process.hpp).
  bool tool_modes{false};
  std::array<double, 2> tool_deflection_um{};
  double sle_um{0.0};
  double feed_programmed_mm_per_min{0.0};
  double feed_ref_mm_per_min{0.0};   ///< speed of the reference along the path
  double feed_real_mm_per_min{0.0};  ///< speed of the real tool
  double contour_error_mm{0.0};      ///< distance of the real tool from the reference path (normal component)
  int block{-1};
  bool reference_done{false};
};

/// Per axis, the watch for a limit cycle bounded by the command clamp.
struct ClampWatch {
  int ticks_in_block{0};
  int saturated_ticks{0};
  int flips{0};
  int bad_blocks{0};
};

/// The whole mutable state, for FMU get/set state and retries.
struct CoSimState {
  std::int64_t k{0};
  std::vector<feeddrive::DriveState> drives;
  std::vector<controller::PositionLoopState> loops;
  std::shared_ptr<const process::ProcessModel> process;
  Snapshot last;
  std::vector<ClampWatch> clamp_watch;
  std::vector<PeriodMean> period_mean;  ///< per axis, the period before tick k (empty: none stepped)
};

class CoSimulation {
 public:
  /// `process` may be null (an air cut). `x0_mm` is where every axis starts, at rest.
  CoSimulation(MachineDefinition machine, std::shared_ptr<const ReferenceSource> reference,
               std::unique_ptr<process::ProcessModel> process, const AxisArray<double>& x0_mm,
               feeddrive::IntegratorOptions options = {});
  ~CoSimulation();
  CoSimulation(CoSimulation&&) noexcept;
  CoSimulation& operator=(CoSimulation&&) noexcept;

  std::int64_t tick() const noexcept { return k_; }
  double time_s() const noexcept { return t0_s_ + static_cast<double>(k_) * machine_.Ts_s; }
  double Ts_s() const noexcept { return machine_.Ts_s; }
  const MachineDefinition& machine() const noexcept { return machine_; }
  /// What the position loop of the i-th present axis computed from its law at construction.
  const controller::LawSetup& loop_setup(std::size_t i) const { return loops_.at(i).setup(); }
  const std::vector<Axis>& axes() const noexcept { return axes_; }

  /// Runs tick k (steps 1-6 above) and returns its row; afterwards tick() == k + 1.
  /// Throws ModelError naming axis, time and error if an axis runs away
  /// (following error beyond its limit, non-finite state).
  const Snapshot& step();
  /// The last row produced by step() (k = tick() - 1).
  const Snapshot& last() const noexcept { return last_; }

  /// Inputs a system-level master may set (FMU): a force on the workpiece
  /// added to the cutting force, and a spindle speed replacing the program's.
  void set_external_force_N(const std::array<double, 3>& F_N) noexcept { F_ext_N_ = F_N; }
  void set_spindle_override_rpm(std::optional<double> rpm) noexcept { spindle_override_rpm_ = rpm; }
  void set_reference(std::shared_ptr<const ReferenceSource> reference);
  const ReferenceSource& reference() const noexcept { return *reference_; }

  /// Work terms of the energy balance of axis a since the start (J).
  const feeddrive::DriveState& drive_state(Axis a) const;
  const feeddrive::DriveParams& drive_params(Axis a) const;

  CoSimState get_state() const;
  void set_state(const CoSimState& state);

 private:
  /// Step 3: the process over [t_k, t_k+1) into `row`; returns the force the drives see.
  std::array<double, 3> run_process(Snapshot& row, const std::array<double, 3>& p_mm,
                                    const std::array<double, 3>& v_mm_per_s);
  /// Step 6's health checks of axis i (runaway, command limit cycle).
  void check_axis(std::size_t i, const AxisSnapshot& s, const feeddrive::DriveOutput& out, double t_s);
  /// The speed axis i's loop feeds back: the motor's (rg w), which behind a compliant
  /// coupling is not the load's (DriveOutput::v_mm_per_s).
  double motor_speed_mm_per_s(std::size_t i, const feeddrive::DriveOutput& out) const {
    return drives_.params(i).rg_mm_per_rad * out.w_rad_per_s;
  }

  MachineDefinition machine_;
  std::vector<Axis> axes_;
  std::shared_ptr<const ReferenceSource> reference_;
  std::unique_ptr<process::ProcessModel> process_;
  /// The drives' ticks per period: the least common multiple of the axes'
  /// inner (velocity-loop) ticks, 1 where every loop runs at Ts.
  int inner_ticks_{1};
  feeddrive::DriveBank drives_;
  std::vector<controller::PositionLoop> loops_;
  controller::Encoder encoder_;
  std::vector<feeddrive::DriveInput> inputs_;
  std::int64_t k_{0};
  double t0_s_{0.0};
  std::array<double, 3> F_ext_N_{};
  std::optional<double> spindle_override_rpm_;
  Snapshot last_;
  /// Per axis of axes_: the means over the period just stepped, given
  /// with the next row (not valid before the first step).
  std::vector<PeriodMean> period_mean_;
  bool period_mean_valid_{false};
  std::vector<ClampWatch> clamp_watch_;
};

/// The reference of an axis where a simulation starts in steady motion:
/// its position at the starting tick k0 and at the two ticks before (the
/// law's own backward-difference speed), and its speed at k0.
struct ReferenceAtStart {
  double x_mm{0.0}, x_prev_mm{0.0}, x_prev2_mm{0.0};
  double v_mm_per_s{0.0};
};

/// Puts each axis given in steady motion at tick k0 (the next tick `cosim`
/// runs): the drive at the reference's speed, the loop's integrators holding
/// what the feedforward does not give of B w, the Coulomb level and the
/// constant load, and the drive behind the reference by the error the law
/// holds there (controller::Law::steady_state). Axes not given keep their state.
void start_in_steady_motion(CoSimulation& cosim, const AxisArray<std::optional<ReferenceAtStart>>& reference,
                            std::int64_t k0);

}  // namespace twin::sim
