// A machine file's `structure:` section: parsed, folded into the drives from
// the Simbody model, written back unfolded (round trip), and what the drives
// do with it: J = J_file + m (rg/1000)^2 per axis (the mass each carries by
// the stacking), a constant torque m g rg / eta on Z that the Z motor holds at
// standstill. Checked against these closed forms; tolerances are stated where
// they are not round-off.
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "controller/gcode.hpp"
#include "feeddrive/drive_bank.hpp"
#include "tests/support/test_files.hpp"
#include "twin/core/error.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/trace_csv.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

constexpr double kG = 9.80665;

sim::MachineDefinition structure_machine() {
  return io::load_machine(io::resolve_machine_path("fadal2216_structure"));
}

using test_support::slurp;

std::filesystem::path temp_dir() {
  return test_support::made_dir(std::filesystem::temp_directory_path() / "structure_machine_test" /
                                test_support::current_test_name());
}

std::filesystem::path write(const std::string& name, const std::string& text) {
  return test_support::write_file(temp_dir() / name, text);
}

TEST(StructureMachine, DrivesCarryTheStackAndZTheWeight) {
  const sim::MachineDefinition m = structure_machine();
  const sim::MachineDefinition rigid = io::load_machine(io::resolve_machine_path("fadal2216"));
  ASSERT_TRUE(m.structure.has_value());
  const auto& s = *m.structure;
  const std::array<double, 3> carried{s.table_kg + s.workpiece_kg, s.saddle_kg + s.table_kg + s.workpiece_kg,
                                      s.head_kg};
  for (Axis a : kAllAxes) {
    const std::size_t i = index(a);
    const double rg_m = m.axes[i].drive.rg_mm_per_rad / 1000.0;
    EXPECT_NEAR(s.carried_kg[i], carried[i], 1e-12 * carried[i]) << axis_name(a);
    EXPECT_NEAR(m.axes[i].drive.J_kg_m2, rigid.axes[i].drive.J_kg_m2, 1e-7 * rigid.axes[i].drive.J_kg_m2)
        << axis_name(a) << ": J_file + m rg^2 should equal the identified J";
    EXPECT_NEAR(s.reflected_J_kg_m2[i], carried[i] * rg_m * rg_m, 1e-12 * carried[i] * rg_m * rg_m);
  }
  const double rg_z = m.axes[index(Axis::kZ)].drive.rg_mm_per_rad / 1000.0;
  const double Tg = (s.head_kg * kG - s.counterbalance_N) * rg_z / s.screw_efficiency;
  const auto& load = m.axes[index(Axis::kZ)].drive.effects.constant_load;
  EXPECT_TRUE(load.enabled);
  EXPECT_NEAR(load.torque_Nm, Tg, 1e-12 * Tg);
  EXPECT_FALSE(m.axes[index(Axis::kX)].drive.effects.constant_load.enabled);
  EXPECT_FALSE(m.axes[index(Axis::kY)].drive.effects.constant_load.enabled);
}

TEST(StructureMachine, RoundTripWritesTheFileJAndTheStructure) {
  const sim::MachineDefinition m = structure_machine();
  const std::string text = io::machine_to_yaml(m, "round trip");
  EXPECT_THAT(text, HasSubstr("structure:"));
  EXPECT_THAT(text, Not(HasSubstr("constant_load")));   // the gravity is the structure's, not the file's
  const sim::MachineDefinition back = io::load_machine(write("back.yaml", text));
  ASSERT_TRUE(back.structure.has_value());
  for (Axis a : kAllAxes) {
    const std::size_t i = index(a);
    EXPECT_DOUBLE_EQ(back.axes[i].drive.J_kg_m2, m.axes[i].drive.J_kg_m2) << axis_name(a);
    EXPECT_EQ(back.axes[i].drive.effects.constant_load.enabled, m.axes[i].drive.effects.constant_load.enabled);
    EXPECT_DOUBLE_EQ(back.axes[i].drive.effects.constant_load.torque_Nm,
                     m.axes[i].drive.effects.constant_load.torque_Nm);
  }
  EXPECT_EQ(back.structure->stacking, m.structure->stacking);
  EXPECT_EQ(back.structure->source, m.structure->source);
  EXPECT_DOUBLE_EQ(back.structure->head_kg, m.structure->head_kg);
  EXPECT_DOUBLE_EQ(back.structure->screw_efficiency, m.structure->screw_efficiency);
}

// The Z motor holds the head at rest: with integral action the loop settles
// where the motor torque balances the load, inside the stiction band, so the
// tolerance is the Z axis's Coulomb level (0.3 N m against Tg = 5.2 N m).
TEST(StructureMachine, ZMotorHoldsTheGravityTorqueAtStandstill) {
  const sim::MachineDefinition m = structure_machine();
  const auto program = controller::parse_gcode("G21 G90\nG4 P0.6\nM30\n", "dwell.nc", {100, 100, -100},
                                               m.rapid_mm_per_min);
  auto ref =
      std::make_shared<sim::ProgramReference>(controller::plan_trajectory(program, m.motion_limits(), m.Ts_s));
  sim::CoSimulation cs(m, ref, nullptr, {100, 100, -100});
  const sim::Snapshot* last = nullptr;
  while (cs.time_s() < 0.5) last = &cs.step();
  const auto& z = last->axes[index(Axis::kZ)];
  const double Tg = m.axes[index(Axis::kZ)].drive.effects.constant_load.torque_Nm;
  EXPECT_GT(Tg, 5.0);
  EXPECT_NEAR(z.Tm_Nm, Tg, m.axes[index(Axis::kZ)].drive.Tc_pos_Nm);
  // It holds the head within microns: P alone would leave Tg / (Ka Kt Kp) = 3.1 um
  // (the integral, Ki / Kp = 0.14 1/s, is slow): 10 um bounds it with the stiction band.
  EXPECT_LT(std::abs(z.e_mm), 0.01);
  // X does not carry a weight: its torque stays inside its stiction band.
  EXPECT_LT(std::abs(last->axes[index(Axis::kX)].Tm_Nm), m.axes[index(Axis::kX)].drive.Tc_pos_Nm + 1e-9);
}

// `twin run --machine fadal2216_structure` on the default scenario: it runs,
// and at the end (Z at rest after the program's last move and the settle
// time) the Z torque in trace.csv is the gravity torque (same band as above).
TEST(StructureMachine, DefaultScenarioRunsOnTheStructureMachine) {
  const auto out = test_support::removed(temp_dir() / "out");
  const auto r = test_support::run_command(
      temp_dir(), test_support::twin_exe() + " run --machine fadal2216_structure --no-plots -o " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const io::TraceTable t = io::read_trace_csv(out / "trace.csv");
  const auto& T = t.at("z_Tm_Nm");
  ASSERT_FALSE(T.empty());
  const sim::MachineDefinition m = structure_machine();
  const auto& s = *m.structure;
  const double Tg = (s.head_kg * kG - s.counterbalance_N) * m.axes[index(Axis::kZ)].drive.rg_mm_per_rad / 1000.0 /
                    s.screw_efficiency;
  EXPECT_NEAR(T.back(), Tg, m.axes[index(Axis::kZ)].drive.Tc_pos_Nm);

  // The tool's modes vibrate in the cut (structure and tool_tip). Over the
  // cut the tool's mean deflection is the modes' static response to the mean
  // force on it, -mean(F_workpiece) / k per direction: the mean of a linear
  // system's response over a long window is its DC gain times the mean input,
  // up to the state at the window's ends over its length (the tool rings down
  // in milliseconds; the cut lasts seconds). 0.1 % covers the ticks at entry
  // and exit and the force held over a tick against the deflection at its
  // start (measured: 4e-6).
  const auto& engaged = t.at("engagement_deg");
  for (const char* c : {"x", "y"}) {
    const auto& u = t.at(std::string("tool_d") + c + "_um");
    const auto& F = t.at(std::string("f") + c + "_avg_N");
    double su = 0.0, sf = 0.0;
    int n = 0;
    for (std::size_t k = 0; k < engaged.size(); ++k)
      if (engaged[k] > 0.0) su += u[k], sf += F[k], ++n;
    ASSERT_GT(n, 10000);
    const double k_N_per_m = (c[0] == 'x' ? m.tool_tip.x : m.tool_tip.y).front().k_N_per_m;
    const double static_um = -sf / n / k_N_per_m * 1e6;
    EXPECT_NEAR(su / n, static_um, 1e-3 * std::abs(static_um)) << c;
  }
  EXPECT_NE(t.find("sle_um"), nullptr);
  const auto summary = slurp(out / "summary.json");
  EXPECT_NE(summary.find("\"max_deflection_um\""), std::string::npos);
  EXPECT_NE(summary.find("\"chatter\": \"stable\""), std::string::npos);   // 1 mm against the lobes' 4.97 mm
}

// A screw stiffness makes the drive two masses: the motor and screw (the file's
// J) against the carried mass J_l = m (rg/1000)^2, joined by K = k rg^2. Free
// vibration of the drive (no friction, no damping, no command, the twist set
// off by 1 um) against the two-mass mode w = sqrt(K (1/J_m + 1/J_l)). The
// period is measured over 8 cycles from interpolated zero crossings of the
// twist sampled at 67 points a cycle: 1e-3 relative covers the interpolation
// and the integrator's tolerance.
TEST(StructureMachine, ScrewStiffnessGivesTheTwoMassScrewTableMode) {
  std::string text = slurp(io::resolve_machine_path("fadal2216_structure"));
  text += "  screw_stiffness_N_per_um: {x: 150}\n";
  const sim::MachineDefinition m = io::load_machine(write("stiff.yaml", text));
  const sim::MachineDefinition file_j = structure_machine();
  feeddrive::DriveParams d = m.axes[index(Axis::kX)].drive;
  ASSERT_TRUE(d.effects.compliance.enabled);
  EXPECT_FALSE(m.axes[index(Axis::kY)].drive.effects.compliance.enabled);
  const double rg_m = d.rg_mm_per_rad / 1000.0;
  const double Jl = m.structure->carried_kg[0] * rg_m * rg_m;
  const double Jm = file_j.axes[index(Axis::kX)].drive.J_kg_m2 - file_j.structure->reflected_J_kg_m2[0];
  const double K = 150e6 * rg_m * rg_m;
  const double w = std::sqrt(K * (1.0 / Jm + 1.0 / Jl));
  d.B_kg_m2_per_s = 0.0;
  d.Tc_pos_Nm = d.Tc_neg_Nm = 0.0;
  const double Ts = 1e-4;
  feeddrive::DriveBank bank({d}, Ts);
  bank.reset({0.0});
  std::vector<feeddrive::DriveState> st = bank.states();
  st[0].x_load_mm = 0.001;
  st[0].stuck = st[0].load_stuck = false;
  bank.set_states(st);
  std::vector<double> crossings;
  double prev = st[0].x_load_mm - st[0].x_mm;
  for (int k = 0; k < 2000 && crossings.size() < 17; ++k) {
    bank.advance(k * Ts, (k + 1) * Ts, {feeddrive::DriveInput{}});
    const double twist = bank.state(0).x_load_mm - bank.state(0).x_mm;
    if ((prev > 0.0) != (twist > 0.0)) crossings.push_back(k * Ts + Ts * prev / (prev - twist));
    prev = twist;
  }
  ASSERT_EQ(crossings.size(), 17u);
  const double period = (crossings.back() - crossings.front()) / 8.0;
  EXPECT_NEAR(2.0 * M_PI / period, w, 1e-3 * w) << "K " << K << " Jm " << Jm << " Jl " << Jl;
}

TEST(StructureMachine, BadStructureIsAOneLineConfigError) {
  const std::string base = slurp(io::resolve_machine_path("fadal2216_structure"));
  auto expect_error = [&](const std::string& from, const std::string& to, const std::string& words) {
    std::string text = base;
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    text.replace(at, from.size(), to);
    try {
      static_cast<void>(io::load_machine(write("bad.yaml", text)));
      ADD_FAILURE() << "no error for " << to;
    } catch (const ConfigError& e) {
      EXPECT_THAT(std::string(e.what()), HasSubstr(words));
      EXPECT_THAT(std::string(e.what()), HasSubstr("bad.yaml"));   // names the file
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
    }
  };
  expect_error("  head_kg: 300", "  head_kg: -3", "head_kg");
  expect_error("  stacking: x_on_y", "  stacking: z_on_x", "stacking");
  expect_error("  screw_efficiency: 0.9", "  screw_efficiency: 1.2", "screw_efficiency");
  expect_error("  table_kg: 160", "  tabel_kg: 160", "tabel_kg");
  // The stack needs every slide's transmission: a machine without Z is refused.
  const auto z_from = base.find("  z:\n"), z_to = base.find("# The tool tip");
  ASSERT_TRUE(z_from != std::string::npos && z_to != std::string::npos && z_from < z_to);
  expect_error(base.substr(z_from, z_to - z_from), "", "axis z is missing");
}

}  // namespace
}  // namespace twin
