#include "process/milling_force.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

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
  const double r = tool_.corner_radius_mm;
  const auto add = [&](double z_lo, double z_hi, double k_lo, double k_hi, bool corner) {
    double z, kappa, db;
    if (corner) {
      kappa = 0.5 * (k_lo + k_hi);
      z = r * (1.0 - std::cos(kappa));
      db = r * (k_hi - k_lo);
    } else {
      kappa = 0.5 * kPi;
      z = 0.5 * (z_lo + z_hi);
      db = z_hi - z_lo;
    }
    const double lag = z * tan_helix / R;
    const double radius = corner ? R - r + r * std::sin(kappa) : R;
    disks_.push_back(Disk{z, z_lo, z_hi, k_lo, k_hi, corner, radius, std::sin(kappa), std::cos(kappa), db,
                          std::sin(lag), std::cos(lag)});
  };
  if (r > 0.0) {
    // The corner arc in equal steps of kappa (db = r dkappa <= dz).
    const int n_corner = std::max(1, static_cast<int>(std::ceil(0.5 * kPi * r / options_.dz_mm)));
    const double dk = 0.5 * kPi / n_corner;
    for (int i = 0; i < n_corner; ++i) {
      const double k0 = i * dk;
      const double k1 = i + 1 == n_corner ? 0.5 * kPi : (i + 1) * dk;
      add(r * (1.0 - std::cos(k0)), i + 1 == n_corner ? r : r * (1.0 - std::cos(k1)), k0, k1, true);
    }
  }
  const double flank = tool_.flute_length_mm - r;
  const int n_flank = static_cast<int>(std::ceil(flank / options_.dz_mm - 1e-9));
  for (int i = 0; i < n_flank; ++i)
    add(r + i * options_.dz_mm, std::min(r + (i + 1) * options_.dz_mm, tool_.flute_length_mm), 0.0, 0.0, false);
  for (const Disk& d : disks_)
    for (int j = 0; j < tool_.flutes; ++j) dR_mm_.push_back(tool_.flute_radius_mm(j, d.z_mm) - R);
  for (int j = 0; j < tool_.flutes; ++j) {
    const double a = j * kRadPerRev / tool_.flutes;
    flute_dir_.push_back({std::sin(a), std::cos(a)});
  }
  const int n_arc = static_cast<int>(std::lround(360.0 / options_.engagement_step_deg));
  for (int i = 0; i < n_arc; ++i) {
    const double phi = (i + 0.5) * kRadPerRev / n_arc;
    arc_sin_.push_back(std::sin(phi));
    arc_cos_.push_back(std::cos(phi));
  }
}

MillingForceModel::ArcRuns MillingForceModel::forward_arc(const std::array<double, 2>& v_dir) const {
  // Sample i lies at phi_i = (i + 1/2) step; v_dir at theta (clockwise from
  // +y): v_dir . (sin, cos)_i = cos(phi_i - theta) > 0 within a quarter turn
  // of theta. The quarter turns end in [lo + 2, lo + 3) and (hi - 3, hi - 2]
  // in units of samples. Samples more than a step inside the half circle
  // (lo + 4 ... hi - 4) have a product above sin(step) (8.7e-4 at the
  // smallest step, 0.05 deg), those a step or more outside (lo, lo + 1,
  // hi - 1, hi) at most -sin(step): their signs are far past rounding. So
  // only the five samples at each end are tested, with the same product a
  // test of every sample would use, and the samples between them all count.
  ArcRuns runs;
  if (!(v_dir[0] != 0.0 || v_dir[1] != 0.0)) return runs;   // every product is 0
  const auto n = static_cast<std::int64_t>(arc_sin_.size());
  const double step = kRadPerRev / static_cast<double>(n);
  const double theta = std::atan2(v_dir[0], v_dir[1]);
  const auto lo = static_cast<std::int64_t>(std::floor((theta - 0.5 * kPi) / step - 0.5)) - 2;
  const auto hi = static_cast<std::int64_t>(std::ceil((theta + 0.5 * kPi) / step - 0.5)) + 2;
  const auto forward = [&](std::int64_t k) {
    const auto i = static_cast<std::size_t>(((k % n) + n) % n);
    return v_dir[0] * arc_sin_[i] + v_dir[1] * arc_cos_[i] > 0.0;
  };
  std::int64_t first = lo;
  while (first < lo + 4 && !forward(first)) ++first;
  std::int64_t last = hi;
  while (last > hi - 4 && !forward(last)) --last;
  // [first, last] as indices modulo n, split where it wraps.
  const std::int64_t b = ((first % n) + n) % n;
  const std::int64_t len = std::min(last - first + 1, n);
  runs.begin[0] = static_cast<std::size_t>(b);
  runs.end[0] = static_cast<std::size_t>(std::min(b + len, n));
  runs.count = 1;
  if (b + len > n) {
    runs.begin[1] = 0;
    runs.end[1] = static_cast<std::size_t>(b + len - n);
    runs.count = 2;
  }
  return runs;
}

double MillingForceModel::fraction_below(const Disk& d, double z_top_local_mm) const {
  if (z_top_local_mm >= d.z_hi_mm) return 1.0;
  if (z_top_local_mm <= d.z_lo_mm) return 0.0;
  if (d.corner) {
    const double r = tool_.corner_radius_mm;
    const double k_top = std::acos(std::clamp(1.0 - z_top_local_mm / r, -1.0, 1.0));
    return std::clamp((k_top - d.kappa_lo) / (d.kappa_hi - d.kappa_lo), 0.0, 1.0);
  }
  return (z_top_local_mm - d.z_lo_mm) / (d.z_hi_mm - d.z_lo_mm);
}

double MillingForceModel::edge_length_mm(double depth_mm) const {
  double L = 0.0;
  for (const Disk& d : disks_) {
    if (d.z_lo_mm >= depth_mm) break;
    L += fraction_below(d, depth_mm) * d.db_mm;
  }
  return L;
}

double MillingForceModel::disk_height_nearest_mm(double z_mm) const {
  const double i = std::floor(std::max(z_mm, 0.0) / options_.dz_mm);
  return std::min((i + 0.5) * options_.dz_mm, disks_.back().z_mm);
}

}  // namespace twin::process
