#pragma once
/// The tool tip's vibration in the cut: the modes of `tool_tip:` (uncoupled,
/// per direction x and y, modal stiffness k, natural frequency fn, damping
/// ratio zeta) driven by the cutting force on the tool,
///   m q'' + c q' + k q = F,   m = k / wn^2,  c = 2 zeta wn m,   u = sum of q,
/// advanced by the exact zero-order-hold discretisation of each mode: for a
/// force held over dt,
///   [q; q']_+ = Phi(dt) [q; q'] + Gamma(dt) F,  Phi = exp(A dt),
///   Gamma = A^-1 (Phi - I) [0; 1/m],  A = [0 1; -wn^2 -2 zeta wn],
/// Phi in closed form (underdamped, wd = wn sqrt(1 - zeta^2), s = zeta wn):
///   Phi = e^(-s dt) [cos + s/wd sin,  sin/wd;  -wn^2/wd sin,  cos - s/wd sin]  (of wd dt).
/// The deflection is kept with its time for one spindle revolution, so the
/// chip can compare the tool now with where it was one or more tooth periods
/// ago (the surface the earlier teeth left). Before the first recorded time
/// the tool was at rest, undeflected.
#include <array>
#include <deque>
#include <vector>

#include "process/stability_lobes.hpp"

namespace twin::process {

class ToolVibration {
 public:
  ToolVibration() = default;
  /// Throws ConfigError for invalid modes.
  explicit ToolVibration(const ToolTipFrf& frf);

  bool empty() const noexcept { return modes_.empty(); }
  /// Highest natural frequency of any mode (Hz).
  double fn_max_Hz() const noexcept { return fn_max_Hz_; }
  /// Deflection of the tool tip now (mm, machine x and y).
  std::array<double, 2> deflection_mm() const noexcept;
  /// Deflection at t_s after dt_s with force F_tool_N held (no change of state), mm.
  std::array<double, 2> predict_mm(double dt_s, const std::array<double, 2>& F_tool_N) const;
  /// Deflection at an earlier time t_s (linear between recorded points; zero
  /// before the first one, the latest one after it).
  std::array<double, 2> deflection_at_mm(double t_s) const;
  /// Advances from t_s to t_s + dt_s with F_tool_N held, records the deflection
  /// at the end, and forgets what is older than keep_s before it.
  void advance(double t_s, double dt_s, const std::array<double, 2>& F_tool_N, double keep_s);

 private:
  struct Mode {
    int direction{0};   ///< 0: x, 1: y
    double wn{0.0}, zeta{0.0}, m_kg{0.0};
    double q_m{0.0}, dq_m_per_s{0.0};
  };
  struct Discrete {
    double dt_s{-1.0};
    std::vector<std::array<double, 6>> phi_gamma;   ///< per mode: Phi 2x2 row major, Gamma 2
  };
  /// The matrices for dt_s, kept in `slot` (recomputed when dt_s changes).
  const Discrete& discrete(Discrete& slot, double dt_s) const;
  struct Point {
    double t_s;
    double x_mm, y_mm;
  };
  std::vector<Mode> modes_;
  double fn_max_Hz_{0.0};
  Discrete step_;              ///< the last step length's matrices
  mutable Discrete predict_;   ///< the last prediction length's
  std::deque<Point> history_;
};

}  // namespace twin::process
