#include "process/exact_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/General_polygon_set_2.h>
#include <CGAL/Gps_circle_segment_traits_2.h>
#include <fmt/format.h>

#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::process {
namespace {

using Kernel = CGAL::Exact_predicates_exact_constructions_kernel;
using Traits = CGAL::Gps_circle_segment_traits_2<Kernel>;
using PolygonSet = CGAL::General_polygon_set_2<Traits>;
using GeneralPolygon = Traits::General_polygon_2;
using XCurve = Traits::X_monotone_curve_2;

GeneralPolygon disk_polygon(Point2 c, double r) {
  Traits traits;
  const Kernel::FT rr = Kernel::FT(r) * Kernel::FT(r);
  Traits::Curve_2 full(Kernel::Circle_2(Kernel::Point_2(c.x_mm, c.y_mm), rr, CGAL::COUNTERCLOCKWISE));
  std::vector<boost::variant<Traits::Point_2, XCurve>> parts;
  traits.make_x_monotone_2_object()(full, std::back_inserter(parts));
  GeneralPolygon pg;
  for (auto& o : parts)
    if (auto* curve = boost::get<XCurve>(&o)) pg.push_back(*curve);
  return pg;
}

GeneralPolygon segment_polygon(const std::vector<Point2>& pts) {
  double area2 = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const Point2& a = pts[i];
    const Point2& b = pts[(i + 1) % pts.size()];
    area2 += a.x_mm * b.y_mm - b.x_mm * a.y_mm;
  }
  if (pts.size() < 3 || area2 == 0.0) throw ConfigError(fmt::format("exact geometry: a polygon of {} points has no area", pts.size()));
  std::vector<Point2> ccw = pts;
  if (area2 < 0.0) std::reverse(ccw.begin(), ccw.end());
  GeneralPolygon pg;
  for (std::size_t i = 0; i < ccw.size(); ++i) {
    const Point2& a = ccw[i];
    const Point2& b = ccw[(i + 1) % ccw.size()];
    pg.push_back(XCurve(Kernel::Point_2(a.x_mm, a.y_mm), Kernel::Point_2(b.x_mm, b.y_mm)));
  }
  return pg;
}

template <class CurveIt>
double boundary_area2(CurveIt begin, CurveIt end) {
  double a2 = 0.0;
  for (auto c = begin; c != end; ++c) {
    const double x0 = CGAL::to_double(c->source().x());
    const double y0 = CGAL::to_double(c->source().y());
    const double x1 = CGAL::to_double(c->target().x());
    const double y1 = CGAL::to_double(c->target().y());
    a2 += x0 * y1 - x1 * y0;
    if (c->is_circular()) {
      const auto& circle = c->supporting_circle();
      const double r2 = CGAL::to_double(circle.squared_radius());
      const double cx = CGAL::to_double(circle.center().x());
      const double cy = CGAL::to_double(circle.center().y());
      double t0 = std::atan2(y0 - cy, x0 - cx);
      double t1 = std::atan2(y1 - cy, x1 - cx);
      double sweep = (c->orientation() == CGAL::COUNTERCLOCKWISE) ? t1 - t0 : t0 - t1;
      while (sweep < 0.0) sweep += 2.0 * kPi;
      const double segment = r2 * (sweep - std::sin(sweep));
      a2 += (c->orientation() == CGAL::COUNTERCLOCKWISE) ? segment : -segment;
    }
  }
  return a2;
}

}  // namespace

struct ExactStock2D::Impl {
  PolygonSet set;
};

ExactStock2D::ExactStock2D(const std::vector<Point2>& outline_mm) : impl_(std::make_unique<Impl>()) {
  impl_->set = PolygonSet(segment_polygon(outline_mm));
}
ExactStock2D::~ExactStock2D() = default;
ExactStock2D::ExactStock2D(ExactStock2D&&) noexcept = default;
ExactStock2D& ExactStock2D::operator=(ExactStock2D&&) noexcept = default;

void ExactStock2D::subtract_disk(Point2 center_mm, double radius_mm) {
  if (!(radius_mm > 0.0)) throw ConfigError(fmt::format("exact geometry: disk radius {} mm must be > 0", radius_mm));
  impl_->set.difference(disk_polygon(center_mm, radius_mm));
}

void ExactStock2D::subtract_polygon(const std::vector<Point2>& polygon_mm) {
  impl_->set.difference(segment_polygon(polygon_mm));
}

void ExactStock2D::subtract_axis_sweep(Point2 a, Point2 b, double r) {
  subtract_disk(b, r);
  if (a.x_mm == b.x_mm && a.y_mm == b.y_mm) return;
  if (a.y_mm == b.y_mm) {
    subtract_polygon(StockSpec::rectangle(std::min(a.x_mm, b.x_mm), a.y_mm - r, std::max(a.x_mm, b.x_mm), a.y_mm + r));
  } else if (a.x_mm == b.x_mm) {
    subtract_polygon(StockSpec::rectangle(a.x_mm - r, std::min(a.y_mm, b.y_mm), a.x_mm + r, std::max(a.y_mm, b.y_mm)));
  } else {
    throw ConfigError(fmt::format("exact geometry: sweep ({}, {}) -> ({}, {}) is not parallel to x or y", a.x_mm,
                                  a.y_mm, b.x_mm, b.y_mm));
  }
  subtract_disk(a, r);
}

std::vector<ArcInterval> ExactStock2D::arcs_in_material(Point2 c, double r) const {
  PolygonSet q(disk_polygon(c, r));
  q.intersection(impl_->set);
  std::vector<Traits::General_polygon_with_holes_2> parts;
  q.polygons_with_holes(std::back_inserter(parts));
  const Kernel::Point_2 center(c.x_mm, c.y_mm);
  const Kernel::FT rr = Kernel::FT(r) * Kernel::FT(r);
  std::vector<ArcInterval> arcs;
  auto collect = [&](const GeneralPolygon& pg) {
    for (auto cv = pg.curves_begin(); cv != pg.curves_end(); ++cv) {
      if (!cv->is_circular()) continue;
      const auto& circle = cv->supporting_circle();
      if (circle.center() != center || circle.squared_radius() != rr) continue;
      double a = std::atan2(CGAL::to_double(cv->source().y()) - c.y_mm, CGAL::to_double(cv->source().x()) - c.x_mm);
      double b = std::atan2(CGAL::to_double(cv->target().y()) - c.y_mm, CGAL::to_double(cv->target().x()) - c.x_mm);
      if (cv->orientation() == CGAL::CLOCKWISE) std::swap(a, b);
      while (b <= a) b += 2.0 * kPi;
      arcs.push_back({a, b});
    }
  };
  for (const auto& pwh : parts) {
    collect(pwh.outer_boundary());
    for (auto h = pwh.holes_begin(); h != pwh.holes_end(); ++h) collect(*h);
  }
  return arcs;
}

double ExactStock2D::area_mm2() const {
  std::vector<Traits::General_polygon_with_holes_2> parts;
  impl_->set.polygons_with_holes(std::back_inserter(parts));
  double a2 = 0.0;
  for (const auto& pwh : parts) {
    a2 += boundary_area2(pwh.outer_boundary().curves_begin(), pwh.outer_boundary().curves_end());
    for (auto h = pwh.holes_begin(); h != pwh.holes_end(); ++h) a2 += boundary_area2(h->curves_begin(), h->curves_end());
  }
  return 0.5 * a2;
}

}  // namespace twin::process
