#pragma once
// Shared set-ups of the process tests: straight cuts driven tick by tick.
#include <array>
#include <cmath>
#include <vector>

#include "process/milling_process.hpp"

namespace twin::process::testing {

inline ToolGeometry flat_tool(double D_mm, int flutes, double helix_deg) {
  ToolGeometry t;
  t.name = "flat";
  t.shape = ToolShape::kFlat;
  t.diameter_mm = D_mm;
  t.flutes = flutes;
  t.helix_deg = helix_deg;
  t.corner_radius_mm = 0.0;
  t.flute_length_mm = 20.0;
  return t;
}

/// design.md section 5: Ktc 800, Krc 250 N/mm^2, Kte 25, Kre 30 N/mm (axial 0).
inline CuttingCoefficients design_coefficients() { return CuttingCoefficients::linear(800.0, 250.0, 0.0, 25.0, 30.0, 0.0); }

/// Ticks of a straight move from p0 at velocity v (mm/s), returning every output.
inline std::vector<ProcessOutput> drive(MillingProcess& proc, std::array<double, 3> p0, std::array<double, 3> v,
                                        double rpm, double Ts_s, int ticks) {
  std::vector<ProcessOutput> outs;
  outs.reserve(static_cast<std::size_t>(ticks));
  for (int k = 0; k < ticks; ++k) {
    ProcessInput in;
    in.k = k;
    in.t_s = k * Ts_s;
    in.Ts_s = Ts_s;
    in.p_mm = {p0[0] + v[0] * k * Ts_s, p0[1] + v[1] * k * Ts_s, p0[2] + v[2] * k * Ts_s};
    in.v_mm_per_s = v;
    in.spindle_rpm = rpm;
    outs.push_back(proc.step(in));
  }
  return outs;
}

}  // namespace twin::process::testing
