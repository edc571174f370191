// Tests of the gain tuning (twin/tune/tune.hpp) of a machine whose position loops
// are the cascade (the fadal2216_cascade example machine), on a short air cut.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/twin/tune/window_check.hpp"
#include "twin/tune/tune.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::analysis {
namespace {

/// Two legs with one blended 90 deg corner at 1200 mm/min on the cascade machine.
io::Scenario cascade_scenario() {
  const auto dir = std::filesystem::path(TWIN_BINARY_DIR) / "tune_test_scenarios" / "cascade_l";
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "scenario.yaml") << "name: cascade_l\nmachine: fadal2216_cascade\nprogram: program.nc\n"
                                       << "start_mm: [0, 0, 0]\nsettle_s: 0.02\n";
  std::ofstream(dir / "program.nc") << "G21 G90 G17\nG64 P0.005\nG1 X4 Y0 F1200\nG1 X4 Y4\nM30\n";
  return io::load_scenario(dir / "scenario.yaml");
}

/// The search's objective (tune.cpp, objective_of) recomputed from two fresh runs of the
/// full scenario, each term normalised by the run with the machine's own gains.
std::pair<double, double> objective_before_after(const io::Scenario& sc, const TuneResult& r,
                                                 const TuneOptions& opt) {
  const PlannedScenario planned = plan_scenario(sc);
  const ScenarioMetrics b = simulate_window(sc, planned, r.machine_before, full_window(planned));
  const ScenarioMetrics a = simulate_window(sc, planned, r.machine_after, full_window(planned));
  EXPECT_TRUE(b.completed && a.completed);
  double rms_b = 0.0, rms_a = 0.0, max_b = 0.0, max_a = 0.0;
  for (Axis ax : opt.axes) {
    rms_b += b.rms_tracking_error_mm[index(ax)];
    rms_a += a.rms_tracking_error_mm[index(ax)];
    max_b += b.max_tracking_error_mm[index(ax)];
    max_a += a.max_tracking_error_mm[index(ax)];
  }
  const double before = 1.0 + opt.rms_weight + opt.max_tracking_weight;
  const double after = a.max_contour_error_mm / b.max_contour_error_mm + opt.rms_weight * rms_a / rms_b +
                       opt.max_tracking_weight * max_a / max_b;
  return {before, after};
}

/// A short search: 30 simulations on windows of 30 ms either side of each corner.
TuneOptions short_search(std::vector<Axis> axes) {
  TuneOptions opt;
  opt.axes = std::move(axes);
  opt.max_evaluations = 30;
  opt.window_before_s = 0.03;
  opt.window_after_s = 0.03;
  return opt;
}

// Oracles: (1) the constraints recomputed afresh (a new linear analysis of the cascade
// and the peak torque of a fresh full run, none of it at the torque limit) hold for the
// returned gains; (2) the search's objective, recomputed from fresh co-simulations of the
// full scenario (not from the search's own bookkeeping or the linear model), is lower
// with the tuned gains than with the machine's; (3) only the feedback gains the cascade
// searches (Kv, Kvp, Tn) changed, the feedforward kff, Jff and the drive's tau_i, T_max
// are the machine's; (4) machine.yaml reloads as a cascade machine with those gains.
TEST(CascadeTune, TunedGainsMeetConstraintsAndLowerTheObjectiveInSimulation) {
  const io::Scenario sc = cascade_scenario();
  const TuneOptions opt = short_search({Axis::kX, Axis::kY});
  const TuneResult r = tune_gains(sc, opt);
  ASSERT_TRUE(r.feasible) << r.message;
  ASSERT_EQ(r.axes.size(), 2u);
  for (const auto& a : r.axes) {
    const auto& def = sc.machine.axes[index(a.axis)];
    ASSERT_TRUE(a.tuned) << a.note;
    const ConstraintValues v = linear_constraints(linear_plant(def.drive), a.after, sc.machine.Ts_s, opt.constraints, "t");
    EXPECT_TRUE(v.linear_ok) << v.violation;
    EXPECT_TRUE(a.analysis_after.stable);
    EXPECT_GE(a.analysis_after.phase_margin_deg, opt.constraints.phase_margin_min_deg);
    EXPECT_GE(a.analysis_after.gain_margin_dB, opt.constraints.gain_margin_min_dB);
    EXPECT_LE(a.analysis_after.sensitivity_peak, opt.constraints.sensitivity_peak_max);
    // The drive's u is the torque / (Ka Kt): the torque peak of the full run.
    const double torque_peak = r.full_after.u_peak_V[index(a.axis)] * def.drive.Ka_A_per_V * def.drive.Kt_Nm_per_A;
    EXPECT_LE(torque_peak, opt.constraints.u_fraction_max * def.loop.cascade.T_max);
    EXPECT_NEAR(a.constraints_after.command_peak, torque_peak, 1e-9 * def.loop.cascade.T_max);
    EXPECT_EQ(r.full_after.saturated_ticks[index(a.axis)], 0);
    EXPECT_EQ(a.after.law, controller::LoopLaw::kCascade);
    EXPECT_EQ(a.after.cascade.kff, def.loop.cascade.kff);
    EXPECT_EQ(a.after.cascade.Jff_torque_s2_per_rad, def.loop.cascade.Jff_torque_s2_per_rad);
    EXPECT_EQ(a.after.cascade.tau_i_s, def.loop.cascade.tau_i_s);
    EXPECT_EQ(a.after.cascade.T_max, def.loop.cascade.T_max);
    EXPECT_NE(a.after.cascade.Kv_per_s, def.loop.cascade.Kv_per_s);
  }
  const auto [before, after] = objective_before_after(sc, r, opt);
  EXPECT_LT(after, before);
  EXPECT_LT(r.full_after.max_contour_error_mm, r.full_before.max_contour_error_mm);

  const auto yaml = std::filesystem::path(TWIN_BINARY_DIR) / "tune_test_scenarios" / "cascade_l" / "tuned.yaml";
  std::ofstream(yaml) << io::machine_to_yaml(r.machine_after, "tuned");
  const sim::MachineDefinition back = io::load_machine(yaml);
  for (const auto& a : r.axes) {
    const auto& c = back.axes[index(a.axis)].loop;
    EXPECT_EQ(c.law, controller::LoopLaw::kCascade);
    EXPECT_NEAR(c.cascade.Kv_per_s, a.after.cascade.Kv_per_s, 1e-9 * a.after.cascade.Kv_per_s);
    EXPECT_NEAR(c.cascade.Kvp_torque_s_per_rad, a.after.cascade.Kvp_torque_s_per_rad,
                1e-9 * a.after.cascade.Kvp_torque_s_per_rad);
    EXPECT_NEAR(c.cascade.Tn_s, a.after.cascade.Tn_s, 1e-9 * a.after.cascade.Tn_s);
  }
}

// A velocity loop at 125 us under a 1 ms position loop: the search keeps both loops'
// margins. Oracles: the constraints recomputed by a fresh linear analysis (the position
// loop lifted over the period, the velocity loop alone at Tv) hold for the returned gains,
// and the objective recomputed from fresh co-simulations of the full scenario (which step
// the velocity loop 8 times a period) falls.
TEST(CascadeTune, AVelocityLoopFasterThanThePositionLoopIsTunedWithinBothLoopsMargins) {
  io::Scenario sc = cascade_scenario();
  sc.machine.Ts_s = 1e-3;
  for (Axis a : sc.machine.present_axes()) sc.machine.axes[index(a)].loop.cascade.Tv_s = 1.25e-4;
  const TuneOptions opt = short_search({Axis::kX});
  const TuneResult r = tune_gains(sc, opt);
  ASSERT_TRUE(r.feasible) << r.message;
  ASSERT_EQ(r.axes.size(), 1u);
  const auto& a = r.axes.front();
  ASSERT_TRUE(a.tuned) << a.note;
  const auto& def = sc.machine.axes[index(a.axis)];
  const ConstraintValues v = linear_constraints(linear_plant(def.drive), a.after, sc.machine.Ts_s, opt.constraints, "t");
  EXPECT_TRUE(v.linear_ok) << v.violation;
  ASSERT_TRUE(a.analysis_after.velocity_loop);
  EXPECT_GE(a.analysis_after.phase_margin_deg, opt.constraints.phase_margin_min_deg);
  EXPECT_GE(a.analysis_after.velocity_loop_phase_margin_deg, opt.constraints.phase_margin_min_deg);
  EXPECT_GE(a.analysis_after.gain_margin_dB, opt.constraints.gain_margin_min_dB);
  EXPECT_GE(a.analysis_after.velocity_loop_gain_margin_dB, opt.constraints.gain_margin_min_dB);
  EXPECT_EQ(a.after.cascade.Tv_s, 1.25e-4);
  const auto [before, after] = objective_before_after(sc, r, opt);
  EXPECT_LT(after, before);
}

// Oracle: a window starting in steady motion reproduces the full run through the corner.
// The cascade's P loop lags on the straight by (1 - kff) v / Kv = 40 um at 20 mm/s; the
// window must start with that lag (and the speed integral holding the viscous and
// Coulomb torque) or its corner differs by tens of microns. Tolerance one encoder count
// (1 um), the quantisation of the error the loop acts on, on the max tracking error of
// each axis and the max contour error.
TEST(CascadeTune, SteadyMotionWindowMatchesTheFullRun) {
  ScenarioMetrics full, win;
  ASSERT_NO_FATAL_FAILURE(testing::expect_corner_window_matches_full_run(cascade_scenario(), full, win));
  for (Axis a : {Axis::kX, Axis::kY})
    EXPECT_NEAR(win.max_tracking_error_mm[index(a)], full.max_tracking_error_mm[index(a)], 1e-3) << axis_name(a);
  EXPECT_GT(full.max_tracking_error_mm[index(Axis::kX)], 0.03);  // the lag is there to be matched
}

}  // namespace
}  // namespace twin::analysis
