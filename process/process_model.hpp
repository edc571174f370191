#pragma once
/// The interface the co-simulation loop calls once per tick for the cutting
/// process. The loop owns time; a process model keeps only its own state
/// (the in-process workpiece).
#include <array>
#include <cstdint>
#include <memory>

namespace twin::process {

/// Where the tool is at tick k and how it really moves (from the drives).
struct ProcessInput {
  std::int64_t k{0};
  double t_s{0.0};
  double Ts_s{1e-4};
  std::array<double, 3> p_mm{};           ///< tool tip relative to the workpiece, machine axes, at t_k
  std::array<double, 3> v_mm_per_s{};     ///< real tool velocity at t_k (drive speeds times rg)
  double spindle_rpm{0.0};                ///< signed: > 0 clockwise (M3)
};

/// Results for the tick [t_k, t_k+1).
struct ProcessOutput {
  std::array<double, 3> F_avg_N{};        ///< force on the workpiece averaged over the tick (loads the drives)
  std::array<double, 3> F_N{};            ///< instantaneous force on the workpiece at t_k (traces)
  double engagement_deg{0.0};             ///< engaged arc of the tool circle at mid depth
  double chip_mm{0.0};                    ///< largest uncut chip thickness over the tick
  double spindle_torque_Nm{0.0};          ///< cutting torque about the tool axis, tick average
  double power_W{0.0};                    ///< cutting power, tick average
  double removed_mm3{0.0};                ///< material removed in the tick
  /// A vibrating tool (tool-tip modes in the process): its deflection at t_k
  /// and the surface location error of the last tooth that passed a finished
  /// wall (deflection along the wall's outward normal; > 0: into the wall).
  bool tool_modes{false};
  std::array<double, 2> deflection_mm{};
  double sle_mm{0.0};
};

class ProcessModel {
 public:
  virtual ~ProcessModel() = default;
  /// Computes the force over [t_k, t_k+1) with the tool at in.p_mm moving at
  /// in.v_mm_per_s, then removes the material it swept from the stock.
  virtual ProcessOutput step(const ProcessInput& in) = 0;
  /// A deep copy (the FMU saves and restores its whole state).
  virtual std::unique_ptr<ProcessModel> clone() const = 0;
};

/// No material: zero force. An air cut.
class AirCut final : public ProcessModel {
 public:
  ProcessOutput step(const ProcessInput&) override { return {}; }
  std::unique_ptr<ProcessModel> clone() const override { return std::make_unique<AirCut>(); }
};

}  // namespace twin::process
