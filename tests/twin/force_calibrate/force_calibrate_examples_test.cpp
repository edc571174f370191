// `twin calibrate` on force series against the truth of the two shared
// example series (made by an independent generator; their READMEs hold the
// truth, copied here with the README as the oracle).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "twin/force_calibrate/force_calibrate.hpp"

namespace twin::analysis::force {
namespace {

const std::filesystem::path kExamples = std::filesystem::path(TWIN_SHARED_DIR) / "data" / "examples";

double rel(double a, double b) { return std::abs(a - b) / std::abs(b); }

/// The report of `r` kept in the build tree as NAME_report.json, for a reader of a failure.
void keep_report(const ForceCalibration& r, const std::string& name) {
  std::ofstream(std::filesystem::path(TWIN_BINARY_DIR) / "tests" / (name + "_report.json"))
      << force_report_json(r).dump(2);
}

/// Expects the identified cutting (a) and edge (e) coefficients within 2 % of the README's.
void expect_coefficients_within_2_percent(const ForceCalibration& r, const std::array<double, 3>& a,
                                          const std::array<double, 3>& e) {
  const auto& k = r.after.k;
  for (std::size_t q = 0; q < 3; ++q) {
    EXPECT_LT(rel(k.a[q], a[q]), 0.02) << "a[" << q << "]";
    EXPECT_LT(rel(k.e[q], e[q]), 0.02) << "e[" << q << "]";
  }
}

// forces_slot_series/README.md: Ktc 850, Krc 280, Kac 120 N/mm^2, Kte 22,
// Kre 28, Kae 4 N/mm; runout rho 0.008 mm at lambda 40 deg. Acceptance of
// issue 14: coefficients within 2 %, runout within 1 um and 5 deg. The plain
// average-force regression is biased by the runout (README: Ktc +1.4 %,
// Krc +5.5 %, ... Kae -14.6 %): checked too, to 0.5 % of those values (noise
// of the means: sigma 1.5 N over ~9000 samples).
TEST(ForceCalibrateExamples, SlotSeriesWithRunout) {
  const auto runs = load_force_series(kExamples / "forces_slot_series");
  ASSERT_EQ(runs.size(), 5u);
  const ForceCalibration r = calibrate_forces(runs);
  keep_report(r, "forces_slot_series");
  expect_coefficients_within_2_percent(r, {850.0, 280.0, 120.0}, {22.0, 28.0, 4.0});
  EXPECT_NEAR(r.after.runout.rho_mm, 0.008, 0.001);
  EXPECT_NEAR(r.after.runout.lambda_deg, 40.0, 5.0);
  ASSERT_FALSE(r.added.empty());
  EXPECT_EQ(r.added.front().effect, "runout");
  for (const auto& e : r.added) EXPECT_NE(e.effect, "sensor_resonance");
  EXPECT_NEAR(r.average_force.a[0], 862.0, 0.005 * 862.0);
  EXPECT_NEAR(r.average_force.a[1], 295.3, 0.005 * 295.3);
  EXPECT_NEAR(r.average_force.e[0], 21.0, 0.01 * 21.0);
  for (int a = 0; a < 3; ++a) EXPECT_LE(r.error_after[a], r.error_before[a]);
  // README: the anti-alias filter is a 2nd-order Butterworth at 3 kHz; the
  // sensor path finds it (15 %: its phase trades with the fitted delay).
  EXPECT_NEAR(r.after.lowpass_hz, 3000.0, 450.0);
}

// forces_slot_resonance/README.md: Ktc 780, Krc 240, Kac 90 N/mm^2, Kte 18,
// Kre 25, Kae 3 N/mm, no runout; a sensor mode at 1150 Hz, zeta 0.03.
// Acceptance: coefficients within 2 %, the resonance named with its
// frequency within 3 %; no runout added.
TEST(ForceCalibrateExamples, SlotSeriesWithSensorResonance) {
  const auto runs = load_force_series(kExamples / "forces_slot_resonance");
  const ForceCalibration r = calibrate_forces(runs);
  keep_report(r, "forces_slot_resonance");
  expect_coefficients_within_2_percent(r, {780.0, 240.0, 90.0}, {18.0, 25.0, 3.0});
  ASSERT_EQ(r.added.size(), 1u);
  EXPECT_EQ(r.added.front().effect, "sensor_resonance");
  ASSERT_TRUE(r.after.mode.has_value());
  EXPECT_LT(rel(r.after.mode->f_hz, 1150.0), 0.03);
  EXPECT_NEAR(r.after.lowpass_hz, 3000.0, 450.0);
  for (int a = 0; a < 3; ++a) EXPECT_LE(r.error_after[a], r.error_before[a]);
}

}  // namespace
}  // namespace twin::analysis::force
