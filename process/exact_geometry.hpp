#pragma once
/// Exact 2D geometry of the stock at one height (CGAL, Epeck kernel, circle-
/// segment traits): a polygon outline minus disks, polygons and straight
/// tool sweeps, kept as a polygon set bounded by segments and circular arcs.
/// It is the engagement oracle of the tests (an exact Boolean costs
/// 0.2-3 ms, far too slow per tick; see workpiece.hpp for the fast query).
/// CGAL types stay inside exact_geometry.cpp.
#include <memory>
#include <vector>

#include "process/workpiece.hpp"

namespace twin::process {

/// A counter-clockwise arc of a circle, angles in rad from +x (math convention), start < end.
struct ArcInterval {
  double start_rad{0.0};
  double end_rad{0.0};
};

class ExactStock2D {
 public:
  /// Throws ConfigError when the outline has < 3 points or no area.
  explicit ExactStock2D(const std::vector<Point2>& outline_mm);
  ~ExactStock2D();
  ExactStock2D(ExactStock2D&&) noexcept;
  ExactStock2D& operator=(ExactStock2D&&) noexcept;
  ExactStock2D(const ExactStock2D&) = delete;
  ExactStock2D& operator=(const ExactStock2D&) = delete;

  void subtract_disk(Point2 center_mm, double radius_mm);
  void subtract_polygon(const std::vector<Point2>& polygon_mm);
  /// Removes the region a disk of radius_mm sweeps from a to b. The move must
  /// be parallel to x or y (so the sweep's corners lie exactly on the end
  /// circles); otherwise ConfigError.
  void subtract_axis_sweep(Point2 a_mm, Point2 b_mm, double radius_mm);
  /// The arcs of the circle (center, radius) that bound disk ∩ remaining
  /// material: where the tool's circle touches material.
  std::vector<ArcInterval> arcs_in_material(Point2 center_mm, double radius_mm) const;
  /// Area of the remaining material, mm^2.
  double area_mm2() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace twin::process
