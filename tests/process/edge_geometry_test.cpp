// The two geometry points of the force model that an independent reference
// found wrong: the runout radius must follow the helical flute along z, and
// the bull-nose corner must be weighed by its true arc length.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "process/milling_force.hpp"
#include "process/tool.hpp"

namespace twin::process {
namespace {

constexpr double kPi = std::numbers::pi;

ToolGeometry bull_nose_d10_r15() {
  ToolGeometry t;
  t.shape = ToolShape::kBullNose;
  t.diameter_mm = 10.0;
  t.flutes = 1;
  t.helix_deg = 0.0;
  t.corner_radius_mm = 1.5;
  t.flute_length_mm = 22.0;
  return t;
}

// Oracle: the corner arc from the tip (kappa = 0) to height ap has length
// r acos(1 - ap/r) (circle arc); at r 1.5 mm, ap 1 mm: 1.84644 mm. The model
// slices the corner in equal steps of kappa and cuts the top element at ap,
// so the only error is rounding: 1e-9 mm.
TEST(EdgeGeometry, BullNoseCornerEdgeLengthIsTheArcLength) {
  for (double dz : {0.05, 0.1, 0.3}) {
    ForceModelOptions o;
    o.dz_mm = dz;
    const MillingForceModel m(bull_nose_d10_r15(), CuttingCoefficients::linear(800, 250, 100, 25, 30, 5), 0.0, o);
    EXPECT_NEAR(m.edge_length_mm(1.0), 1.5 * std::acos(1.0 - 1.0 / 1.5), 1e-9) << "dz " << dz;
    EXPECT_NEAR(m.edge_length_mm(1.0), 1.846, 5e-4);
    // Above the corner the flank adds its height: r pi/2 + (ap - r).
    EXPECT_NEAR(m.edge_length_mm(3.2), 1.5 * kPi / 2 + 1.7, 1e-9) << "dz " << dz;
  }
}

// The same through the force sum: one flute, no helix, edge force only
// (Ktc negligible), flute at phi = 90 deg where it moves straight into the
// material: every element's dFt = Kte db points along +y on the tool, so
// Fy = Kte * (edge length) = 25 * 1.84644 N. Before the corner was sliced in
// kappa it came out 25 * 1.681 N (-9 %). Tolerance: Ktc h db, < 1e-6 N.
TEST(EdgeGeometry, EdgeForceOfTheCornerIsKteTimesArcLength) {
  ForceModelOptions o;
  o.dz_mm = 0.05;
  const MillingForceModel m(bull_nose_d10_r15(), CuttingCoefficients::linear(1e-6, 0.0, 0.0, 25.0, 0.0, 0.0), 0.0, o);
  const auto everywhere = [](double, double, double) { return true; };
  // Tip at z = -1, stock top at z = 0: ap = 1 mm.
  const ForceSample s = m.sample(0.5 * kPi, {0.0, 0.0, -1.0}, {0.1, 0.0}, 0.0, 0.0, everywhere);
  EXPECT_NEAR(s.F_tool_N[1], 25.0 * 1.5 * std::acos(1.0 - 1.0 / 1.5), 1e-6);
}

// Oracle: geometry. The tool axis sits rho off the spindle axis in the
// direction lambda of the rotating frame; flute j's point at height z lies
// on the tool's cylinder at the frame angle theta = j 2pi/N - z tan(beta)/R
// (the helix lags it), so its distance from the spindle axis is
// |rho e(lambda) + R e(theta)| = sqrt(R^2 + rho^2 + 2 R rho cos(theta - lambda)).
// The model's R + rho cos(lambda - theta) is its first-order form: the two
// differ by < rho^2/(2R) = 6.4e-6 mm here. A radius constant along the flute
// is off by up to rho |cos(a) - cos(a + z tan(beta)/R)| (1.5 um at z = 2 mm).
TEST(EdgeGeometry, RunoutRadiusFollowsTheHelix) {
  ToolGeometry t;
  t.diameter_mm = 10.0;
  t.flutes = 2;
  t.helix_deg = 30.0;
  t.runout_rho_mm = 0.008;
  t.runout_lambda_deg = 40.0;
  const double R = 5.0, rho = 0.008, lambda = 40.0 * kPi / 180.0;
  for (int j = 0; j < 2; ++j) {
    for (double z : {0.0, 1.0, 2.0, 5.0}) {
      const double theta = j * kPi - z * std::tan(30.0 * kPi / 180.0) / R;
      const double exact = std::sqrt(R * R + rho * rho + 2 * R * rho * std::cos(theta - lambda));
      EXPECT_NEAR(t.flute_radius_mm(j, z), exact, rho * rho / (2 * R)) << "flute " << j << " z " << z;
    }
  }
}

}  // namespace
}  // namespace twin::process
