#include "process/workpiece.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::process {
namespace {

constexpr double kMaxCells = 80e6;

/// x where the row at height y crosses the polygon's edges (even-odd rule).
std::vector<double> row_crossings(const std::vector<Point2>& poly, double y) {
  std::vector<double> xs;
  const std::size_t n = poly.size();
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = poly[i];
    const Point2& b = poly[(i + 1) % n];
    if ((a.y_mm <= y) != (b.y_mm <= y)) xs.push_back(a.x_mm + (y - a.y_mm) / (b.y_mm - a.y_mm) * (b.x_mm - a.x_mm));
  }
  std::sort(xs.begin(), xs.end());
  return xs;
}

}  // namespace

std::vector<Point2> StockSpec::rectangle(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

void StockSpec::validate(const std::string& where) const {
  if (outline_mm.size() < 3)
    throw ConfigError(fmt::format("{}: stock.outline_mm has {} points, needs at least 3", where, outline_mm.size()));
  for (const auto& p : outline_mm)
    if (!std::isfinite(p.x_mm) || !std::isfinite(p.y_mm))
      throw ConfigError(fmt::format("{}: stock.outline_mm has a non-finite point", where));
  if (!std::isfinite(top_z_mm) || !std::isfinite(bottom_z_mm) || top_z_mm <= bottom_z_mm)
    throw ConfigError(fmt::format("{}: stock.top_z_mm = {} must be above stock.bottom_z_mm = {}", where, top_z_mm, bottom_z_mm));
  if (!(cell_mm >= 0.005 && cell_mm <= 1.0))
    throw ConfigError(fmt::format("{}: stock.cell_mm = {} must be in [0.005, 1] mm", where, cell_mm));
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& p : outline_mm) {
    xmin = std::min(xmin, p.x_mm);
    xmax = std::max(xmax, p.x_mm);
    ymin = std::min(ymin, p.y_mm);
    ymax = std::max(ymax, p.y_mm);
  }
  const double cells = std::ceil((xmax - xmin) / cell_mm) * std::ceil((ymax - ymin) / cell_mm);
  if (!(xmax > xmin && ymax > ymin)) throw ConfigError(fmt::format("{}: stock.outline_mm encloses no area", where));
  if (cells > kMaxCells)
    throw ConfigError(fmt::format("{}: stock of {:.1f} x {:.1f} mm at stock.cell_mm = {} needs {:.3g} cells (limit {:.3g}); "
                                  "use a larger cell",
                                  where, xmax - xmin, ymax - ymin, cell_mm, cells, kMaxCells));
  for (std::size_t i = 0; i < pockets.size(); ++i) {
    const auto& pk = pockets[i];
    if (!std::isfinite(pk.floor_z_mm))
      throw ConfigError(fmt::format("{}: stock.pockets[{}].floor_z_mm is not finite", where, i));
    if (pk.polygon_mm.empty() && !(pk.radius_mm > 0.0 && std::isfinite(pk.radius_mm)))
      throw ConfigError(fmt::format("{}: stock.pockets[{}] needs polygon_mm (>= 3 points) or radius_mm > 0", where, i));
    if (!pk.polygon_mm.empty() && pk.polygon_mm.size() < 3)
      throw ConfigError(fmt::format("{}: stock.pockets[{}].polygon_mm has {} points, needs at least 3", where, i,
                                    pk.polygon_mm.size()));
  }
}

HeightMapStock::HeightMapStock(const StockSpec& spec) {
  spec.validate("stock");
  double xmin = 1e300, xmax = -1e300, ymin = 1e300, ymax = -1e300;
  for (const auto& p : spec.outline_mm) {
    xmin = std::min(xmin, p.x_mm);
    xmax = std::max(xmax, p.x_mm);
    ymin = std::min(ymin, p.y_mm);
    ymax = std::max(ymax, p.y_mm);
  }
  cell_mm_ = spec.cell_mm;
  inv_cell_ = 1.0 / cell_mm_;
  x0_mm_ = xmin;
  y0_mm_ = ymin;
  nx_ = static_cast<std::size_t>(std::ceil((xmax - xmin) / cell_mm_));
  ny_ = static_cast<std::size_t>(std::ceil((ymax - ymin) / cell_mm_));
  top_z_mm_ = spec.top_z_mm;
  bottom_z_mm_ = spec.bottom_z_mm;
  top_.assign(nx_ * ny_, static_cast<float>(bottom_z_mm_));
  auto fill = [&](const std::vector<Point2>& poly, auto&& set) {
    for (std::size_t iy = 0; iy < ny_; ++iy) {
      const double y = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_;
      const auto xs = row_crossings(poly, y);
      for (std::size_t k = 0; k + 1 < xs.size(); k += 2) {
        const double a = std::ceil((xs[k] - x0_mm_) * inv_cell_ - 0.5);
        const double b = std::floor((xs[k + 1] - x0_mm_) * inv_cell_ - 0.5);
        for (double ix = std::max(a, 0.0); ix <= std::min(b, static_cast<double>(nx_) - 1.0); ix += 1.0)
          set(top_[iy * nx_ + static_cast<std::size_t>(ix)]);
      }
    }
  };
  fill(spec.outline_mm, [&](float& t) { t = static_cast<float>(top_z_mm_); });
  for (const auto& pk : spec.pockets) {
    const float floor_z = static_cast<float>(std::max(pk.floor_z_mm, bottom_z_mm_));
    if (pk.polygon_mm.size() >= 3) {
      fill(pk.polygon_mm, [&](float& t) { t = std::min(t, floor_z); });
    } else {
      for (std::size_t iy = 0; iy < ny_; ++iy) {
        const double dy = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_ - pk.center_mm.y_mm;
        if (std::abs(dy) >= pk.radius_mm) continue;
        const double w = std::sqrt(pk.radius_mm * pk.radius_mm - dy * dy);
        const double a = std::ceil((pk.center_mm.x_mm - w - x0_mm_) * inv_cell_ - 0.5);
        const double b = std::floor((pk.center_mm.x_mm + w - x0_mm_) * inv_cell_ - 0.5);
        for (double ix = std::max(a, 0.0); ix <= std::min(b, static_cast<double>(nx_) - 1.0); ix += 1.0) {
          float& t = top_[iy * nx_ + static_cast<std::size_t>(ix)];
          t = std::min(t, floor_z);
        }
      }
    }
  }
}

double HeightMapStock::top_z_at_mm(double x_mm, double y_mm) const noexcept {
  const double fx = (x_mm - x0_mm_) * inv_cell_;
  const double fy = (y_mm - y0_mm_) * inv_cell_;
  if (!(fx >= 0.0 && fy >= 0.0)) return bottom_z_mm_;
  const auto ix = static_cast<std::size_t>(fx);
  const auto iy = static_cast<std::size_t>(fy);
  if (ix >= nx_ || iy >= ny_) return bottom_z_mm_;
  return static_cast<double>(top_[iy * nx_ + ix]);
}

double HeightMapStock::volume_mm3() const {
  double v = 0.0;
  for (float t : top_) v += std::max(static_cast<double>(t) - bottom_z_mm_, 0.0);
  return v * cell_mm_ * cell_mm_;
}

void HeightMapStock::lower_cells_in_row(std::size_t iy, double xa, double xb, const ToolGeometry& tool,
                                        const std::array<double, 3>& p0, const std::array<double, 3>& p1,
                                        double& removed) {
  const double a = std::max(std::ceil((xa - x0_mm_) * inv_cell_ - 0.5), 0.0);
  const double b = std::min(std::floor((xb - x0_mm_) * inv_cell_ - 0.5), static_cast<double>(nx_) - 1.0);
  if (a > b) return;
  const double R = tool.radius_mm();
  const double y = y0_mm_ + (static_cast<double>(iy) + 0.5) * cell_mm_;
  const double Dx = p1[0] - p0[0];
  const double Dy = p1[1] - p0[1];
  const double L2 = Dx * Dx + Dy * Dy;
  const double inv_L2 = L2 > 0.0 ? 1.0 / L2 : 0.0;
  float* row = top_.data() + iy * nx_;
  for (auto ix = static_cast<std::size_t>(a); ix <= static_cast<std::size_t>(b); ++ix) {
    const double top = static_cast<double>(row[ix]);
    if (top <= bottom_z_mm_) continue;
    const double x = x0_mm_ + (static_cast<double>(ix) + 0.5) * cell_mm_;
    const double s = std::clamp(((x - p0[0]) * Dx + (y - p0[1]) * Dy) * inv_L2, 0.0, 1.0);
    const double ex = x - (p0[0] + s * Dx);
    const double ey = y - (p0[1] + s * Dy);
    const double d2 = ex * ex + ey * ey;
    if (d2 > R * R) continue;
    const double z_new = p0[2] + s * (p1[2] - p0[2]) + tool.bottom_height_mm(std::sqrt(d2));
    if (z_new >= top) continue;
    const double z_set = std::max(z_new, bottom_z_mm_);
    removed += top - z_set;
    row[ix] = static_cast<float>(z_set);
  }
}

double HeightMapStock::remove_sweep(const ToolGeometry& tool, const std::array<double, 3>& p0_mm,
                                    const std::array<double, 3>& p1_mm, bool whole) {
  const double R = tool.radius_mm();
  const double Rc = R - tool.corner_radius_mm;
  const double Dx = p1_mm[0] - p0_mm[0];
  const double Dy = p1_mm[1] - p0_mm[1];
  const double L = std::hypot(Dx, Dy);
  const bool incremental = !whole && p1_mm[2] >= p0_mm[2] - 1e-9 && L <= 3.0 * cell_mm_;
  if (incremental && L == 0.0) return 0.0;
  double removed = 0.0;
  const double ylo = (incremental ? p1_mm[1] : std::min(p0_mm[1], p1_mm[1])) - R;
  const double yhi = (incremental ? p1_mm[1] : std::max(p0_mm[1], p1_mm[1])) + R;
  const double ia = std::max(std::ceil((ylo - y0_mm_) * inv_cell_ - 0.5), 0.0);
  const double ib = std::min(std::floor((yhi - y0_mm_) * inv_cell_ - 0.5), static_cast<double>(ny_) - 1.0);
  const double mx = 0.5 * (p0_mm[0] + p1_mm[0]);
  const double my = 0.5 * (p0_mm[1] + p1_mm[1]);
  for (double fiy = ia; fiy <= ib; fiy += 1.0) {
    const auto iy = static_cast<std::size_t>(fiy);
    const double y = y0_mm_ + (fiy + 0.5) * cell_mm_;
    if (!incremental) {
      lower_cells_in_row(iy, std::min(p0_mm[0], p1_mm[0]) - R, std::max(p0_mm[0], p1_mm[0]) + R, tool, p0_mm, p1_mm,
                         removed);
      continue;
    }
    const double dy1 = y - p1_mm[1];
    if (std::abs(dy1) > R) continue;
    const double w1 = std::sqrt(R * R - dy1 * dy1);
    double xa = p1_mm[0] - w1;
    double xb = p1_mm[0] + w1;
    // Only cells ahead of the bisector of p0 p1 come closer to the axis.
    if (Dx > 0.0) {
      xa = std::max(xa, mx - (y - my) * Dy / Dx);
    } else if (Dx < 0.0) {
      xb = std::min(xb, mx - (y - my) * Dy / Dx);
    } else if ((y - my) * Dy <= 0.0) {
      continue;
    }
    if (xa > xb) continue;
    // Cells over the flat core of the tool at p0 are already at the tip height.
    const double dy0 = y - p0_mm[1];
    if (Rc > 0.0 && std::abs(dy0) < Rc) {
      const double w0 = std::sqrt(Rc * Rc - dy0 * dy0);
      const double ca = p0_mm[0] - w0;
      const double cb = p0_mm[0] + w0;
      if (xa < ca) lower_cells_in_row(iy, xa, std::min(xb, ca), tool, p0_mm, p1_mm, removed);
      if (xb > cb) lower_cells_in_row(iy, std::max(xa, cb), xb, tool, p0_mm, p1_mm, removed);
    } else {
      lower_cells_in_row(iy, xa, xb, tool, p0_mm, p1_mm, removed);
    }
  }
  return removed * cell_mm_ * cell_mm_;
}

}  // namespace twin::process
