#pragma once
/// Contour-parallel clearing of a rectangular pocket, written as a part
/// program (.nc) for the twin's G-code subset.
///
/// The tool enters at one end of the pocket's centre line (through a
/// pre-drilled hole the stock must have there), cuts along it, then spirals outward on
/// rectangles inset from the pocket walls by R + k s (k = K .. 0, s the
/// stepover), ending on the wall-finishing loop inset by R. Every move is
/// parallel to x or y; loops run counter-clockwise (climb milling with M3).
#include <array>
#include <string>
#include <vector>

#include "process/workpiece.hpp"

namespace twin::process {

struct PocketProgramSpec {
  double x0_mm{0.0};
  double y0_mm{0.0};
  double x1_mm{40.0};
  double y1_mm{30.0};
  double tool_diameter_mm{10.0};
  double stepover_mm{4.0};
  double depth_z_mm{-1.0};       ///< tool-tip z while cutting
  double safe_z_mm{5.0};
  double feed_mm_per_min{500.0};
  double plunge_feed_mm_per_min{100.0};
  double spindle_rpm{1200.0};
  double blend_tolerance_mm{0.01};   ///< G64 P
  /// Throws ConfigError: pocket narrower than the tool, stepover outside (0, D], feeds <= 0, safe_z <= depth.
  void validate() const;
};

struct PocketProgram {
  std::vector<std::array<double, 3>> cut_path_mm;   ///< the cutting polyline at depth, first point = entry
  std::string gcode;
};

/// Inset of a convex polygon (counter-clockwise) by d_mm (each edge moved
/// inward by d and consecutive edges intersected). Throws ConfigError when
/// the polygon is not convex and counter-clockwise.
std::vector<Point2> inset_convex_polygon(const std::vector<Point2>& ccw_polygon, double d_mm);

PocketProgram make_rectangular_pocket_program(const PocketProgramSpec& spec);

}  // namespace twin::process
