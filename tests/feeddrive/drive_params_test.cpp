// Oracle: the validation contract of DriveParams::validate and of DriveBank's
// constructor: a bad value throws ConfigError whose one-line message names the
// place, the field and the value.
#include <gtest/gtest.h>
#include <gmock/gmock.h>

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include "fadal_fixture.hpp"
#include "feeddrive/drive_bank.hpp"
#include "twin/core/error.hpp"

namespace twin::feeddrive {
namespace {

using ::testing::HasSubstr;

struct BadCase {
  std::string field;
  std::function<void(DriveParams&)> spoil;
};

TEST(DriveParamsValidate, FadalAxesAreValid) {
  EXPECT_NO_THROW(testing::fadal_x().validate("x"));
  EXPECT_NO_THROW(testing::fadal_y().validate("y"));
}

TEST(DriveParamsValidate, RejectsNonPhysicalValuesNamingTheField) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<BadCase> cases{
      {"J_kg_m2", [](DriveParams& p) { p.J_kg_m2 = 0.0; }},
      {"J_kg_m2", [&](DriveParams& p) { p.J_kg_m2 = nan; }},
      {"Ka_A_per_V", [](DriveParams& p) { p.Ka_A_per_V = -1.0; }},
      {"Kt_Nm_per_A", [](DriveParams& p) { p.Kt_Nm_per_A = 0.0; }},
      {"rg_mm_per_rad", [](DriveParams& p) { p.rg_mm_per_rad = 0.0; }},
      {"B_kg_m2_per_s", [](DriveParams& p) { p.B_kg_m2_per_s = -0.1; }},
      {"B_kg_m2_per_s", [&](DriveParams& p) { p.B_kg_m2_per_s = inf; }},
      {"Tc_pos_Nm", [](DriveParams& p) { p.Tc_pos_Nm = -0.2; }},
      {"Tc_neg_Nm", [&](DriveParams& p) { p.Tc_neg_Nm = nan; }},
      {"effects.stribeck.Ts_static_Nm", [](DriveParams& p) { p.effects.stribeck = {true, 0.1, 1.0}; }},
      {"effects.stribeck.ws_rad_per_s", [](DriveParams& p) { p.effects.stribeck = {true, 0.5, 0.0}; }},
      {"effects.compliance.K_Nm_per_rad", [](DriveParams& p) { p.effects.compliance = {true, 0.0, 0.0, 0.5}; }},
      {"effects.compliance.load_fraction", [](DriveParams& p) { p.effects.compliance = {true, 1e3, 0.0, 1.0}; }},
      {"effects.current_saturation.i_max_A", [](DriveParams& p) { p.effects.current_saturation = {true, 0.0}; }},
      {"effects.delay.delay_s", [](DriveParams& p) { p.effects.delay = {true, -1e-4}; }},
      {"effects.backlash.gap_mm", [](DriveParams& p) { p.effects.backlash = {true, -0.01}; }},
      {"effects.screw_pitch_error.period_mm", [](DriveParams& p) { p.effects.screw_pitch_error = {true, 0.001, 0.0, 0.0}; }},
      {"effects.cogging.cycles_per_rev", [](DriveParams& p) { p.effects.cogging = {true, 0.1, 0.0, 0.0}; }},
      {"effects.position_dependent_friction.x_end_mm",
       [](DriveParams& p) { p.effects.position_dependent_friction = {true, 0.1, 10.0, 5.0}; }},
      {"effects.constant_load.torque_Nm", [&](DriveParams& p) { p.effects.constant_load = {true, inf}; }},
  };
  for (const BadCase& c : cases) {
    DriveParams p = testing::fadal_x();
    c.spoil(p);
    try {
      p.validate("machine.yaml: y");
      ADD_FAILURE() << "no error for " << c.field;
    } catch (const ConfigError& e) {
      const std::string msg = e.what();
      EXPECT_THAT(msg, HasSubstr("machine.yaml: y: " + c.field + " = "));
      EXPECT_THAT(msg, HasSubstr("must be"));
      EXPECT_EQ(msg.find('\n'), std::string::npos);
    }
  }
}

TEST(DriveBankConstruct, RejectsBadParamsAndOptions) {
  DriveParams p = testing::fadal_x();
  p.J_kg_m2 = -0.008;
  try {
    DriveBank bank({testing::fadal_x(), p}, 1e-4);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_THAT(std::string(e.what()), HasSubstr("axis y: J_kg_m2 = -0.008 must be > 0"));
  }
  EXPECT_THROW(DriveBank({testing::fadal_x()}, 0.0), ConfigError);
  IntegratorOptions o;
  o.rtol = -1.0;
  EXPECT_THROW(DriveBank({testing::fadal_x()}, 1e-4, o), ConfigError);
  DriveBank bank({testing::fadal_x()}, 1e-4);
  EXPECT_THROW(bank.advance(0.0, 1e-4, {{std::nan(""), 0.0}}), ModelError);
  EXPECT_THROW(bank.reset({0.0, 1.0}), ConfigError);
}

}  // namespace
}  // namespace twin::feeddrive
