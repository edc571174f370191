// Milling force model against closed forms (Altintas, Manufacturing
// Automation, eq. 2.26: the average force per tooth period with the linear
// edge-force model) and against first-order properties of runout and feed.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "process/steady_cut.hpp"
#include "process_test_util.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

using testing::design_coefficients;
using testing::flat_tool;

constexpr double kPi = std::numbers::pi;

// Average force on the TOOL per tooth period, immersion phi_st..phi_ex, from
// the integral of the elemental forces (Altintas eq. 2.26):
//  Fx = N a c/(8 pi) [Ktc cos 2phi - Krc (2 phi - sin 2phi)] + N a/(2 pi) [-Kte sin phi + Kre cos phi]
//  Fy = N a c/(8 pi) [Ktc (2 phi - sin 2phi) + Krc cos 2phi] - N a/(2 pi) [Kte cos phi + Kre sin phi]
std::array<double, 2> closed_form_tool_N(double N, double a, double c, double st, double ex) {
  const double Ktc = 800, Krc = 250, Kte = 25, Kre = 30;
  auto fx = [&](double p) {
    return N * a * c / (8 * kPi) * (Ktc * std::cos(2 * p) - Krc * (2 * p - std::sin(2 * p))) +
           N * a / (2 * kPi) * (-Kte * std::sin(p) + Kre * std::cos(p));
  };
  auto fy = [&](double p) {
    return N * a * c / (8 * kPi) * (Ktc * (2 * p - std::sin(2 * p)) + Krc * std::cos(2 * p)) -
           N * a / (2 * kPi) * (Kte * std::cos(p) + Kre * std::sin(p));
  };
  return {fx(ex) - fx(st), fy(ex) - fy(st)};
}

SteadyCutSpec design_cut(double ae_mm, bool up, double helix_deg) {
  SteadyCutSpec s;
  s.tool = flat_tool(10.0, 4, helix_deg);
  s.coefficients = design_coefficients();
  s.spindle_rpm = 1000.0;
  s.feed_per_tooth_mm = 0.1;
  s.ae_mm = ae_mm;
  s.ap_mm = 2.0;
  s.up_milling = up;
  s.angle_step_deg = 0.5;
  s.dz_mm = 0.1;
  return s;
}

// The number quoted in design.md section 5, to pin the oracle itself.
TEST(ClosedForm, SlotNumbersOfDesignNote) {
  const auto F = closed_form_tool_N(4, 2, 0.1, 0, kPi);
  EXPECT_NEAR(F[0], -126.394, 1e-3);
  EXPECT_NEAR(F[1], 223.662, 1e-3);
}

// Slot, up and down half immersion through the whole MillingProcess (stock,
// engagement, disks, sub-steps). The mean over one revolution sampled every
// 0.5 deg is a Riemann sum of the integral; each disk's entry/exit jump of the
// edge force costs up to half a step (0.25 deg of 90 deg per tooth), and the
// probe shifts engagement boundaries by < 0.3 deg, so 1 % of the largest
// component bounds the difference.
TEST(MillingForce, MeanForcesMatchClosedForm) {
  struct Case {
    double ae;
    bool up;
    double st, ex;
  } cases[] = {{10.0, true, 0.0, kPi}, {5.0, true, 0.0, kPi / 2}, {5.0, false, kPi / 2, kPi}};
  for (double helix : {0.0, 30.0}) {
    for (const auto& cs : cases) {
      const SteadyCutResult r = run_steady_cut(design_cut(cs.ae, cs.up, helix));
      const auto F = closed_form_tool_N(4, 2, 0.1, cs.st, cs.ex);
      const double scale = std::max(std::abs(F[0]), std::abs(F[1]));
      // run_steady_cut reports forces on the workpiece: the opposite.
      EXPECT_NEAR(-r.mean_F_N[0], F[0], 0.01 * scale) << "ae " << cs.ae << " up " << cs.up << " helix " << helix;
      EXPECT_NEAR(-r.mean_F_N[1], F[1], 0.01 * scale) << "ae " << cs.ae << " up " << cs.up << " helix " << helix;
      EXPECT_NEAR(r.mean_F_N[2], 0.0, 1e-9);
      // Torque: mean tangential force times R, from the same integral:
      // T = N a R/(2 pi) [Ktc c (1 - cos) + Kte (ex - st)] in N mm.
      const double T_Nmm = 4 * 2 * 5.0 / (2 * kPi) *
                           (800 * 0.1 * (std::cos(cs.st) - std::cos(cs.ex)) + 25 * (cs.ex - cs.st));
      EXPECT_NEAR(r.mean_torque_Nm, T_Nmm * 1e-3, 0.01 * T_Nmm * 1e-3);
      EXPECT_NEAR(r.mean_power_W, r.mean_torque_Nm * 1000.0 * 2 * kPi / 60.0, 1e-9);
    }
  }
}

// Per-tooth peaks of the resultant over one revolution of a 4-flute slot.
std::array<double, 4> tooth_peaks(const SteadyCutResult& r) {
  std::array<double, 4> peaks{};
  for (const auto& row : r.rows) {
    const int tooth = static_cast<int>(std::floor(std::fmod(row.angle_deg + 360.0, 360.0) / 90.0)) % 4;
    peaks[static_cast<std::size_t>(tooth)] =
        std::max(peaks[static_cast<std::size_t>(tooth)], std::hypot(row.F_N[0], row.F_N[1]));
  }
  return peaks;
}

// Runout 0: every tooth carries the same load (helix 0, so a tooth period is
// a 90 deg window; the sampling is identical in each: 1e-6 relative).
// Runout rho = 10 um at lambda = 0: the chip of flute j changes by
// R_j - R_{j-1} = rho (cos(j 90 deg) - cos((j-1) 90 deg)), +-10 um against c = 100 um,
// so the peaks differ by about 10-20 %, while these changes sum to zero over
// the flutes: the revolution mean moves only where the chip would go
// negative (second order): 1 %.
TEST(MillingForce, RunoutChangesToothPeaksNotTheMean) {
  SteadyCutSpec s = design_cut(10.0, true, 0.0);
  const SteadyCutResult r0 = run_steady_cut(s);
  const auto p0 = tooth_peaks(r0);
  for (double p : p0) EXPECT_NEAR(p, p0[0], 1e-6 * p0[0]);
  s.tool.runout_rho_mm = 0.01;
  s.tool.runout_lambda_deg = 0.0;
  const SteadyCutResult r1 = run_steady_cut(s);
  const auto p1 = tooth_peaks(r1);
  const double hi = *std::max_element(p1.begin(), p1.end());
  const double lo = *std::min_element(p1.begin(), p1.end());
  EXPECT_GT(hi / lo, 1.10);
  for (std::size_t a = 0; a < 2; ++a)
    EXPECT_NEAR(r1.mean_F_N[a], r0.mean_F_N[a], 0.01 * std::hypot(r0.mean_F_N[0], r0.mean_F_N[1]));
}

// The chip comes from the tool's actual velocity: halving the real feed (as a
// lagging drive does) halves the largest chip (h = c sin phi, c = v/(N n)),
// and the mean force falls toward the edge-force share. Oracle: h = c exactly
// at phi = 90 deg (sampled within 0.36 deg: 2e-5 relative).
TEST(MillingForce, SlowerRealFeedLowersChipAndForce) {
  ProcessSetup setup;
  setup.tool = flat_tool(10.0, 4, 0.0);
  setup.coefficients = design_coefficients();
  setup.stock.outline_mm = StockSpec::rectangle(-20, -10, 40, 10);
  setup.stock.top_z_mm = 0.0;
  setup.stock.bottom_z_mm = -5.0;
  const double rpm = 1000.0, Ts = 1e-4;
  const double v_full = 0.1 * 4 * rpm / 60.0;
  double chip[2], force[2];
  int i = 0;
  for (double v : {v_full, 0.5 * v_full}) {
    MillingProcess proc(setup);
    proc.remove_swept({-30, 0, -2}, {0, 0, -2});
    const auto outs = testing::drive(proc, {0, 0, -2}, {v, 0, 0}, rpm, Ts, 600);  // one revolution = 600 ticks
    chip[i] = 0.0;
    force[i] = 0.0;
    for (const auto& o : outs) {
      chip[i] = std::max(chip[i], o.chip_mm);
      force[i] += std::hypot(o.F_avg_N[0], o.F_avg_N[1]) / outs.size();
    }
    ++i;
  }
  EXPECT_NEAR(chip[0], 0.1, 2e-5 * 0.1);
  EXPECT_NEAR(chip[1] / chip[0], 0.5, 1e-4);
  EXPECT_LT(force[1], 0.8 * force[0]);
}

// Bad inputs are errors with the quantity in the message, never NaN.
TEST(MillingForce, InvalidInputsThrow) {
  ProcessSetup setup;
  setup.tool = flat_tool(10.0, 4, 0.0);
  setup.coefficients = design_coefficients();
  setup.stock.outline_mm = StockSpec::rectangle(-20, -10, 40, 10);
  MillingProcess proc(setup);
  ProcessInput in;
  in.p_mm = {0, 0, -1};
  in.v_mm_per_s = {std::nan(""), 0, 0};
  in.spindle_rpm = 1000;
  EXPECT_THROW(proc.step(in), ModelError);
  in.v_mm_per_s = {5, 0, 0};
  in.spindle_rpm = -1000;
  EXPECT_THROW(proc.step(in), ModelError);
  in.spindle_rpm = 0.0;
  EXPECT_THROW(proc.step(in), ModelError);  // feeding into material with the spindle stopped
  ToolGeometry bad = flat_tool(10.0, 4, 0.0);
  bad.corner_radius_mm = 1.0;
  EXPECT_THROW(bad.validate("test"), ConfigError);
  setup.tool.diameter_mm = -1;
  EXPECT_THROW(MillingProcess{setup}, ConfigError);
}

// Spindle speeds that ask for absurd force sub-step counts (issue 19): S1e20
// overflowed the int sub-step count (undefined) and reported 7e-15 N, S1e7
// took 4000 force samples per tick. Oracle: the count n = ceil(Omega Ts /
// angle_step) from the input (at Ts = 1e-4 s and 1.5 deg: 1e7 rpm -> 4000,
// 250000 rpm -> 100). The limit is 1000 samples per tick.
TEST(MillingProcess, ForceSubStepCountBounded) {
  ProcessSetup setup;
  setup.tool = flat_tool(10.0, 4, 0.0);
  setup.coefficients = design_coefficients();
  setup.stock.outline_mm = StockSpec::rectangle(-20, -10, 40, 10);
  ProcessInput in;
  in.p_mm = {0, 0, -1};
  in.v_mm_per_s = {5, 0, 0};
  in.Ts_s = 1e-4;
  for (double rpm : {1e20, 1e7}) {
    MillingProcess proc(setup);
    in.spindle_rpm = rpm;
    try {
      proc.step(in);
      ADD_FAILURE() << rpm << " rpm accepted";
    } catch (const ModelError& e) {
      EXPECT_NE(std::string(e.what()).find("force samples"), std::string::npos) << e.what();
    }
  }
  MillingProcess proc(setup);
  in.spindle_rpm = 250000.0;
  const ProcessOutput out = proc.step(in);
  EXPECT_GT(std::abs(out.F_avg_N[0]) + std::abs(out.F_avg_N[1]), 1.0);  // it cuts: the force is not lost
  // At the finest angle step a process file may set (0.05 deg), 100000 rpm
  // asks for 1200 samples per tick: refused.
  setup.options.angle_step_deg = 0.05;
  MillingProcess fine(setup);
  in.spindle_rpm = 100000.0;
  EXPECT_THROW(fine.step(in), ModelError);
}

// clone() deep-copies the stock and the spindle angle: the clone and the
// original give bit-identical outputs afterwards, and cutting with one leaves
// the other's stock untouched.
TEST(MillingProcess, CloneIsDeep) {
  ProcessSetup setup;
  setup.tool = flat_tool(10.0, 2, 30.0);
  setup.coefficients = design_coefficients();
  setup.stock.outline_mm = StockSpec::rectangle(-20, -10, 40, 10);
  setup.stock.bottom_z_mm = -5.0;
  MillingProcess proc(setup);
  testing::drive(proc, {-8, 0, -1}, {8, 0, 0}, 1200, 1e-4, 2000);
  auto copy = proc.clone();
  const double v0 = proc.stock().volume_mm3();
  const auto a = testing::drive(proc, {-6.4, 0, -1}, {8, 0, 0}, 1200, 1e-4, 500);
  EXPECT_LT(proc.stock().volume_mm3(), v0);
  EXPECT_EQ(dynamic_cast<MillingProcess&>(*copy).stock().volume_mm3(), v0);
  std::vector<ProcessOutput> b;
  for (int k = 0; k < 500; ++k) {
    ProcessInput in;
    in.k = k;
    in.Ts_s = 1e-4;
    in.p_mm = {-6.4 + 8 * k * 1e-4, 0, -1};
    in.v_mm_per_s = {8, 0, 0};
    in.spindle_rpm = 1200;
    b.push_back(copy->step(in));
  }
  for (std::size_t k = 0; k < a.size(); ++k) EXPECT_EQ(a[k].F_N, b[k].F_N);
}

}  // namespace
}  // namespace twin::process
