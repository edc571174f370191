// The corner summary of summary.json compares like with like: the
// revolution-mean force of the straight cut before the corner, outside the
// engagement ramp, against the revolution-mean and the peak force through the
// ramp. Oracle: synthetic snapshots whose force is known in closed form.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "controller/interpolator.hpp"
#include "twin/report/run_report.hpp"
#include "twin/core/units.hpp"

namespace twin {
namespace {

// A 90 degree corner at F 600 (10 mm/s), spindle 1200 rpm (a revolution is
// 0.05 s = 500 ticks of 1e-4 s). The engagement is 40 deg on the straight cut,
// ramps linearly to 120 deg over the 0.2 s before the corner and back over the
// 0.2 s after it. The force magnitude is 20 N (1 + 0.5 sin(2 pi 20 t)) while
// the engagement is within the straight cut's band (40 + 2 deg) and 60 N
// (1 + 0.5 sin(...)) above it. So:
// - the straight-cut revolution mean is 20 N (four whole revolutions of a
//   sine sampled 500 times a period sum to zero up to rounding: 1e-9 N);
// - the largest revolution mean in the ramp is 60 N (the ramp is longer than a
//   revolution), the largest force 90 N, the straight cut's 30 N;
// - the ramp starts where the engagement first leaves the band: 2 deg / (80
//   deg / 0.2 s) = 5 ms after the ramp's start (one tick).
// Before this summary the mean force before the corner averaged the 0.2 s
// before the speed dip, which here lies inside the engagement ramp.
TEST(CornerSummary, StraightCutOutsideTheRampAgainstTheCorner) {
  const double Ts = 1e-4;
  controller::MotionLimits lim{.v_max_mm_per_s = {100, 100, 100}, .a_max_mm_per_s2 = {2000, 2000, 2000},
                               .j_max_mm_per_s3 = {1e12, 1e12, 1e12}};
  const controller::Program prog =
      controller::parse_gcode("G64 P0.05\nG1 X20 F600\nY20\n", "corner.nc", {0, 0, 0}, 6000.0);
  const controller::Trajectory traj = controller::plan_trajectory(prog, lim, Ts);
  ASSERT_EQ(traj.corners().size(), 1u);
  const double t_c = traj.corners()[0].t_s;
  analysis::RunStatistics stats(prog, traj, {Axis::kX, Axis::kY}, 1e-4);
  const std::int64_t n = traj.num_ticks();
  for (std::int64_t k = 0; k <= n; ++k) {
    sim::Snapshot s;
    s.k = k;
    s.t_s = static_cast<double>(k) * Ts;
    s.spindle_rpm = 1200.0;
    const double dt = std::abs(s.t_s - t_c);
    s.engagement_deg = dt < 0.2 ? 120.0 - 80.0 * dt / 0.2 : 40.0;
    const double level = s.engagement_deg <= 42.0 ? 20.0 : 60.0;
    const double F = level * (1.0 + 0.5 * std::sin(2.0 * kPi * 20.0 * s.t_s));
    s.F_N = {F, 0.0, 0.0};
    s.F_avg_N = {F, 0.0, 0.0};
    s.block = traj.sample(k).block;
    s.reference_done = k == n;
    stats.add(s);
  }
  const nlohmann::json j = stats.summary();
  ASSERT_EQ(j["corners"].size(), 1u);
  const auto& c = j["corners"][0];
  EXPECT_NEAR(c["mean_force_before_corner_N"].get<double>(), 20.0, 1e-9);
  EXPECT_NEAR(c["straight_cut_peak_force_N"].get<double>(), 30.0, 1e-3);  // sampled sine peak: 1 - cos(2 pi / 500 / 2)
  EXPECT_NEAR(c["corner_revolution_mean_force_N"].get<double>(), 60.0, 1e-6);  // difference of running sums
  EXPECT_NEAR(c["corner_peak_force_N"].get<double>(), 90.0, 1e-3);
  EXPECT_NEAR(c["revolution_mean_force_ratio"].get<double>(), 3.0, 1e-7);
  EXPECT_NEAR(c["straight_cut_engagement_deg"].get<double>(), 40.0, 1e-12);
  const auto ramp = c["engagement_ramp_s"];
  EXPECT_NEAR(ramp[0].get<double>(), t_c - 0.2 + 0.005, 1.5 * Ts);
  EXPECT_NEAR(ramp[1].get<double>(), t_c + 0.2 - 0.005, 1.5 * Ts);
  const auto win = c["straight_cut_window_s"];
  EXPECT_NEAR(win[1].get<double>() - win[0].get<double>(), 4 * 0.05 - Ts, 1e-9);
  EXPECT_LE(win[1].get<double>(), ramp[0].get<double>());
}

// Oracle: the program text. A program without corners keeps no history of
// ticks and reports no corner (this run used to write past an empty buffer).
TEST(CornerSummary, ProgramWithoutCornersKeepsNoHistory) {
  const double Ts = 1e-4;
  controller::MotionLimits lim{.v_max_mm_per_s = {100, 100, 100}, .a_max_mm_per_s2 = {2000, 2000, 2000},
                               .j_max_mm_per_s3 = {50000, 50000, 50000}};
  const controller::Program prog = controller::parse_gcode("G1 X2 F600\n", "line.nc", {0, 0, 0}, 6000.0);
  const controller::Trajectory traj = controller::plan_trajectory(prog, lim, Ts);
  ASSERT_TRUE(traj.corners().empty());
  analysis::RunStatistics stats(prog, traj, {Axis::kX}, 1e-4);
  for (std::int64_t k = 0; k <= traj.num_ticks(); ++k) {
    sim::Snapshot s;
    s.k = k;
    s.t_s = static_cast<double>(k) * Ts;
    s.spindle_rpm = 1200.0;
    s.engagement_deg = 40.0;
    s.F_N = s.F_avg_N = {10.0, 0.0, 0.0};
    s.block = 0;
    s.reference_done = k == traj.num_ticks();
    stats.add(s);
  }
  EXPECT_TRUE(stats.summary()["corners"].empty());
}

}  // namespace
}  // namespace twin
