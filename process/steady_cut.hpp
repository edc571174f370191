#pragma once
/// A steady straight cut, one tool revolution: the calculator behind `twin cut`.
///
/// The tool moves along +x at v = f_t N n with its tip at z = -ap below the
/// stock top z = 0, in a block whose +y edge (up milling: material on +y,
/// immersion 0 .. acos(1 - 2 ae/D)) or -y edge (down milling: acos(2 ae/D - 1)
/// .. 180 deg) leaves radial depth ae; ae = D is a slot. The cut so far is
/// removed first, then the MillingProcess runs one revolution at one tick
/// per angle_step_deg, and the force on the workpiece is recorded per tick.
#include <array>
#include <vector>

#include "process/cutting_coefficients.hpp"
#include "process/milling_force.hpp"
#include "process/tool.hpp"

namespace twin::process {

struct SteadyCutSpec {
  ToolGeometry tool;
  CuttingCoefficients coefficients;
  double lead_deg{0.0};
  double tilt_deg{0.0};
  double spindle_rpm{1200.0};
  double feed_per_tooth_mm{0.05};
  double ae_mm{5.0};
  double ap_mm{1.0};
  bool up_milling{true};
  double angle_step_deg{1.0};
  double dz_mm{0.05};
  double cell_mm{0.02};
  /// A calibrated cut (twin calibrate on force logs): the wear state as a
  /// factor on every coefficient, K(L) = K(L_ref) (1 + w (L - L_ref)).
  double coefficient_scale{1.0};
  /// A sensor mode in the force output, wn^2/(s^2 + 2 zeta wn s + wn^2)
  /// (unit DC gain; 0 Hz: none). The revolution is a steady periodic force,
  /// so each of its harmonics k (frequency k n) is multiplied by H(k n).
  double sensor_f_hz{0.0};
  double sensor_zeta{0.0};
  /// Throws ConfigError naming the option: rpm <= 0, feed per tooth outside
  /// (0, 1] mm, ae outside (0, D], ap outside (0, flute length], steps out of
  /// range, a coefficient scale outside (0, 10], a sensor mode with f < 0 or
  /// zeta outside (0, 1].
  void validate() const;
};

struct SteadyCutRow {
  double angle_deg{0.0};            ///< spindle angle of flute 0
  std::array<double, 3> F_N{};      ///< on the workpiece
  double torque_Nm{0.0};
  double chip_mm{0.0};
};

struct SteadyCutResult {
  std::vector<SteadyCutRow> rows;   ///< one revolution
  std::array<double, 3> mean_F_N{};
  std::array<double, 3> peak_F_N{}; ///< the signed value of largest magnitude per axis
  double mean_torque_Nm{0.0};
  double mean_power_W{0.0};
  double feed_mm_per_min{0.0};
  double engagement_deg{0.0};       ///< engaged arc at mid depth
};

SteadyCutResult run_steady_cut(const SteadyCutSpec& spec);

}  // namespace twin::process
