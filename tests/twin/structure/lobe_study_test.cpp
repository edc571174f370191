// The cut study of a program and `twin lobes`. Oracles: the immersion of a
// straight cut of radial depth ae with a tool of diameter D is
// acos(1 - 2 ae / D) (up milling from 0, down milling to 180 deg), a slot
// 0-180 deg (the shipped scenarios say which cut they make); the critical
// depth at the scenario's speed is the boundary of the lobes computed on
// their own (process/stability_lobes, verified against closed forms in
// tests/process); the machine file's tool tip reads back as written.
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/support/test_files.hpp"
#include "twin/core/error.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/structure/lobe_study.hpp"

namespace twin::structure {
namespace {

constexpr double kDeg = 180.0 / std::numbers::pi;

using test_support::slurp;

std::filesystem::path work() {
  return test_support::fresh_dir(std::filesystem::temp_directory_path() / "twin_lobe_study_test" /
                                 test_support::current_test_name());
}

int sh(const std::filesystem::path& dir, const std::string& command) {
  return test_support::run_command(dir, command).exit_code;
}

std::string twin() { return test_support::twin_exe(); }

TEST(CutStudy, TheDefaultWallCutIsTwoMillimetresOfATenMillimetreTool) {
  // fadal_pocket_corner: "Wall cut with radial depth 2 mm ... ap 1 mm", a
  // 10 mm cutter. Angles are probed at 1 deg: within 1.5 deg.
  const io::Scenario s = io::load_scenario(io::default_scenario_path());
  const controller::Program p = io::parse_program(s);
  const auto cuts = study_cuts(p, *s.process_setup);
  ASSERT_FALSE(cuts.empty());
  const CutCondition& c = cuts.front();
  const double arc_deg = std::acos(1.0 - 2.0 * 2.0 / 10.0) * kDeg;
  const double st = c.immersion.phi_st_rad * kDeg, ex = c.immersion.phi_ex_rad * kDeg;
  EXPECT_NEAR(ex - st, arc_deg, 1.5);
  EXPECT_TRUE(st < 1.5 || ex > 178.5) << st << " " << ex;  // one side of the tool
  EXPECT_NEAR(c.ap_mm, 1.0, 0.03);
  EXPECT_NEAR(c.spindle_rpm, 1200.0, 1e-9);
}

TEST(CutStudy, ASlotIsFullImmersion) {
  const io::Scenario s = io::load_scenario(io::resolve_scenario_path("slot"));
  const auto cuts = study_cuts(io::parse_program(s), *s.process_setup);
  ASSERT_FALSE(cuts.empty());
  EXPECT_NEAR(cuts.front().immersion.phi_st_rad * kDeg, 0.0, 1.5);
  EXPECT_NEAR(cuts.front().immersion.phi_ex_rad * kDeg, 180.0, 1.5);
}

TEST(LobeStudy, CriticalDepthIsTheLobesBoundaryAtTheScenarioSpeed) {
  const io::Scenario s = io::load_scenario(io::default_scenario_path());
  const LobeStudy st = study_lobes(s, {});
  // The same lobes computed on their own from the study's settings.
  const process::StabilityLobes lobes = process::zero_order_lobes(s.machine.tool_tip, st.settings);
  EXPECT_NEAR(st.a_crit_mm, lobes.critical_depth_mm(1200.0), 1e-9 * st.a_crit_mm);
  // At a speed far below the first lobes the boundary is the lobes' floor,
  // within the few per cent the dense low-speed lobes ripple over it.
  EXPECT_GE(st.a_crit_mm, st.lobes.a_lim_min_mm * (1 - 1e-9));
  EXPECT_LT(st.a_crit_mm, 1.05 * st.lobes.a_lim_min_mm);
  EXPECT_EQ(st.stable, st.cut.ap_mm < st.a_crit_mm);
}

TEST(LobeStudy, CommandWritesItsResultSet) {
  const auto d = work();
  ASSERT_EQ(sh(d, twin() + " lobes -o " + (d / "out").string()), 0) << slurp(d / "stderr.txt");
  for (const char* f : {"lobes.csv", "boundary.csv", "report.json", "lobes.png", "manifest.json"})
    EXPECT_TRUE(std::filesystem::exists(d / "out" / f)) << f;
  const auto j = nlohmann::json::parse(slurp(d / "out" / "report.json"));
  EXPECT_EQ(j["scenario"], "fadal_pocket_corner");
  EXPECT_GT(j["a_crit_mm"].get<double>(), 0.0);
  EXPECT_THAT(slurp(d / "stdout.txt"), ::testing::HasSubstr("critical depth"));
}

// The check mode on the default scenario: far below the lobes' critical
// depth (4.97 mm at 1200 rpm) the coupled twin's straight cut is stable, far
// above it chatters; check.csv and report.json carry both verdicts, and the
// lobes' critical depth is the report's own. A malformed point is refused in
// one line and nothing is written.
TEST(LobeStudy, CheckModeRunsTheCoupledTwinBesideTheLobes) {
  const auto d = work();
  ASSERT_EQ(sh(d, twin() + " lobes -o " + (d / "out").string() + " --check 1200:1 --check 1200:9"), 0)
      << slurp(d / "stderr.txt");
  const auto j = nlohmann::json::parse(slurp(d / "out" / "report.json"));
  ASSERT_EQ(j["check"].size(), 2u);
  for (const auto& c : j["check"]) EXPECT_NEAR(c["a_crit_mm"].get<double>(), j["a_crit_mm"].get<double>(), 1e-12);
  EXPECT_EQ(j["check"][0]["lobes_verdict"], "stable");
  EXPECT_EQ(j["check"][0]["twin_verdict"], "stable");
  EXPECT_EQ(j["check"][1]["lobes_verdict"], "chatter");
  EXPECT_EQ(j["check"][1]["twin_verdict"], "chatter");
  const std::string csv = slurp(d / "out" / "check.csv");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 3);
  EXPECT_THAT(slurp(d / "stdout.txt"), ::testing::HasSubstr("check 1200 rpm, ap 9 mm: lobes chatter"));
  const auto bad = work() / "bad";
  std::filesystem::create_directories(bad);
  EXPECT_NE(sh(bad, twin() + " lobes -o " + (bad / "out").string() + " --check 1200mm"), 0);
  const std::string err = slurp(bad / "stderr.txt");
  EXPECT_THAT(err, ::testing::HasSubstr("expected RPM:DEPTH_mm"));
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(bad / "out"));
}

TEST(LobeStudy, AMachineWithoutToolTipModesIsRefusedInOneLine) {
  const auto d = work();
  const std::string machine = slurp(std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios/machines/fadal2216.yaml");
  const auto cut = machine.find("tool_tip:");
  ASSERT_NE(cut, std::string::npos);
  std::ofstream(d / "rigid.yaml") << machine.substr(0, cut);
  EXPECT_NE(sh(d, twin() + " lobes --machine " + (d / "rigid.yaml").string() + " -o " + (d / "out").string()), 0);
  const std::string err = slurp(d / "stderr.txt");
  EXPECT_THAT(err, ::testing::HasSubstr("no tool_tip modes"));
  EXPECT_EQ(std::count(err.begin(), err.end(), '\n'), 1);
  EXPECT_FALSE(std::filesystem::exists(d / "out" / "report.json"));
}

TEST(MachineFile, ToolTipModesReadBackAsWritten) {
  const auto d = work();
  sim::MachineDefinition m = io::load_machine(std::filesystem::path(TWIN_SOURCE_DIR) / "scenarios/machines/fadal2216.yaml");
  ASSERT_EQ(m.tool_tip.x.size(), 1u);
  m.tool_tip_source = "tap test 'A', 2026";
  std::ofstream(d / "m.yaml") << io::machine_to_yaml(m, "round trip");
  const sim::MachineDefinition r = io::load_machine(d / "m.yaml");
  EXPECT_EQ(r.tool_tip_source, m.tool_tip_source);
  ASSERT_EQ(r.tool_tip.y.size(), 1u);
  EXPECT_DOUBLE_EQ(r.tool_tip.y[0].fn_Hz, m.tool_tip.y[0].fn_Hz);
  EXPECT_DOUBLE_EQ(r.tool_tip.y[0].k_N_per_m, m.tool_tip.y[0].k_N_per_m);
  // A mode without its stiffness, or a damping ratio of 1, is refused with the key.
  std::string text = slurp(d / "m.yaml");
  const auto k = text.find(", k_N_per_m: 12000000");
  ASSERT_NE(k, std::string::npos);
  std::ofstream(d / "bad.yaml") << text.substr(0, k) + text.substr(text.find('}', k));
  try {
    io::load_machine(d / "bad.yaml");
    FAIL() << "accepted a mode without k_N_per_m";
  } catch (const ConfigError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr("tool_tip.x[0]"));
  }
}

}  // namespace
}  // namespace twin::structure
