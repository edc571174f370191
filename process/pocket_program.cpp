#include "process/pocket_program.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::process {

void PocketProgramSpec::validate() const {
  const double D = tool_diameter_mm;
  if (!(D > 0.0)) throw ConfigError(fmt::format("pocket: tool_diameter_mm = {} must be > 0", D));
  if (!(x1_mm - x0_mm > D && y1_mm - y0_mm > D))
    throw ConfigError(fmt::format("pocket: {} x {} mm is not wider than the tool ({} mm)", x1_mm - x0_mm,
                                  y1_mm - y0_mm, D));
  if (!(stepover_mm > 0.0 && stepover_mm <= D))
    throw ConfigError(fmt::format("pocket: stepover_mm = {} must be in (0, {}] mm", stepover_mm, D));
  if (!(feed_mm_per_min > 0.0 && plunge_feed_mm_per_min > 0.0 && spindle_rpm > 0.0))
    throw ConfigError("pocket: feed, plunge feed and spindle speed must be > 0");
  if (!(safe_z_mm > depth_z_mm)) throw ConfigError(fmt::format("pocket: safe_z_mm = {} must be above depth_z_mm = {}", safe_z_mm, depth_z_mm));
  if (!(blend_tolerance_mm >= 0.0)) throw ConfigError(fmt::format("pocket: blend_tolerance_mm = {} must be >= 0", blend_tolerance_mm));
}

std::vector<Point2> inset_convex_polygon(const std::vector<Point2>& poly, double d) {
  const std::size_t n = poly.size();
  if (n < 3) throw ConfigError("inset: a polygon needs at least 3 points");
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = poly[i];
    const Point2& b = poly[(i + 1) % n];
    const Point2& c = poly[(i + 2) % n];
    const double cross = (b.x_mm - a.x_mm) * (c.y_mm - b.y_mm) - (b.y_mm - a.y_mm) * (c.x_mm - b.x_mm);
    if (cross <= 0.0) throw ConfigError(fmt::format("inset: polygon is not convex counter-clockwise at point {}", (i + 1) % n));
  }
  // Each edge i as n_i . x = c_i with n_i its inward unit normal, moved by d.
  std::vector<std::array<double, 3>> lines;
  for (std::size_t i = 0; i < n; ++i) {
    const Point2& a = poly[i];
    const Point2& b = poly[(i + 1) % n];
    const double L = std::hypot(b.x_mm - a.x_mm, b.y_mm - a.y_mm);
    const double nx = -(b.y_mm - a.y_mm) / L;
    const double ny = (b.x_mm - a.x_mm) / L;
    lines.push_back({nx, ny, nx * a.x_mm + ny * a.y_mm + d});
  }
  std::vector<Point2> out;
  for (std::size_t i = 0; i < n; ++i) {
    const auto& l0 = lines[(i + n - 1) % n];
    const auto& l1 = lines[i];
    const double det = l0[0] * l1[1] - l0[1] * l1[0];
    out.push_back({(l0[2] * l1[1] - l0[1] * l1[2]) / det, (l0[0] * l1[2] - l0[2] * l1[0]) / det});
  }
  return out;
}

PocketProgram make_rectangular_pocket_program(const PocketProgramSpec& spec) {
  spec.validate();
  const double R = 0.5 * spec.tool_diameter_mm;
  const double s = spec.stepover_mm;
  const double W = spec.x1_mm - spec.x0_mm;
  const double H = spec.y1_mm - spec.y0_mm;
  const double xm = 0.5 * (spec.x0_mm + spec.x1_mm);
  const double ym = 0.5 * (spec.y0_mm + spec.y1_mm);
  const double z = spec.depth_z_mm;
  const std::vector<Point2> pocket = StockSpec::rectangle(spec.x0_mm, spec.y0_mm, spec.x1_mm, spec.y1_mm);
  // Loops k = 0 (walls) .. K (innermost with positive width and height).
  const double d_center = 0.5 * std::min(W, H);
  int K = 0;
  while (R + (K + 1) * s < d_center - 1e-9) ++K;
  PocketProgram prog;
  auto& path = prog.cut_path_mm;
  auto to = [&](double x, double y) {
    const auto& last = path.back();
    if (std::abs(last[0] - x) > 1e-12 || std::abs(last[1] - y) > 1e-12) path.push_back({x, y, z});
  };
  const std::vector<Point2> center_line = inset_convex_polygon(pocket, d_center);
  const double cx0 = std::min({center_line[0].x_mm, center_line[1].x_mm, center_line[2].x_mm, center_line[3].x_mm});
  const double cx1 = std::max({center_line[0].x_mm, center_line[1].x_mm, center_line[2].x_mm, center_line[3].x_mm});
  const double cy0 = std::min({center_line[0].y_mm, center_line[1].y_mm, center_line[2].y_mm, center_line[3].y_mm});
  const double cy1 = std::max({center_line[0].y_mm, center_line[1].y_mm, center_line[2].y_mm, center_line[3].y_mm});
  // The centre line is cut once, from the entry at one end to the other end,
  // where the loops start: no stretch of the path runs back over its own cut.
  const bool horizontal = cx1 - cx0 >= cy1 - cy0;
  const double x_start = horizontal ? cx1 : xm;
  if (horizontal) {
    path.push_back({cx0, ym, z});
    to(cx1, ym);
  } else {
    path.push_back({xm, cy1, z});
    to(xm, cy0);
  }
  for (int k = K; k >= 0; --k) {
    const std::vector<Point2> loop = inset_convex_polygon(pocket, R + k * s);
    const double a0 = loop[0].x_mm, b0 = loop[0].y_mm, a1 = loop[2].x_mm, b1 = loop[2].y_mm;
    to(x_start, b0);
    to(a1, b0);
    to(a1, b1);
    to(a0, b1);
    to(a0, b0);
    to(x_start, b0);
  }
  std::string g;
  g += "%\n";
  g += fmt::format("(rectangular pocket X{:.3f}..{:.3f} Y{:.3f}..{:.3f} at Z{:.3f}: contour-parallel, tool D{:.3f}, "
                   "stepover {:.3f}, {} loops)\n",
                   spec.x0_mm, spec.x1_mm, spec.y0_mm, spec.y1_mm, z, spec.tool_diameter_mm, s, K + 1);
  g += "(enters through a pre-drilled hole at the start of the centre line)\n";
  g += "G21 G90 G17\n";
  g += fmt::format("G64 P{:.4f}\n", spec.blend_tolerance_mm);
  g += fmt::format("S{:.0f} M3\n", spec.spindle_rpm);
  g += fmt::format("G0 Z{:.3f}\n", spec.safe_z_mm);
  g += fmt::format("G0 X{:.4f} Y{:.4f}\n", path[0][0], path[0][1]);
  g += fmt::format("G1 Z{:.4f} F{:.1f}\n", z, spec.plunge_feed_mm_per_min);
  for (std::size_t i = 1; i < path.size(); ++i) {
    g += fmt::format("G1 X{:.4f} Y{:.4f}", path[i][0], path[i][1]);
    g += (i == 1) ? fmt::format(" F{:.1f}\n", spec.feed_mm_per_min) : "\n";
  }
  g += fmt::format("G0 Z{:.3f}\n", spec.safe_z_mm);
  g += "M5\nM30\n%\n";
  prog.gcode = std::move(g);
  return prog;
}

}  // namespace twin::process
