// The effect catalogue and the effects' equations, each checked against
// something outside them.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <set>
#include <string>

#include "feeddrive/effect_catalogue.hpp"
#include "feeddrive/effect_torques.hpp"

namespace twin::feeddrive {
namespace {

// Oracle: the names of spec/measured-data.md's table of effects a model may
// lack, written out here from the spec; the drive's catalogue holds the
// drive-side ones by exactly those names (plus smooth_friction,
// rising_friction and load_dependent_friction, which the spec's catalogue
// allows: "its own catalogue may hold more").
TEST(EffectCatalogue, NamesAreTheSpecs) {
  const std::set<std::string> spec{"stribeck",   "cogging",     "screw_pitch_error",
                                   "backlash",   "constant_load", "position_dependent_friction",
                                   "delay",      "compliance",  "current_saturation"};
  std::set<std::string> ours;
  for (std::size_t i = 0; i < kDriveEffectCount; ++i)
    ours.insert(std::string(effect_name(static_cast<EffectKind>(i))));
  for (const auto& n : spec) EXPECT_TRUE(ours.count(n)) << n;
  EXPECT_EQ(ours.size(), spec.size() + 3);
  EXPECT_TRUE(ours.count("smooth_friction"));
  EXPECT_TRUE(ours.count("rising_friction"));
  EXPECT_TRUE(ours.count("load_dependent_friction"));
}

// Oracle: a parameter's qualified name is its effect's name, a dot and its
// own name (the form machine files and --set use), and it sets the field it
// names: writing through `ref` is read back from the struct.
TEST(EffectCatalogue, ParametersNameAndSetTheirField) {
  const EffectParamDef& ws = effect_param_def(EffectParam::stribeck_ws);
  EXPECT_EQ(ws.qualified, "stribeck.ws");
  EXPECT_EQ(ws.unit, "rad/s");
  DriveEffects e;
  ws.ref(e) = 2.5;
  EXPECT_EQ(e.stribeck.ws_rad_per_s, 2.5);
  const EffectParamDef& gap = effect_param_def(EffectParam::backlash_gap_mm);
  gap.ref(e) = 0.01;
  EXPECT_EQ(e.backlash.gap_mm, 0.01);
  EXPECT_EQ(gap.effect, EffectKind::kBacklash);
  effect_def(EffectKind::kBacklash).enabled(e) = true;
  EXPECT_TRUE(e.backlash.enabled);
  EXPECT_TRUE(EffectParam::compliance_K_Nm_per_rad == "K_Nm_per_rad");
  EXPECT_TRUE(EffectParam::compliance_K_Nm_per_rad == "compliance.K_Nm_per_rad");
  EXPECT_FALSE(EffectParam::compliance_K_Nm_per_rad == "gap_mm");
}

// Oracle: the cogging work is the integral of the cogging torque over the
// motor angle, here by the composite Simpson rule on 20000 intervals (error
// at most (b - a) h^4 max|T| / 180 = 1.6e-12 J in angle units). Tolerance 1e-10 J.
TEST(EffectTorques, CoggingWorkIsTheIntegralOfItsTorque) {
  const double A = 0.07, n = 6.0, phase = 0.3, rg = 10.0 / (2.0 * std::numbers::pi);
  const double xa = 1.0, xb = 23.0;
  const int N = 20000;
  const double h = (xb - xa) / N;
  double sum = 0.0;
  for (int i = 0; i <= N; ++i) {
    const double w = (i == 0 || i == N) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    sum += w * cogging_torque_Nm(A, n, phase, xa + i * h, rg);
  }
  const double simpson_J = sum * h / 3.0 / rg;  // d theta = dx / rg
  EXPECT_NEAR(cogging_work_J(A, n, phase, xa, xb, rg), simpson_J, 1e-10);
}

// Oracle: the steepest slope of (Ts - Tc) exp(-(w/ws)^2) lies at w = ws/sqrt(2)
// (the zero of the second derivative); a central difference there with
// step 1e-6 ws errs by ~1e-13 (truncation) and ~1e-10 (rounding) relative.
// Tolerance 1e-8 relative.
TEST(EffectTorques, StribeckMaxSlopeIsTheSteepestSlope) {
  const double Ts = 0.6, Tc = 0.35, ws = 1.7;
  const double w = ws / std::sqrt(2.0), d = 1e-6 * ws;
  const double slope = (stribeck_excess_Nm(Ts, Tc, w + d, ws) - stribeck_excess_Nm(Ts, Tc, w - d, ws)) / (2.0 * d);
  EXPECT_NEAR(-slope, stribeck_max_slope(Ts, Tc, ws), 1e-8 * stribeck_max_slope(Ts, Tc, ws));
  EXPECT_DOUBLE_EQ(stribeck_excess_Nm(Ts, Tc, 0.0, ws), Ts - Tc);
  EXPECT_NEAR(stribeck_shape(ws, ws), std::exp(-1.0), 1e-15);
}

// Oracle: the lead error repeats every period and is A sin(phase) at x = 0;
// the band friction holds inside [start, end] (both ends included) only.
TEST(EffectTorques, ScrewErrorPeriodicAndBandBounded) {
  const double A = 0.004, P = 8.0, phase = 0.5;
  EXPECT_NEAR(screw_pitch_error_mm(A, P, phase, 0.0), A * std::sin(phase), 1e-18);
  EXPECT_NEAR(screw_pitch_error_mm(A, P, phase, 3.3), screw_pitch_error_mm(A, P, phase, 3.3 + 5 * P), 1e-15);
  EXPECT_EQ(band_friction_Nm(0.1, 40.0, 60.0, 40.0), 0.1);
  EXPECT_EQ(band_friction_Nm(0.1, 40.0, 60.0, 60.0), 0.1);
  EXPECT_EQ(band_friction_Nm(0.1, 40.0, 60.0, 60.0001), 0.0);
  EXPECT_EQ(saturated_current_A(-7.0, 5.0), -5.0);
  EXPECT_NEAR(smooth_friction_Nm(0.3, 1e9, 1.0), 0.3, 1e-15);
}

}  // namespace
}  // namespace twin::feeddrive
