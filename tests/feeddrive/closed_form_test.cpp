// The closed-form advance of ordinary sliding ticks
// (IntegratorOptions::exact_linear_ticks) against SUNDIALS, side by side.
//
// Oracle: the same bank with exact_linear_ticks = false, where ARKODE
// integrates every tick (the integrator of record, itself held to the matrix
// exponential by feeddrive_linear_test to 1e-9 mm and to the closed-form
// friction solutions by feeddrive_friction_test). Each pair runs its own copy
// of the same PID, so a difference anywhere feeds back through the loop as it
// would in the co-simulation. Tolerance 1e-9 mm in position (the issue's
// bound): one fixed ERK step of Ts differs from the exact solution by about
// (h B/J)^5 / 120 of a tick's motion, below 1e-13 mm per tick on the FADAL
// drives, so a real error in the closed form (a wrong coefficient, the wrong
// Coulomb side, a missed event) shows by orders of magnitude above it.
//
// Events stay with SUNDIALS: every tick that starts from rest, has a stop or
// reversal inside, or clamps the current is checked to have been integrated,
// not advanced in closed form, and reversal and stop positions are checked
// against their closed-form two-phase solutions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "fadal_fixture.hpp"
#include "feeddrive/drive_bank.hpp"

namespace twin::feeddrive {
namespace {

// The FADAL fixture: its drives, gains, hand-written loop, period and encoder count.
using namespace testing;

constexpr double kTol_mm = 1e-9;

IntegratorOptions sundials_only() {
  IntegratorOptions o;
  o.exact_linear_ticks = false;
  return o;
}

DriveParams frictionless(DriveParams p) {
  p.Tc_pos_Nm = p.Tc_neg_Nm = 0.0;
  return p;
}

struct PairResult {
  double max_dx_mm{0.0};        // largest |x_closed - x_sundials| over ticks and axes
  double max_dwork_rel{0.0};    // largest relative difference of friction and damping work
  long closed_form_ticks{0};    // of the default bank
  long sundials_ticks{0};       // of the default bank
  long reference_closed_form{0};  // of the SUNDIALS-only bank (must be 0)
};

// Runs X and Y under their PIDs (reference ref_mm(axis, k), disturbance
// Td_Nm(axis, k)) in a default bank and a SUNDIALS-only bank, side by side.
PairResult run_pair(const std::vector<DriveParams>& params, const std::function<double(int, int)>& ref_mm,
                    const std::function<double(int, int)>& Td_Nm, int n, double x0_mm, bool quantised) {
  DriveBank fast(params, kTs_s);
  DriveBank slow(params, kTs_s, sundials_only());
  const std::vector<double> x0(params.size(), x0_mm);
  fast.reset(x0);
  slow.reset(x0);
  std::vector<HandPid> pid_f, pid_s;
  for (std::size_t a = 0; a < params.size(); ++a) {
    pid_f.emplace_back(a == 0 ? testing::fadal_x_gains() : testing::fadal_y_gains(), kTs_s);
    pid_s.emplace_back(a == 0 ? testing::fadal_x_gains() : testing::fadal_y_gains(), kTs_s);
  }
  std::vector<DriveInput> in_f(params.size()), in_s(params.size());
  PairResult res;
  for (int k = 0; k < n; ++k) {
    for (std::size_t a = 0; a < params.size(); ++a) {
      const int ai = static_cast<int>(a);
      const double r = ref_mm(ai, k);
      const double xf = fast.output(a).x_meas_mm, xs = slow.output(a).x_meas_mm;
      in_f[a] = {pid_f[a].step(r, quantised ? quantize_mm(xf, kCount_mm) : xf), Td_Nm(ai, k)};
      in_s[a] = {pid_s[a].step(r, quantised ? quantize_mm(xs, kCount_mm) : xs), Td_Nm(ai, k)};
    }
    fast.advance(k * kTs_s, (k + 1) * kTs_s, in_f);
    slow.advance(k * kTs_s, (k + 1) * kTs_s, in_s);
    for (std::size_t a = 0; a < params.size(); ++a)
      res.max_dx_mm = std::max(res.max_dx_mm, std::abs(fast.output(a).x_mm - slow.output(a).x_mm));
  }
  for (std::size_t a = 0; a < params.size(); ++a) {
    const DriveState& f = fast.state(a);
    const DriveState& s = slow.state(a);
    const auto rel = [](double u, double v) { return std::abs(u - v) / std::max(1e-300, std::abs(v)); };
    if (s.work_damping_J > 0.0) res.max_dwork_rel = std::max(res.max_dwork_rel, rel(f.work_damping_J, s.work_damping_J));
    if (s.work_friction_J > 0.0)
      res.max_dwork_rel = std::max(res.max_dwork_rel, rel(f.work_friction_J, s.work_friction_J));
  }
  res.closed_form_ticks = fast.num_closed_form_ticks();
  res.sundials_ticks = fast.num_sundials_ticks();
  res.reference_closed_form = slow.num_closed_form_ticks();
  return res;
}

const auto no_load = [](int, int) { return 0.0; };

// The two scenarios of feeddrive_linear_test (frictionless X and Y, FADAL PID,
// exact feedback): a 2 um step and a 20 mm/s ramp then hold.
TEST(ClosedFormVsSundials, LinearResponseStepAndRamp) {
  const std::vector<DriveParams> lin{frictionless(fadal_x()), frictionless(fadal_y())};
  const PairResult step = run_pair(lin, [](int, int) { return 150.002; }, no_load, 3000, 150.0, false);
  EXPECT_LT(step.max_dx_mm, kTol_mm);
  const auto ramp = [](int, int k) { return 300.0 + 20.0 * std::min(k, 3000) * kTs_s; };
  const PairResult r = run_pair(lin, ramp, no_load, 4000, 300.0, false);
  EXPECT_LT(r.max_dx_mm, kTol_mm);
  EXPECT_LT(r.max_dwork_rel, 1e-9);
  // The shortcut is really taken (most ticks) and never in the reference bank.
  EXPECT_GT(r.closed_form_ticks, 7000);
  EXPECT_EQ(r.reference_closed_form, 0);
}

// The friction scenario of feeddrive_friction_test's energy balance: X and Y
// with Coulomb friction, quantised feedback, sinusoidal references with a
// reversal every few hundred ms and a cutting-like disturbance torque, 2 s.
TEST(ClosedFormVsSundials, FrictionReversalsAndDisturbance) {
  const std::vector<DriveParams> p{fadal_x(), fadal_y()};
  const auto ref = [](int a, int k) { return 2.0 * std::sin(2.0 * 3.14159 * (1.5 + a) * k * kTs_s); };
  const auto Td = [](int, int k) { return 0.1 * std::sin(2.0 * 3.14159 * 40.0 * k * kTs_s); };
  const PairResult r = run_pair(p, ref, Td, 20000, 0.0, true);
  EXPECT_LT(r.max_dx_mm, kTol_mm);
  EXPECT_LT(r.max_dwork_rel, 1e-9);
  EXPECT_GT(r.closed_form_ticks, 20000);  // of 40000 axis-ticks
  EXPECT_GT(r.sundials_ticks, 0);         // reversals, stops, breakaways
  EXPECT_EQ(r.reference_closed_form, 0);
}

// Holding a position under quantised feedback: the axis sticks and slips
// around the target (many stick/slip transitions at tiny speeds).
TEST(ClosedFormVsSundials, HoldingPositionStickSlip) {
  const std::vector<DriveParams> p{fadal_x(), fadal_y()};
  const PairResult r = run_pair(p, [](int, int) { return 100.005; }, no_load, 15000, 100.0, true);
  EXPECT_LT(r.max_dx_mm, kTol_mm);
  EXPECT_GT(r.sundials_ticks, 0);
}

// One axis stepped tick by tick with constant inputs: records, per tick,
// whether it was advanced in closed form, with the speeds at both ends.
struct TickLog {
  std::vector<bool> closed_form;
  std::vector<double> w_start, w_end, x_end;
};

TickLog run_open_loop(DriveBank& bank, const std::vector<DriveInput>& in, int n) {
  TickLog log;
  for (int k = 0; k < n; ++k) {
    const long before = bank.num_closed_form_ticks();
    log.w_start.push_back(bank.state(0).w_rad_per_s);
    bank.advance(k * kTs_s, (k + 1) * kTs_s, in);
    log.closed_form.push_back(bank.num_closed_form_ticks() > before);
    log.w_end.push_back(bank.state(0).w_rad_per_s);
    log.x_end.push_back(bank.output(0).x_mm);
  }
  return log;
}

DriveBank bank_sliding(const DriveParams& p, double x0_mm, double w0, const IntegratorOptions& o) {
  DriveBank bank({p}, kTs_s, o);
  bank.reset({x0_mm});
  DriveState s = bank.state(0);
  s.w_rad_per_s = w0;
  s.stuck = false;
  bank.set_states({s});
  return bank;
}

// Oracle: a reversal under a constant command. From w0 = 3 rad/s with a motor
// torque T = -0.5 N m (beyond breakaway in -), the axis decelerates as
// J dw/dt = T - Tc_pos - B w until it stops at t1 = (J/B) ln(1 + B w0/(Tc_pos - T))
// having moved x1 = rg (J/B) (w0 - ((Tc_pos - T)/B) ln(...)), then accelerates
// in - as J dw/dt = T + Tc_neg - B w from rest:
//   w(t) = wn (1 - exp(-B t/J)), x(t) = x1 + rg wn (t - (J/B)(1 - exp(-B t/J))),
// wn = (T + Tc_neg)/B. Tolerance 1e-7 mm as in the stop test (root location to
// integrator accuracy); the two paths agree to 1e-9 mm. The tick holding the
// stop and every tick from rest must be SUNDIALS ticks.
TEST(ClosedFormEvents, ReversalIsIntegratedAndLocated) {
  const DriveParams p = fadal_x();
  const double T = -0.5;
  const double u = T / (p.Ka_A_per_V * p.Kt_Nm_per_A);
  const int n = 2000;
  DriveBank fast = bank_sliding(p, 10.0, 3.0, IntegratorOptions{});
  DriveBank slow = bank_sliding(p, 10.0, 3.0, sundials_only());
  const TickLog lf = run_open_loop(fast, {{u, 0.0}}, n);
  const TickLog ls = run_open_loop(slow, {{u, 0.0}}, n);
  const double B = p.B_kg_m2_per_s, J = p.J_kg_m2, rg = p.rg_mm_per_rad;
  const double L = std::log(1.0 + B * 3.0 / (p.Tc_pos_Nm - T));
  const double t1 = J / B * L;
  const double x1 = 10.0 + rg * J / B * (3.0 - (p.Tc_pos_Nm - T) / B * L);
  const double wn = (T + p.Tc_neg_Nm) / B;
  int reversals = 0;
  for (int k = 0; k < n; ++k) {
    EXPECT_NEAR(lf.x_end[k], ls.x_end[k], kTol_mm) << "tick " << k;
    const bool event = lf.w_start[k] == 0.0 || lf.w_start[k] * lf.w_end[k] <= 0.0;
    if (event) {
      EXPECT_FALSE(lf.closed_form[k]) << "tick " << k << ": w from " << lf.w_start[k] << " to " << lf.w_end[k];
      ++reversals;
    }
    const double t = (k + 1) * kTs_s;
    if (t > t1) {
      const double tau = t - t1;
      const double x = x1 + rg * wn * (tau - J / B * (-std::expm1(-B * tau / J)));
      EXPECT_NEAR(lf.x_end[k], x, 1e-7) << "tick " << k;
    }
  }
  EXPECT_EQ(reversals, 1);
  // Ordinary ticks before and after the reversal were taken in closed form.
  EXPECT_GT(fast.num_closed_form_ticks(), n - 10);
}

// Stick -> slip -> stick: at rest under a torque below breakaway (no motion,
// no integration), a push above breakaway (slip from rest: SUNDIALS), then the
// command removed so the axis stops inside a tick and sticks (SUNDIALS, stop
// located), and stays stuck. Both paths agree to 1e-9 mm at every tick and
// end bit-for-bit at rest at the same place.
TEST(ClosedFormEvents, StickSlipStickTransitions) {
  const DriveParams p = fadal_y();
  const double u_per_Nm = 1.0 / (p.Ka_A_per_V * p.Kt_Nm_per_A);
  DriveBank fast({p}, kTs_s);
  DriveBank slow({p}, kTs_s, sundials_only());
  fast.reset({5.0});
  slow.reset({5.0});
  int k = 0;
  int slips = 0, stops = 0;
  const auto phase = [&](double T_Nm, int ticks) {
    for (int j = 0; j < ticks; ++j, ++k) {
      const long before = fast.num_closed_form_ticks();
      const double w0 = fast.state(0).w_rad_per_s;
      fast.advance(k * kTs_s, (k + 1) * kTs_s, {{T_Nm * u_per_Nm, 0.0}});
      slow.advance(k * kTs_s, (k + 1) * kTs_s, {{T_Nm * u_per_Nm, 0.0}});
      const bool closed = fast.num_closed_form_ticks() > before;
      const double w1 = fast.state(0).w_rad_per_s;
      if (w0 == 0.0 && w1 != 0.0) ++slips;
      if (w0 != 0.0 && w1 == 0.0) ++stops;
      if (w0 == 0.0 || w1 == 0.0) {
        EXPECT_FALSE(closed) << "tick " << k;
      }
      EXPECT_NEAR(fast.output(0).x_mm, slow.output(0).x_mm, kTol_mm) << "tick " << k;
    }
  };
  phase(0.9 * p.Tc_pos_Nm, 500);
  EXPECT_EQ(fast.output(0).x_mm, 5.0);
  phase(1.5 * p.Tc_pos_Nm, 3000);
  EXPECT_GT(fast.output(0).x_mm, 5.0);
  phase(0.0, 3000);
  EXPECT_EQ(slips, 1);
  EXPECT_EQ(stops, 1);
  EXPECT_TRUE(fast.state(0).stuck);
  EXPECT_EQ(fast.state(0).w_rad_per_s, 0.0);
  EXPECT_NEAR(fast.output(0).x_mm, slow.output(0).x_mm, kTol_mm);
  EXPECT_GT(fast.num_closed_form_ticks(), 3000);  // the slip phase and the slow-down before the stop
}

// Oracle: one tick of J dw/dt = F - B w, dx/dt = rg w from w0, in closed form
// (w = w0 e + (F/B)(1 - e), e = exp(-B h/J)). When w(h) ends a comfortable
// 10 % of w0 above zero the tick is taken in closed form and matches the
// formula to 1e-12 relative; when it ends 1e-9 of w0 above zero (inside the
// 1e-6 margin) the tick goes to SUNDIALS: a conservative decision.
TEST(ClosedFormEvents, NearStopTickGoesToSundials) {
  const DriveParams p = fadal_y();
  const double B = p.B_kg_m2_per_s, J = p.J_kg_m2, h = kTs_s;
  const double one_minus_e = -std::expm1(-B * h / J);
  const double e = 1.0 - one_minus_e;
  const double w0 = 0.01;
  for (const double end_fraction : {0.1, 1e-9}) {
    // F such that w(h) = end_fraction w0: F = B (w_end - w0 e)/(1 - e).
    const double F = B * (end_fraction * w0 - w0 * e) / one_minus_e;
    const double T_motor = F + p.Tc_pos_Nm;
    DriveBank bank = bank_sliding(p, 0.0, w0, IntegratorOptions{});
    bank.advance(0.0, h, {{T_motor / (p.Ka_A_per_V * p.Kt_Nm_per_A), 0.0}});
    const bool closed = bank.num_closed_form_ticks() == 1;
    if (end_fraction > 1e-3) {
      EXPECT_TRUE(closed);
      const double w_expected = end_fraction * w0;
      const double x_expected = p.rg_mm_per_rad * (F / B * h + (w0 - F / B) * J / B * one_minus_e);
      EXPECT_NEAR(bank.state(0).w_rad_per_s, w_expected, 1e-12 * w0);
      EXPECT_NEAR(bank.output(0).x_mm, x_expected, 1e-12 * std::abs(x_expected));
    } else {
      EXPECT_FALSE(closed);
      EXPECT_EQ(bank.num_sundials_ticks(), 1);
    }
  }
}

// Oracle: the one-tick solution of J dw/dt = F - B w from w0 with
// w_inf = F/B and d = w0 - w_inf: w(h) = w_inf + d e^{-z}, z = B h/J,
// theta(h) = w_inf h + d (J/B)(1 - e^{-z}),
// int w^2 = w_inf^2 h + 2 w_inf d (J/B)(1 - e^{-z}) + d^2 (J/2B)(1 - e^{-2z}).
// The bank sums power series for z < 1 and uses closed forms above; both
// sides of the switch (z = 0.5, 0.999, 1.001, 3) must match to 1e-12 relative
// (the formulas have no cancellation for z >= 0.5).
TEST(ClosedFormEvents, CoefficientsOnBothSidesOfTheSeriesSwitch) {
  for (const double z : {0.5, 0.999, 1.001, 3.0}) {
    DriveParams p = fadal_y();
    p.B_kg_m2_per_s = z * p.J_kg_m2 / kTs_s;
    const double B = p.B_kg_m2_per_s, J = p.J_kg_m2, h = kTs_s;
    const double w0 = 2.0;
    const double T_motor = 0.5 * B * w0 + p.Tc_pos_Nm;  // w_inf = w0 / 2: stays positive
    DriveBank bank = bank_sliding(p, 0.0, w0, IntegratorOptions{});
    bank.advance(0.0, h, {{T_motor / (p.Ka_A_per_V * p.Kt_Nm_per_A), 0.0}});
    ASSERT_EQ(bank.num_closed_form_ticks(), 1) << "z = " << z;
    const double w_inf = (T_motor - p.Tc_pos_Nm) / B, d = w0 - w_inf;
    const double w = w_inf + d * std::exp(-z);
    const double theta = w_inf * h + d * J / B * (-std::expm1(-z));
    const double int_w2 = w_inf * w_inf * h + 2.0 * w_inf * d * J / B * (-std::expm1(-z)) +
                          d * d * J / (2.0 * B) * (-std::expm1(-2.0 * z));
    EXPECT_NEAR(bank.state(0).w_rad_per_s, w, 1e-12 * w) << "z = " << z;
    EXPECT_NEAR(bank.output(0).x_mm, p.rg_mm_per_rad * theta, 1e-12 * p.rg_mm_per_rad * theta) << "z = " << z;
    EXPECT_NEAR(bank.state(0).work_damping_J, B * int_w2, 1e-12 * B * int_w2) << "z = " << z;
    EXPECT_NEAR(bank.state(0).work_friction_J, p.Tc_pos_Nm * theta, 1e-12 * p.Tc_pos_Nm * theta) << "z = " << z;
  }
}

// Nonlinear effects keep every tick on SUNDIALS; linear ones (constant load,
// backlash, delay, screw error) keep the shortcut and agree to 1e-9 mm; a
// current limit sends exactly its clamped ticks to SUNDIALS.
TEST(ClosedFormEffects, WhichEffectsKeepTheShortcut) {
  const auto ref = [](int a, int k) { return 2.0 * std::sin(2.0 * 3.14159 * (1.5 + a) * k * kTs_s); };
  {
    DriveParams p = fadal_x();
    p.effects.cogging = {true, 0.02, 4.0, 0.3};
    DriveParams q = fadal_y();
    q.effects.stribeck = {true, 0.4, 0.5};
    const PairResult r = run_pair({p, q}, ref, no_load, 3000, 0.0, true);
    EXPECT_EQ(r.closed_form_ticks, 0);
    EXPECT_EQ(r.max_dx_mm, 0.0);  // same SUNDIALS ticks on both sides: bit for bit
  }
  {
    DriveParams p = fadal_x();
    p.effects.constant_load = {true, 0.15};
    p.effects.delay = {true, 3e-4};
    p.effects.screw_pitch_error = {true, 0.002, 5.0, 0.1};
    DriveParams q = fadal_y();
    q.effects.backlash = {true, 0.004};
    const PairResult r = run_pair({p, q}, ref, no_load, 10000, 0.0, true);
    EXPECT_GT(r.closed_form_ticks, 10000);
    EXPECT_LT(r.max_dx_mm, kTol_mm);
  }
  {
    DriveParams p = fadal_x();
    p.effects.current_saturation = {true, 5.0};
    const double u_clamped = 2.0 * 5.0 / p.Ka_A_per_V;  // twice the limit
    DriveBank bank = bank_sliding(p, 0.0, 2.0, IntegratorOptions{});
    const TickLog log = run_open_loop(bank, {{u_clamped, 0.0}}, 100);
    for (int k = 0; k < 100; ++k) EXPECT_FALSE(log.closed_form[k]) << "tick " << k;
    DriveBank free = bank_sliding(p, 0.0, 2.0, IntegratorOptions{});
    const TickLog log_free = run_open_loop(free, {{0.5 * 5.0 / p.Ka_A_per_V, 0.0}}, 100);
    for (int k = 0; k < 100; ++k) EXPECT_TRUE(log_free.closed_form[k]) << "tick " << k;
  }
}

}  // namespace
}  // namespace twin::feeddrive
