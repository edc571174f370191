#pragma once
/// Cutting-force coefficients of a tool/material pair.
///
/// Elemental force on one edge element of chip thickness h (mm) and chip
/// width db (mm):  dF_q = (K_qc(h) h + K_qe) db,  q in {t, r, a}, with
///   K_qc(h) = a_q + b_q exp(-c_q h)    [N/mm^2], h in mm, c_q in 1/mm
/// (Duan et al. 2025, eq. (1); the linear edge-force model of Altintas is
/// b_q = 0, K_qc = a_q). K_qe are the edge (ploughing) coefficients in N/mm.
#include <string>

namespace twin::process {

/// K(h) = a + b exp(-c h), N/mm^2.
struct ExpCoefficient {
  double a_N_per_mm2{0.0};
  double b_N_per_mm2{0.0};
  double c_per_mm{0.0};
  double at(double h_mm) const;
};

struct CuttingCoefficients {
  std::string name{"coefficients"};
  ExpCoefficient Kt{};   ///< tangential
  ExpCoefficient Kr{};   ///< radial
  ExpCoefficient Ka{};   ///< axial
  double Kte_N_per_mm{0.0};
  double Kre_N_per_mm{0.0};
  double Kae_N_per_mm{0.0};

  /// The linear edge-force model (constant cutting coefficients).
  static CuttingCoefficients linear(double Ktc_N_per_mm2, double Krc_N_per_mm2, double Kac_N_per_mm2,
                                    double Kte_N_per_mm, double Kre_N_per_mm, double Kae_N_per_mm);
  /// Throws ConfigError naming `where` and the coefficient when a value is
  /// not finite, c < 0, or K_tc(h) <= 0 somewhere in 0 <= h <= 1 mm.
  void validate(const std::string& where) const;
};

}  // namespace twin::process
