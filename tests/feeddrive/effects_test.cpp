// Each drive effect checked against its own closed form.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "fadal_fixture.hpp"
#include "feeddrive/drive_bank.hpp"
#include "twin/core/error.hpp"

namespace twin::feeddrive {
namespace {

// The FADAL fixture: its drives, gains, hand-written loop, period and encoder count.
using namespace testing;

/// A bank of the one axis `p`, at rest at x = 0.
DriveBank axis_at_rest(const DriveParams& p, const IntegratorOptions& o = {}) {
  DriveBank bank({p}, kTs_s, o);
  bank.reset({0.0});
  return bank;
}

void run_constant(DriveBank& bank, double u_V, int n, int k0 = 0) {
  for (int k = k0; k < k0 + n; ++k) bank.advance(k * kTs_s, (k + 1) * kTs_s, {{u_V, 0.0}});
}

// Oracle: under the PID (integral action, no quantisation) at a constant
// reference speed, the steady command balances u = (B w + Tc + T_load)/(Ka Kt),
// so a constant load shifts it by exactly T_load/(Ka Kt). Tolerance 1e-5 V
// (1e-4 relative): the integral pole (Ki/Kp = 0.14 1/s) leaves a slowly
// decaying remainder of the load step, measured 1.3e-6 V at 1.5 s.
TEST(ConstantLoad, ShiftsSteadyCommandByLoadOverKaKt) {
  auto steady_u = [](bool load_on) {
    DriveParams p = fadal_y();
    p.effects.constant_load.enabled = load_on;
    p.effects.constant_load.torque_Nm = 0.4;
    DriveBank bank = axis_at_rest(p);
    HandPid pid(testing::fadal_y_gains(), kTs_s);
    double u = 0.0;
    for (int k = 0; k < 15000; ++k) {
      u = pid.step(50.0 * k * kTs_s, bank.output(0).x_meas_mm);
      bank.advance(k * kTs_s, (k + 1) * kTs_s, {{u, 0.0}});
    }
    return u;
  };
  const DriveParams p = fadal_y();
  EXPECT_NEAR(steady_u(true) - steady_u(false), 0.4 / (p.Ka_A_per_V * p.Kt_Nm_per_A), 1e-5);
}

// Oracle: i = clamp(Ka u, +-i_max); from rest with a saturated command the
// speed follows w = (Kt i_max - Tc)/B (1 - exp(-B t/J)). Tolerance 1e-7 relative.
TEST(CurrentSaturation, CapsCurrentAndAcceleration) {
  DriveParams p = fadal_x();
  p.effects.current_saturation = {.enabled = true, .i_max_A = 5.0};
  DriveBank bank = axis_at_rest(p);
  run_constant(bank, 10.0, 2000);
  EXPECT_DOUBLE_EQ(bank.output(0).i_A, 5.0);
  EXPECT_DOUBLE_EQ(bank.output(0).Tm_Nm, 5.0 * p.Kt_Nm_per_A);
  const double t = 0.2;
  const double w = (p.Kt_Nm_per_A * 5.0 - p.Tc_pos_Nm) / p.B_kg_m2_per_s *
                   (1.0 - std::exp(-p.B_kg_m2_per_s * t / p.J_kg_m2));
  EXPECT_NEAR(bank.output(0).w_rad_per_s, w, 1e-7 * w);
}

// Oracle: a delay of n ticks shifts the open-loop response by exactly n
// ticks. The same u sequence runs with and without the delay; x_delay[k + n]
// equals x[k]. Tolerance 1e-12 mm: identical fixed-step arithmetic except
// for the absolute time values handed to the integrator.
TEST(Delay, ShiftsResponseByWholeTicks) {
  DriveParams p = fadal_y();
  DriveParams pd = p;
  pd.effects.delay.enabled = true;
  pd.effects.delay.delay_s = 3.2e-4;  // rounds to 3 ticks
  DriveBank plain({p}, kTs_s);
  DriveBank delayed({pd}, kTs_s);
  plain.reset({0.0});
  delayed.reset({0.0});
  std::vector<double> x_plain;
  std::vector<double> x_delayed;
  for (int k = 0; k < 2000; ++k) {
    const double u = 3.0 * std::sin(2.0 * std::numbers::pi * 7.0 * k * kTs_s);
    plain.advance(k * kTs_s, (k + 1) * kTs_s, {{u, 0.0}});
    delayed.advance(k * kTs_s, (k + 1) * kTs_s, {{u, 0.0}});
    x_plain.push_back(plain.output(0).x_mm);
    x_delayed.push_back(delayed.output(0).x_mm);
  }
  for (int k = 0; k < 3; ++k) EXPECT_EQ(x_delayed[k], 0.0);
  double worst = 0.0;
  for (int k = 0; k + 3 < 2000; ++k) worst = std::max(worst, std::abs(x_delayed[k + 3] - x_plain[k]));
  EXPECT_LT(worst, 1e-12);
  EXPECT_GT(std::abs(x_plain[1000]), 0.1);
}

// Oracle: the two-mass free oscillation (friction, B and C off) has angular
// frequency sqrt(K (1/Jm + 1/Jl)). Zero crossings of x_motor - x_load are
// interpolated linearly between ticks over 20 periods; tolerance 0.2% covers
// the interpolation (about 1e-6 s per crossing over 0.067 s).
TEST(Compliance, FreeResponseResonanceFrequency) {
  DriveParams p = fadal_x();
  p.Tc_pos_Nm = p.Tc_neg_Nm = 0.0;
  p.B_kg_m2_per_s = 0.0;
  p.effects.compliance = {.enabled = true, .K_Nm_per_rad = 7000.0, .C_Nm_s_per_rad = 0.0, .load_fraction = 0.6};
  const double Jl = p.J_kg_m2 * 0.6;
  const double Jm = p.J_kg_m2 - Jl;
  const double omega = std::sqrt(7000.0 * (1.0 / Jm + 1.0 / Jl));
  for (int method = 0; method < 2; ++method) {
    IntegratorOptions o;
    o.method = method == 0 ? IntegratorOptions::Method::kCvodeAdams : IntegratorOptions::Method::kArkodeErk;
    DriveBank bank = axis_at_rest(p, o);
    DriveState s = bank.state(0);
    s.x_mm = 0.002;
    bank.set_states({s});
    std::vector<double> crossings;
    double prev = 0.002;
    for (int k = 0; k < 1000; ++k) {
      run_constant(bank, 0.0, 1, k);
      const double d = bank.state(0).x_mm - bank.state(0).x_load_mm;
      if ((prev > 0.0) != (d > 0.0)) crossings.push_back((k + prev / (prev - d)) * kTs_s);
      prev = d;
    }
    ASSERT_GE(crossings.size(), 41u);
    const double period = 2.0 * (crossings[40] - crossings[0]) / 40.0;
    EXPECT_NEAR(2.0 * std::numbers::pi / period, omega, 2e-3 * omega) << "method " << method;
  }
}

// Oracle: backlash is a play operator of width gap on the table position.
// Moving + the table trails the motor by gap/2; after reversal the table stays
// put until the motor has come back by the gap (lost motion = gap), then
// leads by gap/2. Tolerance 1e-12 mm where both sides are the same state.
TEST(Backlash, LostMotionAtReversalEqualsGap) {
  DriveParams p = fadal_y();
  p.effects.backlash = {.enabled = true, .gap_mm = 0.02};
  DriveBank bank = axis_at_rest(p);
  run_constant(bank, 1.0, 1000);
  EXPECT_NEAR(bank.output(0).x_mm, bank.state(0).x_mm - 0.01, 1e-12);
  EXPECT_NEAR(bank.output(0).x_meas_mm, bank.state(0).x_mm - 0.01, 1e-12);
  // Reverse; the motor turns at its largest position x_turn.
  int k = 1000;
  double x_turn = bank.state(0).x_mm;
  while (bank.state(0).x_mm > x_turn - 0.015) {
    run_constant(bank, -1.0, 1, k++);
    x_turn = std::max(x_turn, bank.state(0).x_mm);
  }
  // Back by 15 um < gap: the table has not moved since the turn. x_turn is
  // sampled at ticks while the play follows the true turn (located by the
  // stop event), which lies at most a Ts^2 / 8 = 1.5e-6 mm beyond it
  // (a = 1170 mm/s^2 here): tolerance 2e-6 mm, one-sided.
  EXPECT_GE(bank.output(0).x_mm, x_turn - 0.01);
  EXPECT_NEAR(bank.output(0).x_mm, x_turn - 0.01, 2e-6);
  run_constant(bank, -1.0, 1000, k);
  EXPECT_NEAR(bank.output(0).x_mm, bank.state(0).x_mm + 0.01, 1e-12);
}

// Oracle: a gap in the coupling (backlash with compliance). Started centred
// in the gap, the motor carries no load: under a constant torque Tm with
// B = 0 it turns as theta = Tm t^2 / (2 Jm) and the load (held by its
// friction) does not move, until the twist reaches half the gap at
// t_c = sqrt(gap_rad Jm / Tm); from then on the spring pushes the load. The
// reported table position is the load's; the measured one the motor's.
// Tolerances: 1e-9 mm on the motor's parabola (the integrator's relative
// tolerance on a 10 um path), exact zero for the load inside the gap.
TEST(Backlash, InTheCouplingTheMotorCrossesTheGapFree) {
  DriveParams p = fadal_x();
  p.B_kg_m2_per_s = 0.0;
  p.effects.compliance = {.enabled = true, .K_Nm_per_rad = 5000.0, .C_Nm_s_per_rad = 0.5, .load_fraction = 0.5};
  p.effects.backlash = {.enabled = true, .gap_mm = 0.02};
  const double Jm = 0.5 * p.J_kg_m2;
  const double u_V = 0.02;  // Tm = 0.062 N m, below the load's friction 0.2 N m
  const double Tm = p.Ka_A_per_V * p.Kt_Nm_per_A * u_V;
  ASSERT_LT(Tm, p.Tc_pos_Nm);
  const double t_contact_s = std::sqrt(0.02 / p.rg_mm_per_rad * Jm / Tm);
  DriveBank bank = axis_at_rest(p);
  int k = 0;
  for (; (k + 1) * kTs_s < t_contact_s; ++k) {
    run_constant(bank, u_V, 1, k);
    const double t_s = (k + 1) * kTs_s;
    EXPECT_NEAR(bank.state(0).x_mm, p.rg_mm_per_rad * Tm * t_s * t_s / (2.0 * Jm), 1e-9) << "t = " << t_s;
    EXPECT_EQ(bank.state(0).x_load_mm, 0.0);
    EXPECT_EQ(bank.output(0).x_mm, 0.0);
    EXPECT_EQ(bank.output(0).x_meas_mm, bank.state(0).x_mm);
  }
  ASSERT_GT(k, 10);
  // The impact (peak spring torque sqrt(Jm K) w_c, about 2 N m here) breaks
  // the load loose for a moment; once all has come to rest, the load is
  // stuck (Tm is below its friction) and the spring holds the motor against
  // it: the twist is half the gap plus Tm / K. Tolerance 1e-7 mm: the
  // damped spring's remainder after 0.3 s.
  run_constant(bank, u_V, 3000, k);
  EXPECT_GT(bank.state(0).x_load_mm, 0.0);
  EXPECT_NEAR(bank.state(0).x_mm - bank.state(0).x_load_mm, 0.01 + p.rg_mm_per_rad * Tm / 5000.0, 1e-7);
  EXPECT_EQ(bank.output(0).x_mm, bank.state(0).x_load_mm);
}

// Oracle: the lead error enters only the measured position,
// x_meas - x = A sin(2 pi x / P + phase), and never the dynamics (bit-equal
// states with and without). Tolerance 1e-12 mm: formula evaluation.
TEST(ScrewPitchError, ShowsInMeasuredPositionOnly) {
  DriveParams p = fadal_y();
  DriveParams pe = p;
  pe.effects.screw_pitch_error = {true, 0.003, 7.0, 0.4};
  DriveBank a({p}, kTs_s);
  DriveBank b({pe}, kTs_s);
  a.reset({1.0});
  b.reset({1.0});
  for (int k = 0; k < 3000; ++k) {
    a.advance(k * kTs_s, (k + 1) * kTs_s, {{2.0, 0.0}});
    b.advance(k * kTs_s, (k + 1) * kTs_s, {{2.0, 0.0}});
    const double x = b.output(0).x_mm;
    ASSERT_EQ(x, a.output(0).x_mm);
    ASSERT_NEAR(b.output(0).x_meas_mm - x, 0.003 * std::sin(2.0 * std::numbers::pi * x / 7.0 + 0.4), 1e-12);
  }
  EXPECT_GT(b.output(0).x_mm, 10.0);
}

// Oracle: with friction and B off, J dw/dt = Tm - A sin(n theta + phase) has
// the energy integral 0.5 J w^2 = Tm theta + (A/n)(cos(n theta + phase) - cos(phase)).
// Tolerance 1e-9 relative on the energy, floor 1e-15 J: one fixed ERK step
// of Ts per tick is exact to roundoff for this smooth, slowly varying torque.
TEST(Cogging, SpeedFollowsEnergyIntegral) {
  DriveParams p = fadal_x();
  p.Tc_pos_Nm = p.Tc_neg_Nm = 0.0;
  p.B_kg_m2_per_s = 0.0;
  p.effects.cogging = {true, 0.15, 6.0, 0.3};
  DriveBank bank = axis_at_rest(p);
  const double u = 0.3;
  const double Tm = p.Ka_A_per_V * p.Kt_Nm_per_A * u;
  for (int k = 0; k < 3000; ++k) {
    run_constant(bank, u, 1, k);
    const double theta = bank.state(0).x_mm / p.rg_mm_per_rad;
    const double energy = Tm * theta + 0.15 / 6.0 * (std::cos(6.0 * theta + 0.3) - std::cos(0.3));
    const double w = bank.output(0).w_rad_per_s;
    ASSERT_NEAR(0.5 * p.J_kg_m2 * w * w, energy, 1e-9 * energy + 1e-15) << "k = " << k;
  }
  EXPECT_GT(bank.state(0).x_mm / p.rg_mm_per_rad, 4.0 * 2.0 * std::numbers::pi / 6.0);  // 4 ripple periods
}

// Oracle: cogging is part of the static balance. At theta = 0 with phase pi/2
// the ripple torque is +A; a motor torque of Tc + A/2 is then held (net
// Tc - A/2 < Tc), while without cogging it slips. Exact equality: no motion.
TEST(Cogging, HoldsAgainstBreakawayAtRest) {
  DriveParams p = fadal_x();
  p.effects.cogging = {true, 0.1, 8.0, std::numbers::pi / 2.0};
  const double u = (p.Tc_pos_Nm + 0.05) / (p.Ka_A_per_V * p.Kt_Nm_per_A);
  DriveBank bank = axis_at_rest(p);
  run_constant(bank, u, 1000);
  EXPECT_EQ(bank.output(0).x_mm, 0.0);
  p.effects.cogging.enabled = false;
  DriveBank plain({p}, kTs_s);
  plain.reset({0.0});
  run_constant(plain, u, 1000);
  EXPECT_GT(plain.output(0).x_mm, 0.0);
}

// Oracle: Stribeck friction. Breakaway is Ts_static: a torque between Tc and
// Ts_static holds (exactly), one above slips. At steady sliding the speed
// satisfies Ka Kt u = B w + Tc + (Ts - Tc) exp(-(w/ws)^2); the residual of
// that equation at the final speed must be below 1e-7 N m.
TEST(Stribeck, BreakawayAtStaticLevelAndSteadyBalance) {
  DriveParams p = fadal_y();
  p.effects.stribeck = {true, 0.5, 2.0};
  const double KaKt = p.Ka_A_per_V * p.Kt_Nm_per_A;
  DriveBank held({p}, kTs_s);
  held.reset({0.0});
  run_constant(held, 0.45 / KaKt, 2000);
  EXPECT_EQ(held.output(0).x_mm, 0.0);
  DriveBank slip({p}, kTs_s);
  slip.reset({0.0});
  const double u = 0.505 / KaKt;
  run_constant(slip, u, 8000);
  const double w = slip.output(0).w_rad_per_s;
  EXPECT_GT(w, 0.0);
  const double residual =
      KaKt * u - (p.B_kg_m2_per_s * w + p.Tc_pos_Nm + (0.5 - p.Tc_pos_Nm) * std::exp(-(w / 2.0) * (w / 2.0)));
  EXPECT_LT(std::abs(residual), 1e-7);
}

// Oracle: inside the band the Coulomb level is Tc + dTc, so the steady speed
// there is (Ka Kt u - Tc - dTc)/B, and (Ka Kt u - Tc)/B before it.
// Y axis, J/B = 0.034 s; 0.5 s in the band = 14 time constants. Tolerance 1e-6 relative.
TEST(PositionDependentFriction, SteadySpeedInsideAndOutsideBand) {
  DriveParams p = fadal_y();
  p.effects.position_dependent_friction = {true, 0.1, 20.0, 1000.0};
  const double KaKt = p.Ka_A_per_V * p.Kt_Nm_per_A;
  const double u = 1.0;
  DriveBank bank = axis_at_rest(p);
  int k = 0;
  const double w_out = (KaKt * u - p.Tc_pos_Nm) / p.B_kg_m2_per_s;
  while (bank.state(0).x_mm < 19.0) run_constant(bank, u, 1, k++);
  EXPECT_NEAR(bank.output(0).w_rad_per_s, w_out, 1e-6 * w_out);
  run_constant(bank, u, 5000, k);
  const double w_in = (KaKt * u - p.Tc_pos_Nm - 0.1) / p.B_kg_m2_per_s;
  EXPECT_NEAR(bank.output(0).w_rad_per_s, w_in, 1e-6 * w_in);
}

// Oracle: energy balance with the spring, damper, cogging and a constant
// load: work_electrical = friction + damping + load + delta(kinetic + spring).
// Tolerance 1e-6 of the electrical work.
TEST(Energy, BalanceClosesWithComplianceCoggingAndLoad) {
  DriveParams p = fadal_x();
  p.effects.compliance = {true, 3000.0, 0.05, 0.5};
  p.effects.cogging = {true, 0.05, 4.0, 0.0};
  p.effects.constant_load = {true, 0.1};
  DriveBank bank = axis_at_rest(p);
  for (int k = 0; k < 10000; ++k) {
    const double u = 2.0 * std::sin(2.0 * std::numbers::pi * 3.0 * k * kTs_s);
    bank.advance(k * kTs_s, (k + 1) * kTs_s, {{u, 0.0}});
  }
  const DriveState& s = bank.state(0);
  const double rhs = s.work_friction_J + s.work_damping_J + s.work_load_J + kinetic_energy_J(p, s) +
                     spring_energy_J(p, s);
  EXPECT_GT(s.work_friction_J, 0.0);
  EXPECT_NEAR(s.work_electrical_J, rhs, 1e-6 * std::abs(s.work_electrical_J));
}


// Oracle: with smooth friction a torque below the Coulomb level does not hold
// the axis; it creeps at the speed w where Ka Kt u = B w + Tc_dir tanh(w / ws)
// (solved here by bisection), in each direction with that direction's level,
// while the same drive with stick/slip stays at rest. Tolerance 1e-7
// relative: after 2 s the transient (time constant J / (B + Tc / ws) at most
// 5 ms on these figures) is gone to far below that.
TEST(SmoothFriction, TorqueBelowCoulombCreepsAtTheBalanceSpeed) {
  DriveParams p = fadal_x();
  p.effects.smooth_friction.ws_rad_per_s = 0.5;
  for (const double frac : {0.5, -0.8}) {
    const double Tc = frac > 0 ? p.Tc_pos_Nm : p.Tc_neg_Nm;
    const double u_V = frac * Tc / (p.Ka_A_per_V * p.Kt_Nm_per_A);
    const double T = p.Ka_A_per_V * p.Kt_Nm_per_A * u_V;
    double lo = frac > 0 ? 0.0 : -100.0, hi = frac > 0 ? 100.0 : 0.0;
    for (int k = 0; k < 200; ++k) {
      const double w = 0.5 * (lo + hi);
      const double net = T - p.B_kg_m2_per_s * w - Tc * std::tanh(w / p.effects.smooth_friction.ws_rad_per_s);
      (net > 0.0 ? lo : hi) = w;
    }
    DriveParams smooth = p;
    smooth.effects.smooth_friction.enabled = true;
    DriveBank bank = axis_at_rest(smooth);
    run_constant(bank, u_V, 20000);
    EXPECT_NEAR(bank.output(0).w_rad_per_s, lo, 1e-7 * std::abs(lo)) << "u = " << u_V;
    EXPECT_GT(std::abs(bank.output(0).w_rad_per_s), 0.1 * p.effects.smooth_friction.ws_rad_per_s);
    DriveBank sticky({p}, kTs_s);
    sticky.reset({0.0});
    run_constant(sticky, u_V, 20000);
    EXPECT_EQ(sticky.output(0).w_rad_per_s, 0.0);
  }
  // With stribeck or compliance it is refused in one line naming the field.
  DriveParams both = p;
  both.effects.smooth_friction.enabled = true;
  both.effects.stribeck.enabled = true;
  both.effects.stribeck.Ts_static_Nm = 2.0 * std::max(p.Tc_pos_Nm, p.Tc_neg_Nm);
  EXPECT_THROW(both.validate("x"), ConfigError);
}

// Oracle: rising friction. Breakaway is share Tc_dir: a torque 5 % below it
// holds (exactly), one 5 % above it, still below the Coulomb level, slips and
// slides at the speed w where Ka Kt u = B w + Tc_dir (1 - (1 - share)
// exp(-(w/ws)^2)) (solved here by bisection; the friction rises with speed,
// so the balance has one root). Tolerance 1e-7 relative: after 2 s the
// transient (time constant J / (B + slope), below J / B = 35 ms on the Y
// drive) is gone to far below that. The same torque holds the axis with
// plain stick/slip. The energy balance closes to 1e-6 of the electrical work.
TEST(RisingFriction, BreakawayBelowCoulombAndSteadyBalance) {
  DriveParams p = fadal_y();
  p.effects.rising_friction = {true, 0.4, 2.0};
  const double KaKt = p.Ka_A_per_V * p.Kt_Nm_per_A;
  for (const int dir : {+1, -1}) {
    const double Tc = dir > 0 ? p.Tc_pos_Nm : p.Tc_neg_Nm;
    DriveBank held = axis_at_rest(p);
    run_constant(held, dir * 0.95 * 0.4 * Tc / KaKt, 2000);
    EXPECT_EQ(held.output(0).x_mm, 0.0) << dir;
    const double T = 1.05 * 0.4 * Tc;
    double lo = 0.0, hi = 100.0;
    for (int k = 0; k < 200; ++k) {
      const double w = 0.5 * (lo + hi);
      const double net = T - p.B_kg_m2_per_s * w - Tc * (1.0 - 0.6 * std::exp(-(w / 2.0) * (w / 2.0)));
      (net > 0.0 ? lo : hi) = w;
    }
    DriveBank slip = axis_at_rest(p);
    run_constant(slip, dir * T / KaKt, 20000);
    EXPECT_NEAR(slip.output(0).w_rad_per_s, dir * lo, 1e-7 * lo) << dir;
    EXPECT_GT(lo, 0.01);  // it slides (0.02 rad/s here), where stick/slip holds
    const DriveState& s = slip.state(0);
    EXPECT_GT(s.work_friction_J, 0.0);
    EXPECT_NEAR(s.work_electrical_J, s.work_friction_J + s.work_damping_J + s.work_load_J + kinetic_energy_J(p, s),
                1e-6 * std::abs(s.work_electrical_J));
    DriveParams plain = fadal_y();
    DriveBank sticky = axis_at_rest(plain);
    run_constant(sticky, dir * T / KaKt, 2000);
    EXPECT_EQ(sticky.output(0).x_mm, 0.0) << dir;
  }
  // A share outside [0, 1), or with smooth_friction, is refused in one line.
  DriveParams bad = p;
  bad.effects.rising_friction.share = 1.0;
  EXPECT_THROW(bad.validate("x"), ConfigError);
  DriveParams both = p;
  both.effects.smooth_friction.enabled = true;
  EXPECT_THROW(both.validate("x"), ConfigError);
}

// Oracle: load-dependent friction. Under a constant torque Tm the axis
// slides against Tc_dir + f |Tm|, so from rest w(t) = w_inf (1 - exp(-B t /
// J)) with w_inf = (Tm - dir (Tc_dir + f |Tm|)) / B, in both directions;
// a torque above Tc_dir but below Tc_dir / (1 - f) holds (exactly), since the
// breakaway level rises with it. Tolerance 1e-7 relative on w at 20 ms
// (the closed form is exact; the integrator's rtol is far below). The energy
// balance closes to 1e-6 of the electrical work.
TEST(LoadDependentFriction, FrictionRisesWithTheMotorsTorque) {
  DriveParams p = fadal_y();
  const double f = 0.2;
  p.effects.load_dependent_friction = {true, f};
  const double KaKt = p.Ka_A_per_V * p.Kt_Nm_per_A;
  for (const int dir : {+1, -1}) {
    const double Tc = dir > 0 ? p.Tc_pos_Nm : p.Tc_neg_Nm;
    const double Tm = dir * 4.0 * Tc;
    DriveBank bank = axis_at_rest(p);
    const int n = 200;
    run_constant(bank, Tm / KaKt, n);
    const double t = n * kTs_s;
    const double w_inf = (Tm - dir * (Tc + f * std::abs(Tm))) / p.B_kg_m2_per_s;
    const double w = w_inf * (1.0 - std::exp(-p.B_kg_m2_per_s * t / p.J_kg_m2));
    EXPECT_NEAR(bank.output(0).w_rad_per_s, w, 1e-7 * std::abs(w)) << dir;
    const DriveState& s = bank.state(0);
    EXPECT_NEAR(s.work_electrical_J, s.work_friction_J + s.work_damping_J + s.work_load_J + kinetic_energy_J(p, s),
                1e-6 * std::abs(s.work_electrical_J));
    // 1.1 Tc: above the Coulomb level, below Tc / (1 - f) = 1.25 Tc.
    DriveBank held = axis_at_rest(p);
    run_constant(held, dir * 1.1 * Tc / KaKt, 2000);
    EXPECT_EQ(held.output(0).x_mm, 0.0) << dir;
    DriveParams plain = fadal_y();
    DriveBank slips = axis_at_rest(plain);
    run_constant(slips, dir * 1.1 * Tc / KaKt, 2000);
    EXPECT_NE(slips.output(0).x_mm, 0.0) << dir;
  }
  DriveParams bad = p;
  bad.effects.load_dependent_friction.fraction = 0.6;
  EXPECT_THROW(bad.validate("x"), ConfigError);
}

// Oracle: the same closed loop integrated at the fine step on every tick,
// which is how the bank integrated smooth friction before it took coarse
// steps away from rest. With a speed scale of 0.002 rad/s, smooth
// friction's slope Tc / (ws J) = 12 900 1/s asks ceil(Ts (B + Tc / ws) / J
// / 0.25) = 6 ERK steps per 0.1 ms tick near zero speed; the bank now takes
// one where no torque on the axis can bring |w| to 10 ws within the tick
// (there tanh is 1 to 4e-9 and the drive linear). The reference is told to
// take those 6 steps on every tick. The loop is the FADAL PID on an
// unquantised position, tracking 4 mm sines at 0.5 and 3 Hz with a dwell
// between (20 000 ticks, reversals and a hard stop): each difference feeds
// back through the loop as in the co-simulation. Tolerance 1e-9 mm and
// 1e-6 rad/s: one step of a linear drive errs by (h B / J)^5 / 120 of the
// tick's motion, below 1e-15 here, and the friction by 4e-9 of Tc (found
// 5e-11 mm and 1.3e-8 rad/s, the speed's from the loop's hunting about the
// dwell); a coarse step taken into the tanh's knee errs by 1e-7 rad/s in a
// tick and, through the loop, by about 2e-4 mm (tried: a guard at the slope's
// limit alone, 3.8 ws here, or a switch to the fine step at a root within
// the tick, which restarts from the step's interpolant).
TEST(SmoothFriction, CoarseStepsAwayFromRestMatchFineStepsEverywhere) {
  DriveParams p = fadal_x();
  p.effects.smooth_friction = {true, 0.002};
  IntegratorOptions fine;
  fine.erk_fixed_steps_per_tick = static_cast<int>(
      std::ceil(kTs_s * (p.B_kg_m2_per_s + p.Tc_pos_Nm / p.effects.smooth_friction.ws_rad_per_s) / p.J_kg_m2 / 0.25));
  ASSERT_EQ(fine.erk_fixed_steps_per_tick, 6);
  DriveBank bank = axis_at_rest(p);
  DriveBank ref = axis_at_rest(p, fine);
  HandPid pid(fadal_x_gains(), kTs_s), pid_ref(fadal_x_gains(), kTs_s);
  const auto x_ref_mm = [](double t_s) {
    const double hold_mm = 4.0 * std::sin(2.0 * std::numbers::pi * 0.4);
    if (t_s < 0.8) return 4.0 * std::sin(2.0 * std::numbers::pi * 0.5 * t_s);
    if (t_s < 1.2) return hold_mm;
    return hold_mm + 4.0 * std::sin(2.0 * std::numbers::pi * 3.0 * (t_s - 1.2));
  };
  double max_dx_mm = 0.0, max_dw = 0.0;
  for (int k = 0; k < 20000; ++k) {
    const double r = x_ref_mm(k * kTs_s);
    const double u = pid.step(r, bank.output(0).x_meas_mm);
    const double u_ref = pid_ref.step(r, ref.output(0).x_meas_mm);
    bank.advance(k * kTs_s, (k + 1) * kTs_s, {{u, 0.0}});
    ref.advance(k * kTs_s, (k + 1) * kTs_s, {{u_ref, 0.0}});
    max_dx_mm = std::max(max_dx_mm, std::abs(bank.output(0).x_mm - ref.output(0).x_mm));
    max_dw = std::max(max_dw, std::abs(bank.output(0).w_rad_per_s - ref.output(0).w_rad_per_s));
  }
  EXPECT_LT(max_dx_mm, 1e-9);
  EXPECT_LT(max_dw, 1e-6);
  // It moves, and the coarse step saves most of the steps (a third is taken).
  EXPECT_GT(std::abs(ref.output(0).x_mm), 1.0);
  EXPECT_LT(bank.num_steps(), ref.num_steps() / 2);
}

}  // namespace
}  // namespace twin::feeddrive
