#include "process/milling_force.hpp"

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::process {

void ForceModelOptions::validate(const std::string& where) const {
  if (!(dz_mm >= 0.005 && dz_mm <= 2.0))
    throw ConfigError(fmt::format("{}: model.dz_mm = {} must be in [0.005, 2] mm", where, dz_mm));
  if (!(angle_step_deg >= 0.05 && angle_step_deg <= 10.0))
    throw ConfigError(fmt::format("{}: model.angle_step_deg = {} must be in [0.05, 10] deg", where, angle_step_deg));
  if (!(engagement_step_deg >= 0.05 && engagement_step_deg <= 10.0))
    throw ConfigError(
        fmt::format("{}: model.engagement_step_deg = {} must be in [0.05, 10] deg", where, engagement_step_deg));
}

MillingForceModel::MillingForceModel(const ToolGeometry& tool, const CuttingCoefficients& coefficients,
                                     double lead_deg, const ForceModelOptions& options)
    : tool_(tool), k_(coefficients), options_(options) {
  tool_.validate("process");
  k_.validate("process: material " + k_.name);
  options_.validate("process");
  if (!std::isfinite(lead_deg) || std::abs(lead_deg) >= 60.0)
    throw ConfigError(fmt::format("process: lead_deg = {} must be in (-60, 60) deg", lead_deg));
  cos_lead_ = std::cos(lead_deg * kRadPerDeg);
  sin_lead_ = std::sin(lead_deg * kRadPerDeg);
  const double R = tool_.radius_mm();
  const double tan_helix = std::tan(tool_.helix_deg * kRadPerDeg);
  const int n_disks = static_cast<int>(std::ceil(tool_.flute_length_mm / options_.dz_mm));
  for (int i = 0; i < n_disks; ++i) {
    const double z0 = i * options_.dz_mm;
    const double z1 = std::min((i + 1) * options_.dz_mm, tool_.flute_length_mm);
    const double z = 0.5 * (z0 + z1);
    const double kappa = tool_.kappa_rad(z);
    const double sk = std::max(std::sin(kappa), 1e-3);
    const double lag = z * tan_helix / R;
    disks_.push_back(Disk{z, tool_.edge_radius_mm(z), sk, std::cos(kappa), (z1 - z0) / sk, std::sin(lag), std::cos(lag)});
  }
  for (int j = 0; j < tool_.flutes; ++j) {
    dR_mm_.push_back(tool_.flute_radius_mm(j) - R);
    const double a = j * kRadPerRev / tool_.flutes;
    flute_dir_.push_back({std::sin(a), std::cos(a)});
  }
  const int n_arc = static_cast<int>(std::lround(360.0 / options_.engagement_step_deg));
  for (int i = 0; i < n_arc; ++i) {
    const double phi = (i + 0.5) * kRadPerRev / n_arc;
    arc_dirs_.push_back({std::sin(phi), std::cos(phi)});
  }
}

double MillingForceModel::disk_height_nearest_mm(double z_mm) const {
  const double i = std::floor(std::max(z_mm, 0.0) / options_.dz_mm);
  return std::min((i + 0.5) * options_.dz_mm, disks_.back().z_mm);
}

}  // namespace twin::process
