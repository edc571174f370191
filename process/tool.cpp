#include "process/tool.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::process {

ToolShape parse_tool_shape(const std::string& name, const std::string& where) {
  if (name == "flat") return ToolShape::kFlat;
  if (name == "bull_nose") return ToolShape::kBullNose;
  if (name == "ball") return ToolShape::kBall;
  throw ConfigError(fmt::format("{}: tool type '{}' is not one of flat, bull_nose, ball", where, name));
}

const char* tool_shape_name(ToolShape shape) {
  switch (shape) {
    case ToolShape::kFlat: return "flat";
    case ToolShape::kBullNose: return "bull_nose";
    case ToolShape::kBall: return "ball";
  }
  return "?";
}

void ToolGeometry::validate(const std::string& where) const {
  auto bad = [&](const char* key, double v, const char* rule) {
    throw ConfigError(fmt::format("{}: tool.{} = {} {}", where, key, v, rule));
  };
  if (!std::isfinite(diameter_mm) || diameter_mm <= 0.0 || diameter_mm > 200.0)
    bad("diameter_mm", diameter_mm, "must be in (0, 200] mm");
  if (flutes < 1 || flutes > 16) bad("flutes", flutes, "must be in [1, 16]");
  if (!std::isfinite(helix_deg) || helix_deg < 0.0 || helix_deg >= 60.0)
    bad("helix_deg", helix_deg, "must be in [0, 60) deg");
  if (!std::isfinite(flute_length_mm) || flute_length_mm <= 0.0) bad("flute_length_mm", flute_length_mm, "must be > 0 mm");
  const double R = radius_mm();
  switch (shape) {
    case ToolShape::kFlat:
      if (corner_radius_mm != 0.0) bad("corner_radius_mm", corner_radius_mm, "must be 0 for a flat end mill");
      break;
    case ToolShape::kBullNose:
      if (!(corner_radius_mm > 0.0 && corner_radius_mm < R))
        bad("corner_radius_mm", corner_radius_mm, fmt::format("must be in (0, {}) mm for a bull-nose end mill", R).c_str());
      break;
    case ToolShape::kBall:
      if (std::abs(corner_radius_mm - R) > 1e-12)
        bad("corner_radius_mm", corner_radius_mm, fmt::format("must equal the radius {} mm for a ball end mill", R).c_str());
      break;
  }
  if (flute_length_mm < corner_radius_mm) bad("flute_length_mm", flute_length_mm, "must be >= corner_radius_mm");
  if (!std::isfinite(runout_rho_mm) || runout_rho_mm < 0.0 || runout_rho_mm >= 0.1 * R)
    bad("runout_rho_mm", runout_rho_mm, "must be in [0, R/10) mm");
  if (!std::isfinite(runout_lambda_deg)) bad("runout_lambda_deg", runout_lambda_deg, "must be finite");
}

double ToolGeometry::edge_radius_mm(double z_mm) const {
  const double R = radius_mm();
  const double r = corner_radius_mm;
  if (z_mm >= r) return R;
  const double zc = std::max(z_mm, 0.0);
  return R - r + std::sqrt(std::max(r * r - (r - zc) * (r - zc), 0.0));
}

double ToolGeometry::kappa_rad(double z_mm) const {
  const double r = corner_radius_mm;
  if (z_mm >= r) return 0.5 * kPi;
  return std::acos(std::clamp(1.0 - std::max(z_mm, 0.0) / r, -1.0, 1.0));
}

double ToolGeometry::bottom_height_mm(double d_mm) const {
  const double R = radius_mm();
  const double r = corner_radius_mm;
  if (d_mm > R) return flute_length_mm + 1.0;
  if (d_mm <= R - r) return 0.0;
  const double u = d_mm - (R - r);
  return r - std::sqrt(std::max(r * r - u * u, 0.0));
}

double ToolGeometry::flute_radius_mm(int j, double z_mm) const {
  const double pitch = kRadPerRev / flutes;
  const double lag = z_mm * std::tan(helix_deg * kRadPerDeg) / radius_mm();
  return radius_mm() + runout_rho_mm * std::cos(runout_lambda_deg * kRadPerDeg - j * pitch + lag);
}

}  // namespace twin::process
