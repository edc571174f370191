// `twin calibrate` on force series made by an independent generator
// (force_truth_generator.hpp: the textbook per-slice sum, no code shared with
// the twin), one undeclared effect per series, for every force effect of the
// catalogue (runout, size_effect, sensor_resonance, tool_wear) and none.
// Oracle: the generator's own parameters. Tolerances: those of issue 14's
// acceptance (coefficients 2 %, runout 1 um and 5 deg, a mode's frequency
// 3 %); a wear rate within 25 % (it is seen through a 20 % change of the
// force over the series under 1.5 N noise).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "tests/process/force_truth_generator.hpp"
#include "twin/force_calibrate/force_calibrate.hpp"
#include "twin/core/error.hpp"

namespace twin::analysis::force {
namespace {

using process::truth::TruthSeries;

std::filesystem::path scratch(const std::string& name) {
  const auto d = std::filesystem::path(TWIN_BINARY_DIR) / "tests" / "force_truth" / name;
  std::filesystem::remove_all(d);
  return d;
}

ForceCalibration calibrate_truth(const std::string& name, const TruthSeries& s) {
  const auto dir = scratch(name);
  process::truth::write_truth_series(dir, s);
  ForceCalibration r = calibrate_forces(load_force_series(dir));
  std::ofstream(dir / "report.json") << force_report_json(r).dump(2);   // for a reader of a failure
  return r;
}

std::vector<std::string> effects(const ForceCalibration& r) {
  std::vector<std::string> e;
  for (const auto& a : r.added) e.push_back(a.effect);
  return e;
}

void expect_coefficients(const ForceCalibration& r, const TruthSeries& s, double tol) {
  for (int q = 0; q < 3; ++q) {
    EXPECT_NEAR(r.after.k.a[q], s.Kc[q], tol * s.Kc[q]) << "cutting coefficient " << q;
    EXPECT_NEAR(r.after.k.e[q], s.Ke[q], tol * s.Ke[q]) << "edge coefficient " << q;
  }
}

void expect_no_rise(const ForceCalibration& r) {
  for (int a = 0; a < 3; ++a) EXPECT_LE(r.error_after[a], r.error_before[a] + 1e-9) << "axis " << a;
}

TEST(ForceCalibrateTruth, CleanSeriesIsNone) {
  const TruthSeries s;
  const ForceCalibration r = calibrate_truth("none", s);
  EXPECT_TRUE(r.added.empty()) << ::testing::PrintToString(effects(r));
  expect_coefficients(r, s, 0.02);
  // At the noise floor: the held-out error is the noise within 10 %.
  for (int a = 0; a < 3; ++a) EXPECT_LT(r.error_after[a], 1.1 * r.noise_floor[a]) << "axis " << a;
}

TEST(ForceCalibrateTruth, Runout) {
  TruthSeries s{.rho_mm = 0.010, .lambda_deg = 120.0};
  const ForceCalibration r = calibrate_truth("runout", s);
  EXPECT_EQ(effects(r), std::vector<std::string>{"runout"});
  EXPECT_NEAR(r.after.runout.rho_mm, 0.010, 0.001);
  EXPECT_NEAR(r.after.runout.lambda_deg, 120.0, 5.0);
  expect_coefficients(r, s, 0.02);
  expect_no_rise(r);
}

TEST(ForceCalibrateTruth, SizeEffect) {
  TruthSeries s{.Kc = {600.0, 180.0, 70.0}, .Kb = {700.0, 300.0, 90.0}, .c_per_mm = 40.0};
  const ForceCalibration r = calibrate_truth("size_effect", s);
  EXPECT_EQ(effects(r), std::vector<std::string>{"size_effect"});
  ASSERT_TRUE(r.after.k.exponential);
  EXPECT_GT(r.after.k.b[0], 0.0);   // K_t rises as the chip thins
  // The elemental force per unit width K_q(h) h + K_qe at the chips of the
  // series, against the truth: 3 % (the split between the exponential part
  // and the edge force is what the data pins least; their sum is the force).
  for (int q = 0; q < 3; ++q)
    for (double h : {0.02, 0.05, 0.1}) {
      const double truth = (s.Kc[q] + s.Kb[q] * std::exp(-s.c_per_mm * h)) * h + s.Ke[q];
      const double got = (r.after.k.a[q] + r.after.k.b[q] * std::exp(-r.after.k.c_per_mm * h)) * h + r.after.k.e[q];
      EXPECT_NEAR(got, truth, 0.03 * truth) << "direction " << q << " h " << h;
    }
  expect_no_rise(r);
}

TEST(ForceCalibrateTruth, SensorResonance) {
  TruthSeries s{.mode_f_hz = 1600.0, .mode_zeta = 0.04};
  const ForceCalibration r = calibrate_truth("sensor_resonance", s);
  EXPECT_EQ(effects(r), std::vector<std::string>{"sensor_resonance"});
  ASSERT_TRUE(r.after.mode.has_value());
  EXPECT_NEAR(r.after.mode->f_hz, 1600.0, 0.03 * 1600.0);
  expect_coefficients(r, s, 0.02);
  expect_no_rise(r);
}

TEST(ForceCalibrateTruth, ToolWear) {
  TruthSeries s;
  s.wear_per_mm = 0.004;   // +15 % over the ~36 mm of the series
  const ForceCalibration r = calibrate_truth("tool_wear", s);
  EXPECT_EQ(effects(r), std::vector<std::string>{"tool_wear"});
  // Identified at L_ref: the law's slope relative to the force at L_ref.
  const double w_truth_at_ref = s.wear_per_mm / (1.0 + s.wear_per_mm * r.after.wear_L_ref_mm);
  EXPECT_NEAR(r.after.wear_per_mm, w_truth_at_ref, 0.25 * w_truth_at_ref);
  expect_no_rise(r);
}

// Without spindle_deg the angle comes from the tooth pattern: a clean series
// still gives the coefficients within 2 %.
TEST(ForceCalibrateTruth, NoSpindleAngleUsesTheToothPattern) {
  TruthSeries s{.log_angle = false};
  const ForceCalibration r = calibrate_truth("no_angle", s);
  expect_coefficients(r, s, 0.02);
  EXPECT_TRUE(r.added.empty()) << ::testing::PrintToString(effects(r));
}

// Bad cut data: a one-line error naming the field.
TEST(ForceCalibrateTruth, BadMetaNamesTheField) {
  TruthSeries s{.fz_mm = {0.05}, .duration_s = 0.1};
  const auto dir = scratch("bad_meta");
  process::truth::write_truth_series(dir, s);
  const auto meta = dir / "fz0.050" / "meta.json";
  auto rewrite = [&](const std::string& from, const std::string& to) {
    std::ifstream in(meta);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos);
    text.replace(at, from.size(), to);
    std::ofstream(meta) << text;
  };
  rewrite("\"ap_mm\": 2, ", "");
  try {
    load_force_series(dir);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("cut.ap_mm"), std::string::npos) << m;
    EXPECT_NE(m.find("meta.json"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
  }
  rewrite("\"milling\": \"slot\"", "\"milling\": \"sideways\", \"ap_mm\": 2");
  try {
    load_force_series(dir);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.milling"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace twin::analysis::force
