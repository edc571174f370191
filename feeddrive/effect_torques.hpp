#pragma once
/// The equations of the drive effects (docs/feeddrive.md), as pure functions
/// of the motion. The drive (drive_bank.cpp) integrates them; calibrate's
/// detectors build their regressors and take a fitted effect's torque out of
/// the residual with the same functions.
#include <algorithm>
#include <cmath>
#include <numbers>

namespace twin::feeddrive {

// stribeck: Tf(w) = Tc + (Ts_static - Tc) g(w), g = exp(-(w / ws)^2).

/// The share g(w) of the static excess left at speed w.
inline double stribeck_shape(double w, double ws) {
  const double r = w / ws;
  return std::exp(-r * r);
}
/// Friction above the Coulomb level Tc at speed w (a magnitude).
inline double stribeck_excess_Nm(double Ts_static_Nm, double Tc_Nm, double w, double ws) {
  return (Ts_static_Nm - Tc_Nm) * stribeck_shape(w, ws);
}
/// The steepest slope of the excess over w: (Ts - Tc) sqrt(2 / e) / ws.
inline double stribeck_max_slope(double Ts_static_Nm, double Tc_Nm, double ws) {
  return (Ts_static_Nm - Tc_Nm) * std::sqrt(2.0 / std::exp(1.0)) / ws;
}

// cogging: T = A sin(n theta + phase), theta = x / rg the motor angle.

inline double cogging_angle_rad(double cycles_per_rev, double x_motor_mm, double rg_mm_per_rad) {
  return cycles_per_rev * x_motor_mm / rg_mm_per_rad;
}
inline double cogging_torque_Nm(double amplitude_Nm, double cycles_per_rev, double phase_rad, double x_motor_mm,
                                double rg_mm_per_rad) {
  return amplitude_Nm * std::sin(cogging_angle_rad(cycles_per_rev, x_motor_mm, rg_mm_per_rad) + phase_rad);
}
/// Work done against the cogging torque from motor position xa to xb (exact:
/// the integral of A sin(n theta + phi) d theta).
inline double cogging_work_J(double amplitude_Nm, double cycles_per_rev, double phase_rad, double xa_mm, double xb_mm,
                             double rg_mm_per_rad) {
  const double n = cycles_per_rev;
  const double ta = xa_mm / rg_mm_per_rad;
  const double tb = xb_mm / rg_mm_per_rad;
  return -(amplitude_Nm / n) * (std::cos(n * tb + phase_rad) - std::cos(n * ta + phase_rad));
}

// screw_pitch_error: x_meas = x + A sin(2 pi x / P + phase).

inline double screw_pitch_angle_rad(double x_mm, double period_mm) {
  return 2.0 * std::numbers::pi * x_mm / period_mm;
}
inline double screw_pitch_error_mm(double amplitude_mm, double period_mm, double phase_rad, double x_mm) {
  return amplitude_mm * std::sin(screw_pitch_angle_rad(x_mm, period_mm) + phase_rad);
}

// position_dependent_friction: Coulomb friction raised by dTc while
// x_start <= x <= x_end.

inline bool in_friction_band(double x_mm, double x_start_mm, double x_end_mm) {
  return x_mm >= x_start_mm && x_mm <= x_end_mm;
}
inline double band_friction_Nm(double dTc_Nm, double x_start_mm, double x_end_mm, double x_mm) {
  return in_friction_band(x_mm, x_start_mm, x_end_mm) ? dTc_Nm : 0.0;
}

// smooth_friction: Tf = Tc_dir tanh(w / ws).

inline double smooth_friction_Nm(double Tc_dir_Nm, double w, double ws) { return Tc_dir_Nm * std::tanh(w / ws); }

// rising_friction: Tf(w) = Tc (1 - (1 - share) g(w)), g as stribeck's.

/// Friction below the Coulomb level Tc at speed w (a magnitude).
inline double rising_friction_deficit_Nm(double Tc_Nm, double share, double w, double ws) {
  return (1.0 - share) * Tc_Nm * stribeck_shape(w, ws);
}

// load_dependent_friction: Tf = sign(w) (Tc_dir + fraction |Tm|).

/// The friction the motor's torque Tm adds to the Coulomb level (a magnitude).
inline double load_friction_Nm(double fraction, double Tm_Nm) { return fraction * std::abs(Tm_Nm); }

// current_saturation: i = clamp(Ka u, -i_max, i_max).

inline double saturated_current_A(double i_A, double i_max_A) { return std::clamp(i_A, -i_max_A, i_max_A); }

}  // namespace twin::feeddrive
