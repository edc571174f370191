#pragma once
/// The milling process coupled to the drives every tick: a tool, its cutting
/// coefficients, the in-process stock and the spindle angle.
///
/// step(in) for the tick [t_k, t_k+1):
///  1. n_sub = ceil(|Omega| Ts / angle_step) force samples at spindle angles
///     phi_k + s Omega Ts/n_sub and tool positions p_k + v s Ts/n_sub
///     (s = 0..n_sub-1), the feed per tooth from the ACTUAL velocity v
///     (in.v_mm_per_s): f = v_xy / (N n), n = rpm/60 (see milling_force.hpp);
///  2. F_avg_N = -(mean of the samples) (on the workpiece; loads the drives),
///     F_N = -(sample s = 0), torque and power = torque * Omega averaged;
///  3. engagement_deg: the engaged arc at the disk nearest half the depth
///     below the stock top (whether or not a flute is there), at p_k;
///  4. phi_k+1 = phi_k + Omega Ts; the stock loses what the tool sweeps from
///     the last update to p_k + v Ts, once the tool has moved two cells (or
///     moved down), so the height map lags the tool by < two cells. The lag
///     leaves material behind the tool, never ahead of it, and the chip
///     condition ignores what lies behind.
/// With tool-tip modes (ProcessSetup::tool_tip) the tool vibrates: the tick is
/// cut into n_sub = max(the angle steps above, ceil(substeps_per_mode_period fn_max Ts)) substeps;
/// in substep s of length dt the force is sampled at its midpoint (spindle
/// angle, tool position, and the deflection predicted there from the state
/// and the previous substep's force) with the regenerative chip of
/// Regeneration (deflection now against one, two ... tooth periods ago, from
/// the recorded deflection), and held over the substep to advance the modes
/// exactly (ToolVibration). The material test stays the rigid tool's. The
/// surface location error is sampled when a flute (at mid depth) passes the
/// angle of a finished wall: the feed normal on a side where material lies
/// just outside the tool.
/// More than 1000 force samples in one tick (a spindle speed or an
/// angle_step_deg far outside milling practice) is a ModelError;
/// a counter-clockwise spindle (M4) is a ModelError; a stopped spindle with
/// the tool feeding into material is a ModelError; non-finite inputs are ModelErrors.
#include <array>
#include <memory>
#include <string>

#include "process/cutting_coefficients.hpp"
#include "process/milling_force.hpp"
#include "process/process_model.hpp"
#include "process/stability_lobes.hpp"
#include "process/tool.hpp"
#include "process/tool_vibration.hpp"
#include "process/workpiece.hpp"

namespace twin::process {

/// Everything a MillingProcess is built from (filled by twin/io/process_yaml).
struct ProcessSetup {
  ToolGeometry tool;
  CuttingCoefficients coefficients;
  double lead_deg{0.0};   ///< Duan's thetaL: chip thickness eq. (4)
  double tilt_deg{0.0};   ///< Duan's thetaT: selects the coefficient set (no effect on eq. (4))
  StockSpec stock;
  ForceModelOptions options;
  double spindle_angle0_deg{0.0};   ///< flute 0's immersion at the first tick
  /// The tool tip's modes in the cut (empty: a rigid tool, the force model as
  /// it is without them). See MillingProcess.
  ToolTipFrf tool_tip;
  /// With tool modes: the fewest force samples per period of the highest mode.
  double substeps_per_mode_period{8.0};
  /// One line: tool, material, stock size.
  std::string summary() const;
};

class MillingProcess final : public ProcessModel {
 public:
  /// Throws ConfigError on an invalid setup.
  explicit MillingProcess(const ProcessSetup& setup);
  ProcessOutput step(const ProcessInput& in) override;
  std::unique_ptr<ProcessModel> clone() const override;

  /// Removes what the tool sweeps from tip p0 to tip p1 without computing a
  /// force (a cut already made, e.g. to start a steady cut); returns mm^3.
  double remove_swept(const std::array<double, 3>& p0_mm, const std::array<double, 3>& p1_mm);
  const HeightMapStock& stock() const noexcept { return stock_; }
  const ToolVibration& vibration() const noexcept { return vibration_; }
  const MillingForceModel& force_model() const noexcept { return model_; }
  double spindle_angle_rad() const noexcept { return phi_rad_; }
  /// The probe distance outside the edge radius (one cell), mm.
  double probe_mm() const noexcept { return stock_.cell_mm(); }

 private:
  /// The tick's geometry, shared by the rigid and the vibrating sampling.
  struct TickCut {
    std::array<double, 2> f_mm{};
    std::array<double, 2> v_dir{};
    double z_top_mm{0.0};
    double omega_rad_per_s{0.0};
    int n_sub{1};
  };
  /// Samples the force over the tick with the rigid tool into `out`.
  void sample_rigid(const ProcessInput& in, const TickCut& cut, ProcessOutput& out) const;
  /// Samples and advances the vibrating tool over the tick into `out`.
  void sample_vibrating(const ProcessInput& in, const TickCut& cut, ProcessOutput& out);
  /// Number of force samples in the tick; ModelError beyond the limit.
  int substeps(const ProcessInput& in, double omega_rad_per_s) const;
  /// Removes what the tool swept in the tick from the stock.
  double update_stock(const ProcessInput& in);
  /// Refuses a stopped spindle feeding into material.
  void check_stopped_spindle(const ProcessInput& in, const std::array<double, 2>& v_dir, double z_top_mm) const;
  /// The outward normals of the finished walls at the tick (0, 1 or 2).
  int finished_walls(const ProcessInput& in, const TickCut& cut, std::array<std::array<double, 2>, 2>& n) const;

  MillingForceModel model_;
  HeightMapStock stock_;
  double phi_rad_{0.0};
  bool swept_once_{false};
  std::array<double, 3> last_removed_mm_{};
  bool last_sweep_level_{true};   ///< the last update did not move down (by more than 1e-9 mm)
  ToolVibration vibration_;        ///< empty: a rigid tool
  double substeps_per_mode_period_{8.0};
  std::array<double, 2> F_tool_prev_N_{};   ///< the last substep's force on the tool (x, y)
  double sle_mm_{0.0};             ///< the last surface location error sampled
};

/// A MillingProcess behind the ProcessModel interface.
std::unique_ptr<ProcessModel> make_process(const ProcessSetup& setup);

}  // namespace twin::process
