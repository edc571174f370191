#include "process/cutting_coefficients.hpp"

#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::process {

double ExpCoefficient::at(double h_mm) const {
  if (b_N_per_mm2 == 0.0) return a_N_per_mm2;
  return a_N_per_mm2 + b_N_per_mm2 * std::exp(-c_per_mm * h_mm);
}

CuttingCoefficients CuttingCoefficients::linear(double Ktc_N_per_mm2, double Krc_N_per_mm2, double Kac_N_per_mm2,
                                                double Kte_N_per_mm, double Kre_N_per_mm, double Kae_N_per_mm) {
  CuttingCoefficients k;
  k.name = "linear";
  k.Kt.a_N_per_mm2 = Ktc_N_per_mm2;
  k.Kr.a_N_per_mm2 = Krc_N_per_mm2;
  k.Ka.a_N_per_mm2 = Kac_N_per_mm2;
  k.Kte_N_per_mm = Kte_N_per_mm;
  k.Kre_N_per_mm = Kre_N_per_mm;
  k.Kae_N_per_mm = Kae_N_per_mm;
  return k;
}

void CuttingCoefficients::validate(const std::string& where) const {
  const struct {
    const char* name;
    const ExpCoefficient* k;
  } all[] = {{"Kt", &Kt}, {"Kr", &Kr}, {"Ka", &Ka}};
  for (const auto& e : all) {
    if (!std::isfinite(e.k->a_N_per_mm2) || !std::isfinite(e.k->b_N_per_mm2) || !std::isfinite(e.k->c_per_mm))
      throw ConfigError(fmt::format("{}: {} has a non-finite a, b or c", where, e.name));
    if (e.k->c_per_mm < 0.0) throw ConfigError(fmt::format("{}: {}.c = {} 1/mm must be >= 0", where, e.name, e.k->c_per_mm));
  }
  for (double h = 0.0; h <= 1.0; h += 0.01) {
    if (Kt.at(h) <= 0.0)
      throw ConfigError(fmt::format("{}: Kt({} mm) = {} N/mm^2 must be > 0", where, h, Kt.at(h)));
  }
  if (!std::isfinite(Kte_N_per_mm) || !std::isfinite(Kre_N_per_mm) || !std::isfinite(Kae_N_per_mm))
    throw ConfigError(fmt::format("{}: an edge coefficient (Kte, Kre, Kae) is not finite", where));
  if (Kte_N_per_mm < 0.0) throw ConfigError(fmt::format("{}: Kte = {} N/mm must be >= 0", where, Kte_N_per_mm));
}

}  // namespace twin::process
