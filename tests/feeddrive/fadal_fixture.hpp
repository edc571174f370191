#pragma once
/// Shared test fixture: the FADAL 2216 X and Y drives (Ozcan et al. 2017,
/// Tables 1 and 3; Coulomb levels are the project's stated assumptions) and
/// the FADAL digital position loop written out by hand from
/// spec/measured-data.md, so tests can close the loop without the controller
/// library.
#include <algorithm>
#include <cmath>

#include "feeddrive/drive_params.hpp"

namespace twin::feeddrive::testing {

/// The FADAL controller's period and its encoders' count (design.md section 4).
inline constexpr double kTs_s = 1e-4;
inline constexpr double kCount_mm = 1e-3;

inline DriveParams fadal_x() {
  return {.Ka_A_per_V = 6.4898, .Kt_Nm_per_A = 0.4769, .J_kg_m2 = 0.0077736, .B_kg_m2_per_s = 0.019811,
          .rg_mm_per_rad = 1.5915, .Tc_pos_Nm = 0.20, .Tc_neg_Nm = 0.18, .effects = {}};
}

/// Y has X's motor and screw (Kt, rg).
inline DriveParams fadal_y() {
  const DriveParams x = fadal_x();
  return {.Ka_A_per_V = 7.5768, .Kt_Nm_per_A = x.Kt_Nm_per_A, .J_kg_m2 = 0.0098109, .B_kg_m2_per_s = 0.28438,
          .rg_mm_per_rad = x.rg_mm_per_rad, .Tc_pos_Nm = 0.30, .Tc_neg_Nm = 0.28, .effects = {}};
}

struct PidGains {
  double Kp_V_per_mm{500.0};
  double Ki_V_per_s_mm{70.0};
  double Kd_V_s_per_mm{0.3};
  double K1_V_s2_per_mm{0.0};
  double K2_V_s_per_mm{-2.37e-6};
  double u_max_V{10.0};
};

inline PidGains fadal_x_gains() { return {}; }
inline PidGains fadal_y_gains() { return {462.539, 64.75, 0.278, 0.0, 5.55e-4, 10.0}; }

/// u[k] = Kp e + Ki I + Kd (e - e[k-1])/Ts + K1 a_ref + K2 v_ref, clamped,
/// with backward differences; the first call takes x_ref[-1] = x_ref[0].
class HandPid {
 public:
  HandPid(PidGains g, double Ts_s) : g_(g), Ts_s_(Ts_s) {}
  double step(double x_ref_mm, double x_meas_mm) {
    if (first_) {
      x_ref_prev_mm_ = x_ref_mm;
      first_ = false;
    }
    const double e_mm = x_ref_mm - x_meas_mm;
    const double v_ref = (x_ref_mm - x_ref_prev_mm_) / Ts_s_;
    const double a_ref = (v_ref - v_ref_prev_) / Ts_s_;
    I_mm_s_ += Ts_s_ * e_mm;
    const double u = g_.Kp_V_per_mm * e_mm + g_.Ki_V_per_s_mm * I_mm_s_ +
                     g_.Kd_V_s_per_mm * (e_mm - e_prev_mm_) / Ts_s_ + g_.K1_V_s2_per_mm * a_ref +
                     g_.K2_V_s_per_mm * v_ref;
    e_prev_mm_ = e_mm;
    x_ref_prev_mm_ = x_ref_mm;
    v_ref_prev_ = v_ref;
    return std::clamp(u, -g_.u_max_V, g_.u_max_V);
  }

 private:
  PidGains g_;
  double Ts_s_;
  bool first_{true};
  double I_mm_s_{0.0};
  double e_prev_mm_{0.0};
  double x_ref_prev_mm_{0.0};
  double v_ref_prev_{0.0};
};

/// Encoder quantisation to the nearest count.
inline double quantize_mm(double x_mm, double resolution_mm) {
  return resolution_mm * std::round(x_mm / resolution_mm);
}

}  // namespace twin::feeddrive::testing
