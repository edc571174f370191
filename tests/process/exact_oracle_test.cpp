// The fast height-map engagement against the exact CGAL oracle along a whole
// contour-parallel pocket program, and the generated program against the
// closed-form area a round tool clears from a rectangular pocket.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "process/exact_geometry.hpp"
#include "process/milling_force.hpp"
#include "process/pocket_program.hpp"
#include "process/workpiece.hpp"
#include "process_test_util.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

constexpr double kPi = std::numbers::pi;

PocketProgramSpec oracle_pocket() {
  return {.x0_mm = 0, .y0_mm = 0, .x1_mm = 30, .y1_mm = 22, .tool_diameter_mm = 8, .stepover_mm = 3, .depth_z_mm = -1};
}

// Measure (deg) of the part of the exact arcs where the edge moves into the
// material (v . r > 0), by 0.01 deg sampling: error <= 0.02 deg per arc end.
double exact_front_measure_deg(const std::vector<ArcInterval>& arcs, double vx, double vy) {
  double sum = 0.0;
  for (const auto& a : arcs) {
    const int n = static_cast<int>(std::ceil((a.end_rad - a.start_rad) * 180.0 / kPi / 0.01));
    const double d = (a.end_rad - a.start_rad) / n;
    for (int i = 0; i < n; ++i) {
      const double t = a.start_rad + (i + 0.5) * d;
      if (vx * std::cos(t) + vy * std::sin(t) > 0.0) sum += d;
    }
  }
  return sum * 180.0 / kPi;
}

// Walk the program's cutting path in 0.05 mm steps through the height map;
// every 1 mm compare its engaged arc with the exact one (the stock cut up to
// the previous step in both). Tolerances: the map samples 0.5 deg and probes
// one cell (c = 0.025 mm) outside the edge radius. Where the tool circle runs
// tangent to a cut boundary (the flanks of a slot, the crescent just after a
// turn), that probe reads material over up to acos(R/(R + c)) = 6.4 deg
// (R = 4 mm) the exact arc does not have; the chip there is < 0.11 f_t.
// Hence each point within 7 deg, and the mean over the program within 1 deg.
TEST(ExactOracle, HeightMapEngagementAlongPocketProgram) {
  const PocketProgramSpec spec = oracle_pocket();
  const PocketProgram prog = make_rectangular_pocket_program(spec);
  const double R = 0.5 * spec.tool_diameter_mm;
  const Point2 hole{prog.cut_path_mm[0][0], prog.cut_path_mm[0][1]};
  StockSpec stock;
  stock.outline_mm = StockSpec::rectangle(-5, -5, 35, 27);
  stock.top_z_mm = 0;
  stock.bottom_z_mm = -3;
  stock.pockets.push_back(PocketFeature{{}, hole, R + 0.5, -3});
  HeightMapStock grid(stock);
  ExactStock2D exact(stock.outline_mm);
  exact.subtract_disk(hole, R + 0.5);
  ForceModelOptions opt;
  opt.engagement_step_deg = 0.5;
  const MillingForceModel model(testing::flat_tool(spec.tool_diameter_mm, 2, 0.0),
                                CuttingCoefficients::linear(800, 250, 0, 25, 30, 0), 0.0, opt);
  const auto material = [&](double x, double y, double z) { return grid.has_material(x, y, z); };
  const auto& path = prog.cut_path_mm;
  std::array<double, 3> prev = path[0];
  grid.remove_sweep(model.tool(), prev, prev, true);
  Point2 exact_at{prev[0], prev[1]};
  double travelled = 0.0, next_check = 1.0, max_err = 0.0, sum_err = 0.0, max_eng = 0.0;
  int checks = 0;
  for (std::size_t seg = 1; seg < path.size(); ++seg) {
    const auto a = path[seg - 1];
    const auto b = path[seg];
    const double L = std::hypot(b[0] - a[0], b[1] - a[1]);
    const int n = std::max(1, static_cast<int>(std::ceil(L / 0.05)));
    const double vx = (b[0] - a[0]) / L, vy = (b[1] - a[1]) / L;
    for (int i = 1; i <= n; ++i) {
      const double t = static_cast<double>(i) / n;
      const std::array<double, 3> cur{a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2]};
      travelled += L / n;
      if (travelled >= next_check) {
        next_check += 1.0;
        // Exact stock up to prev: exact_at and prev both lie on this segment.
        const Point2 p_prev{prev[0], prev[1]};
        exact.subtract_axis_sweep(exact_at, p_prev, R);
        exact_at = p_prev;
        const double e_exact = exact_front_measure_deg(exact.arcs_in_material({cur[0], cur[1]}, R), vx, vy);
        const double e_grid = model.engaged_arc_deg(cur, {vx, vy}, 0.5, grid.cell_mm(), material);
        const double err = std::abs(e_exact - e_grid);
        EXPECT_LT(err, 7.0) << "at s = " << travelled << " mm, p = (" << cur[0] << ", " << cur[1] << ")";
        max_err = std::max(max_err, err);
        sum_err += err;
        max_eng = std::max(max_eng, e_exact);
        ++checks;
      }
      grid.remove_sweep(model.tool(), prev, cur, false);
      if (i == n) {
        exact.subtract_axis_sweep(exact_at, {b[0], b[1]}, R);
        exact_at = {b[0], b[1]};
      }
      prev = cur;
    }
  }
  EXPECT_GT(checks, 100);
  EXPECT_LT(sum_err / checks, 1.0);
  std::printf("engagement, height map vs exact: %d points, max error %.2f deg, mean %.3f deg\n", checks, max_err,
              sum_err / checks);
  EXPECT_GT(max_eng, 90.0);   // the pocket corners engage more than a slot's half
  RecordProperty("max_error_deg", std::to_string(max_err));
  RecordProperty("mean_error_deg", std::to_string(sum_err / checks));
  // The cleared area: the pocket minus the four corner fillets a round tool
  // leaves, (1 - pi/4) R^2 each (closed form), from the exact set (1e-6
  // relative: exact arithmetic, area by chords plus circular segments).
  const double W = spec.x1_mm - spec.x0_mm, H = spec.y1_mm - spec.y0_mm;
  const double cleared = W * H - 4.0 * (1.0 - kPi / 4.0) * R * R;
  EXPECT_NEAR(40.0 * 32.0 - exact.area_mm2(), cleared, 1e-6 * cleared);
}

// The generator: every move parallel to x or y; the last loop runs at R from
// the walls; the centre is the entry point.
TEST(PocketProgram, LoopsAreAxisParallelAndFinishAtTheWalls) {
  const PocketProgramSpec spec = oracle_pocket();
  const PocketProgram prog = make_rectangular_pocket_program(spec);
  const auto& p = prog.cut_path_mm;
  ASSERT_GT(p.size(), 10u);
  EXPECT_EQ(p[0][0], 11.0);   // the centre line runs x 11..19 at y 11
  EXPECT_EQ(p[0][1], 11.0);
  double xmin = 1e9, xmax = -1e9, ymin = 1e9, ymax = -1e9;
  for (std::size_t i = 1; i < p.size(); ++i) {
    EXPECT_TRUE(p[i][0] == p[i - 1][0] || p[i][1] == p[i - 1][1]) << i;
    xmin = std::min(xmin, p[i][0]);
    xmax = std::max(xmax, p[i][0]);
    ymin = std::min(ymin, p[i][1]);
    ymax = std::max(ymax, p[i][1]);
  }
  EXPECT_DOUBLE_EQ(xmin, 4.0);
  EXPECT_DOUBLE_EQ(xmax, 26.0);
  EXPECT_DOUBLE_EQ(ymin, 4.0);
  EXPECT_DOUBLE_EQ(ymax, 18.0);
  EXPECT_NE(prog.gcode.find("G64 P0.0100"), std::string::npos);
  EXPECT_THROW(make_rectangular_pocket_program([] {
                 auto s = oracle_pocket();
                 s.stepover_mm = 9.0;
                 return s;
               }()),
               ConfigError);
}

// Inset of a convex polygon: a right triangle with legs 3, 4 inset by its
// inradius minus 0.5 leaves a similar triangle; against the closed form of a
// square inset by d: side - 2d.
TEST(PocketProgram, InsetConvexPolygon) {
  const auto sq = inset_convex_polygon(StockSpec::rectangle(0, 0, 10, 6), 1.5);
  EXPECT_DOUBLE_EQ(sq[0].x_mm, 1.5);
  EXPECT_DOUBLE_EQ(sq[0].y_mm, 1.5);
  EXPECT_DOUBLE_EQ(sq[2].x_mm, 8.5);
  EXPECT_DOUBLE_EQ(sq[2].y_mm, 4.5);
  EXPECT_THROW(inset_convex_polygon({{0, 0}, {0, 1}, {1, 0}}, 0.1), ConfigError);   // clockwise
}

// The saved program of scenarios/pocket_rectangle is the generator's output
// for that scenario's pocket (so the file can be regenerated and checked).
TEST(PocketProgram, SavedScenarioProgramIsGenerated) {
  const PocketProgramSpec s{.x0_mm = 0,
                            .y0_mm = 0,
                            .x1_mm = 40,
                            .y1_mm = 30,
                            .tool_diameter_mm = 10,
                            .stepover_mm = 4,
                            .depth_z_mm = -1,
                            .safe_z_mm = 5,
                            .feed_mm_per_min = 500,
                            .plunge_feed_mm_per_min = 100,
                            .spindle_rpm = 1200,
                            .blend_tolerance_mm = 0.01};
  const std::string generated = make_rectangular_pocket_program(s).gcode;
  std::FILE* f = std::fopen(TWIN_SOURCE_DIR "/scenarios/pocket_rectangle/program.nc", "rb");
  ASSERT_NE(f, nullptr);
  std::string saved;
  char buf[4096];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) saved.append(buf, n);
  std::fclose(f);
  if (saved != generated) {
    std::FILE* out = std::fopen(TWIN_BINARY_DIR "/pocket_rectangle_program.nc", "wb");
    if (out) {
      std::fwrite(generated.data(), 1, generated.size(), out);
      std::fclose(out);
    }
  }
  EXPECT_EQ(saved, generated) << "regenerated program written to " TWIN_BINARY_DIR "/pocket_rectangle_program.nc";
}

}  // namespace
}  // namespace twin::process
