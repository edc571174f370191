// Engagement and material removal of the height-map workpiece against
// analytic geometry: slot = 180 deg, radial depth ae gives acos(1 - 2 ae/D)
// (up and down milling), the inner 90 deg corner of a wall cut reaches its
// analytic maximum, removed volume = swept area x depth.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "process_test_util.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

using testing::design_coefficients;
using testing::flat_tool;

constexpr double kDeg = 180.0 / std::numbers::pi;
constexpr double kRpm = 1200.0, kTs = 1e-4, kV = 500.0 / 60.0;   // Duan 2025 conditions

ProcessSetup block_setup(std::vector<Point2> outline) {
  ProcessSetup s;
  s.tool = flat_tool(10.0, 2, 30.0);
  s.coefficients = design_coefficients();
  s.stock.outline_mm = std::move(outline);
  s.stock.top_z_mm = 0.0;
  s.stock.bottom_z_mm = -5.0;
  s.stock.cell_mm = 0.025;
  return s;
}

double mean_engagement(const std::vector<ProcessOutput>& outs) {
  double e = 0.0;
  for (const auto& o : outs) e += o.engagement_deg;
  return e / outs.size();
}

// Slot: the front half of the tool circle, 180 deg. The engaged arc is
// sampled every 1 deg and its ends sit at 0 and 180 deg exactly (the chip
// condition), so the error is the sampling: +-1 deg.
TEST(Engagement, SlotIs180Degrees) {
  MillingProcess proc(block_setup(StockSpec::rectangle(-20, -20, 40, 20)));
  proc.remove_swept({-30, 0, -1}, {0, 0, -1});
  const auto outs = testing::drive(proc, {0, 0, -1}, {kV, 0, 0}, kRpm, kTs, 500);
  EXPECT_NEAR(mean_engagement(outs), 180.0, 1.0);
}

// Radial depth ae, up milling (material on +y for a +x feed: immersion
// 0 .. acos(1 - 2ae/D)) and down milling (material on -y: 180 deg minus the
// same). Tolerance 1 deg: 1 deg sampling plus the probe one cell (0.025 mm)
// outside the edge radius, which moves the exit by
// acos((R - ae)/(R + 0.025)) - acos((R - ae)/R) < 0.3 deg here.
TEST(Engagement, RadialDepthGivesArccos) {
  const double R = 5.0;
  for (double ae : {0.5, 1.0, 2.5, 4.0}) {
    for (bool up : {true, false}) {
      auto outline = up ? StockSpec::rectangle(-20, R - ae, 40, 20) : StockSpec::rectangle(-20, -20, 40, -(R - ae));
      MillingProcess proc(block_setup(outline));
      proc.remove_swept({-30, 0, -1}, {0, 0, -1});
      const auto outs = testing::drive(proc, {0, 0, -1}, {kV, 0, 0}, kRpm, kTs, 300);
      EXPECT_NEAR(mean_engagement(outs), std::acos(1.0 - 2.0 * ae / 10.0) * kDeg, 1.0)
          << "ae " << ae << (up ? " up" : " down");
    }
  }
}

// Inner 90 deg corner of a wall cut with radial depth ae (Ozcan 2017 sec. 4):
// the tool runs +x along a wall (material y > 0) into a second wall (material
// x > 0), then -y along it. With beta = acos(1 - ae/R), at the corner point
// the circle meets material on [0, beta] (first wall, ahead of the swept
// band) and [90 - beta, 90 + beta] (second wall), i.e. 3 beta when
// beta <= 45 deg, 90 + beta otherwise; before it the second arc is smaller,
// after it the first wall's arc shrinks and [90 - beta, 90] is swept. So the
// maximum along the path is this value. Tolerance 2 deg: sampling (1 deg)
// plus the probe (< 0.3 deg per arc end, 3 ends).
TEST(Engagement, InnerCornerReachesAnalyticMaximum) {
  const double R = 5.0;
  for (double ae : {1.0, 2.0}) {
    ProcessSetup s = block_setup(StockSpec::rectangle(-40, -40, 20, 20));
    s.stock.pockets.push_back(PocketFeature{StockSpec::rectangle(-41, -41, 0, 0), {}, 0.0, -5.0});
    MillingProcess proc(s);
    const double c = -R + ae;   // tool-centre offset from both walls
    const int n1 = static_cast<int>(std::lround((c + 25.0) / kV / kTs));
    auto a = testing::drive(proc, {-25.0, c, -1}, {kV, 0, 0}, kRpm, kTs, n1);
    auto b = testing::drive(proc, {c, c, -1}, {0, -kV, 0}, kRpm, kTs, 12000);
    double peak = 0.0;
    for (const auto& o : a) peak = std::max(peak, o.engagement_deg);
    for (const auto& o : b) peak = std::max(peak, o.engagement_deg);
    const double beta = std::acos(1.0 - ae / R) * kDeg;
    const double expected = beta <= 45.0 ? 3.0 * beta : 90.0 + beta;
    EXPECT_NEAR(peak, expected, 2.0) << "ae " << ae;
    // Far from the corner the wall cut is back to beta on each leg.
    EXPECT_NEAR(a[a.size() / 3].engagement_deg, beta, 1.0);
    EXPECT_NEAR(b.back().engagement_deg, beta, 1.0);
    // The force rises with the engaged arc: peak resultant in the corner
    // exceeds the straight-wall peak.
    double f_wall = 0.0, f_corner = 0.0;
    for (std::size_t k = a.size() / 3; k < a.size() / 3 + 500; ++k)
      f_wall = std::max(f_wall, std::hypot(a[k].F_N[0], a[k].F_N[1]));
    for (std::size_t k = a.size() - 250; k < a.size(); ++k)
      f_corner = std::max(f_corner, std::hypot(a[k].F_N[0], a[k].F_N[1]));
    for (std::size_t k = 0; k < 250; ++k) f_corner = std::max(f_corner, std::hypot(b[k].F_N[0], b[k].F_N[1]));
    EXPECT_GT(f_corner, f_wall);
  }
}

// A straight slot of length L with a flat end mill of diameter D at depth ap
// removes D L ap plus the entry half disk pi D^2/8 ap (the tool enters from
// outside the stock). Cells of 0.025 mm miss or add material along the
// boundary only: relative error ~ cell/D, 0.5 %.
TEST(Workpiece, SlotRemovesSweptVolume) {
  ProcessSetup s = block_setup(StockSpec::rectangle(0, -20, 60, 20));
  MillingProcess proc(s);
  const double v0 = proc.stock().volume_mm3();
  EXPECT_NEAR(v0, 60.0 * 40.0 * 5.0, 1e-6 * v0);
  double removed = 0.0;
  const int ticks = static_cast<int>(std::lround(30.0 / kV / kTs));
  for (const auto& o : testing::drive(proc, {-10, 0, -1.5}, {kV, 0, 0}, kRpm, kTs, ticks)) removed += o.removed_mm3;
  const double x_end = -10 + kV * kTs * ticks;
  const double expected = (10.0 * x_end + std::numbers::pi * 25.0 / 2.0) * 1.5;
  EXPECT_NEAR(removed, expected, 0.005 * expected);
  EXPECT_NEAR(v0 - proc.stock().volume_mm3(), removed, 1e-6 * v0);
}

// A bull-nose tool (R 5, r 1.5) plunged to depth ap < r leaves a floor of
// radius R - r and the fillet: removed volume = volume of revolution of the
// profile, V = pi (R-r)^2 ap + 2 pi int_0^ap (R - r + sqrt(r^2 - (r - z)^2))^2 - (R-r)^2 ... computed
// here by a 1e5-point midpoint rule of V = int_0^ap pi radius(z)^2 dz. Cell error ~ 0.5 %.
TEST(Workpiece, BullNosePlungeRemovesVolumeOfRevolution) {
  ProcessSetup s = block_setup(StockSpec::rectangle(-20, -20, 20, 20));
  s.tool.shape = ToolShape::kBullNose;
  s.tool.corner_radius_mm = 1.5;
  MillingProcess proc(s);
  const double v0 = proc.stock().volume_mm3();
  proc.remove_swept({0, 0, -1.0}, {0, 0, -1.0});
  double V = 0.0;
  const int n = 100000;
  for (int i = 0; i < n; ++i) {
    const double z = (i + 0.5) / n * 1.0;
    const double r = s.tool.edge_radius_mm(z);
    V += std::numbers::pi * r * r / n;
  }
  EXPECT_NEAR(v0 - proc.stock().volume_mm3(), V, 0.005 * V);
}

TEST(Workpiece, InvalidStockThrows) {
  StockSpec s;
  s.outline_mm = {{0, 0}, {1, 0}};
  EXPECT_THROW(s.validate("t"), ConfigError);
  s.outline_mm = StockSpec::rectangle(0, 0, 1000, 1000);
  s.cell_mm = 0.01;
  EXPECT_THROW(s.validate("t"), ConfigError);   // 1e10 cells
}

}  // namespace
}  // namespace twin::process
