// Machine definitions: the shipped FADAL 2216 file against Ozcan et al. 2017
// Tables 1 and 3 (typed in here from the paper), and every kind of bad input.
#include <filesystem>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/test_files.hpp"
#include "twin/core/error.hpp"
#include "twin/io/machine_file.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;

std::filesystem::path temp_yaml(const std::string& name, const std::string& text) {
  return test_support::write_file(std::filesystem::temp_directory_path() / "twin_machine_file_test" / name, text);
}

std::string fadal_text() { return test_support::slurp(TWIN_SOURCE_DIR "/scenarios/machines/fadal2216.yaml"); }

TEST(MachineFile, ShippedFadalMatchesOzcanTables) {
  const sim::MachineDefinition m = io::load_machine(io::resolve_machine_path("fadal2216"));
  const auto& x = m.axes[index(Axis::kX)];
  const auto& y = m.axes[index(Axis::kY)];
  // Table 1 (exact decimal values of the paper).
  EXPECT_EQ(x.drive.Ka_A_per_V, 6.4898);
  EXPECT_EQ(y.drive.Ka_A_per_V, 7.5768);
  EXPECT_EQ(x.drive.Kt_Nm_per_A, 0.4769);
  EXPECT_EQ(x.drive.J_kg_m2, 0.0077736);
  EXPECT_EQ(y.drive.J_kg_m2, 0.0098109);
  EXPECT_EQ(x.drive.B_kg_m2_per_s, 0.019811);
  EXPECT_EQ(y.drive.B_kg_m2_per_s, 0.28438);
  EXPECT_EQ(x.drive.rg_mm_per_rad, 1.5915);
  // Table 3.
  EXPECT_EQ(x.loop.Kp_V_per_mm, 500.0);
  EXPECT_EQ(y.loop.Kp_V_per_mm, 462.539);
  EXPECT_EQ(x.loop.Ki_V_per_s_mm, 70.0);
  EXPECT_EQ(y.loop.Kd_V_s_per_mm, 0.278);
  EXPECT_EQ(x.loop.K2_V_s_per_mm, -2.37e-6);
  EXPECT_EQ(y.loop.K2_V_s_per_mm, 5.55e-4);
  // design.md section 4 assumptions.
  EXPECT_EQ(m.Ts_s, 1e-4);
  EXPECT_EQ(m.encoder_resolution_mm, 0.001);
  EXPECT_EQ(x.drive.Tc_pos_Nm, 0.20);
  EXPECT_EQ(y.drive.Tc_neg_Nm, 0.28);
  EXPECT_EQ(x.loop.u_max_V, 10.0);
  EXPECT_TRUE(m.axes[index(Axis::kZ)].present);
}

TEST(MachineFile, RoundTripThroughYamlKeepsEveryParameter) {
  sim::MachineDefinition m = io::load_machine(io::resolve_machine_path("fadal2216"));
  sim::apply_set(m, "y.stribeck.Ts_static=0.45");
  sim::apply_set(m, "y.stribeck.ws=3");
  const auto p = temp_yaml("roundtrip.yaml", io::machine_to_yaml(m, "test"));
  const sim::MachineDefinition back = io::load_machine(p);
  for (Axis a : kAllAxes)
    for (const auto& spec : sim::axis_param_specs())
      EXPECT_EQ(sim::get_axis_param(back.axes[index(a)], spec), sim::get_axis_param(m.axes[index(a)], spec))
          << axis_name(a) << "." << spec.name;
  EXPECT_TRUE(back.axes[index(Axis::kY)].drive.effects.stribeck.enabled);
  EXPECT_FALSE(back.axes[index(Axis::kX)].drive.effects.stribeck.enabled);
}

TEST(MachineFile, UnknownKeyNamesFileAndKey) {
  std::string t = fadal_text();
  t.replace(t.find("    Kd: 0.3 "), 11, "    Kdd: 0.3");
  const auto p = temp_yaml("unknown.yaml", t);
  try {
    io::load_machine(p);
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr(p.string()));
    EXPECT_THAT(e.what(), HasSubstr("axes.x"));
    EXPECT_THAT(e.what(), HasSubstr("Kdd"));
  }
}

TEST(MachineFile, NonFiniteAndNonPhysicalValuesAreErrors) {
  std::string t = fadal_text();
  std::string bad = t;
  bad.replace(bad.find("J: 0.0077736"), 12, "J: .nan");
  EXPECT_THROW(io::load_machine(temp_yaml("nan.yaml", bad)), ConfigError);
  bad = t;
  bad.replace(bad.find("J: 0.0077736"), 12, "J: -0.0077");
  try {
    io::load_machine(temp_yaml("neg.yaml", bad));
    FAIL() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), HasSubstr("axis x"));
    EXPECT_THAT(e.what(), HasSubstr("J"));
    EXPECT_THAT(e.what(), HasSubstr("-0.0077"));
  }
  bad = t;
  bad.replace(bad.find("Ts: 1.0e-4"), 10, "Ts: fast  ");
  EXPECT_THROW(io::load_machine(temp_yaml("ts.yaml", bad)), ConfigError);
}

TEST(MachineFile, SetOverridesAndRejectsUnknowns) {
  sim::MachineDefinition m = io::load_machine(io::resolve_machine_path("fadal2216"));
  sim::apply_set(m, "x.J=0.008");
  EXPECT_EQ(m.axes[0].drive.J_kg_m2, 0.008);
  sim::apply_set(m, "Ts=2e-4");
  EXPECT_EQ(m.Ts_s, 2e-4);
  EXPECT_THROW(sim::apply_set(m, "q.J=1"), ConfigError);
  EXPECT_THROW(sim::apply_set(m, "x.Jay=1"), ConfigError);
  EXPECT_THROW(sim::apply_set(m, "x.J=abc"), ConfigError);
  EXPECT_THROW(sim::apply_set(m, "x.J=nan"), ConfigError);
  EXPECT_THROW(sim::apply_set(m, "x.J"), ConfigError);
  sim::apply_set(m, "x.Kt=-1");
  EXPECT_THROW(m.validate(), ConfigError);
}

}  // namespace
}  // namespace twin
