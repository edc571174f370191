// Tests of the linear position-loop analysis (twin/tune/linear_analysis.hpp).
#include "twin/tune/linear_analysis.hpp"

#include <cmath>
#include <complex>
#include <vector>

#include <gtest/gtest.h>

#include "controller/position_loop.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::analysis {
namespace {

constexpr double kTs_s = 1e-4;

// FADAL 2216 X drive, Ozcan 2017 Table 1, and the Table 3 gains.
LinearPlant fadal_x() { return LinearPlant{6.4898, 0.4769, 0.0077736, 0.019811, 1.5915}; }
controller::PositionLoopParams table3_x() {
  controller::PositionLoopParams g;
  g.Kp_V_per_mm = 500.0;
  g.Ki_V_per_s_mm = 70.0;
  g.Kd_V_s_per_mm = 0.3;
  g.K1_V_s2_per_mm = 0.0;
  g.K2_V_s_per_mm = -2.37e-6;
  return g;
}

/// A PD position loop: Kp and Kd, no integral and no feedforward.
controller::PositionLoopParams pd_loop(double Kp_V_per_mm, double Kd_V_s_per_mm) {
  controller::PositionLoopParams g;
  g.Kp_V_per_mm = Kp_V_per_mm;
  g.Kd_V_s_per_mm = Kd_V_s_per_mm;
  return g;
}

/// An independent closed loop: the drive integrated in closed form over each
/// tick with u held (w(t) = w0 e^{-at} + (G/a)(1 - e^{-at}), a = B/J, G = Ka Kt u / J;
/// x the integral of rg w), and the law from controller::PositionLoop; the drive
/// applies the command of `delay_ticks` ticks before (0 before the first).
std::vector<double> reference_closed_loop(const LinearPlant& p, const controller::PositionLoopParams& g,
                                          const std::vector<double>& x_ref, std::size_t delay_ticks = 0) {
  controller::PositionLoopParams unclamped = g;
  unclamped.u_max_V = 1e12;
  controller::PositionLoop loop(unclamped, kTs_s);
  double w = 0.0, x = 0.0;
  const double a = p.B_kg_m2_per_s / p.J_kg_m2, Ts = kTs_s;
  std::vector<double> out, u_given;
  for (std::size_t k = 0; k < x_ref.size(); ++k) {
    out.push_back(x);
    u_given.push_back(loop.step(static_cast<std::int64_t>(k), x_ref[k], x).u_unclamped_V);
    const double u = k >= delay_ticks ? u_given[k - delay_ticks] : 0.0;
    const double G = p.Ka_A_per_V * p.Kt_Nm_per_A * u / p.J_kg_m2;
    if (a > 0.0) {
      const double E = std::exp(-a * Ts);
      const double w_inf = G / a;
      x += p.rg_mm_per_rad * (w_inf * Ts + (w - w_inf) * (1.0 - E) / a);
      w = w_inf + (w - w_inf) * E;
    } else {
      x += p.rg_mm_per_rad * (w * Ts + 0.5 * G * Ts * Ts);
      w += G * Ts;
    }
  }
  return out;
}

// Oracle: the exact ZOH discretisation of J dw/dt = Ka Kt u - B w, dx/dt = rg w in
// closed form. Tolerance 1e-12 relative: the Taylor series is truncated below 1e-16.
TEST(LinearAnalysis, ZohDiscretisationMatchesClosedForm) {
  const LinearPlant p = fadal_x();
  const DiscreteLoopModel m(p, table3_x(), kTs_s);
  const double a = p.B_kg_m2_per_s / p.J_kg_m2, Ts = 1e-4, E = std::exp(-a * Ts);
  const double G = p.Ka_A_per_V * p.Kt_Nm_per_A / p.J_kg_m2;
  EXPECT_NEAR(m.Phi()(0, 0), E, 1e-14);
  EXPECT_NEAR(m.Phi()(1, 0), p.rg_mm_per_rad * (1.0 - E) / a, 1e-16);
  EXPECT_NEAR(m.Phi()(1, 1), 1.0, 1e-15);
  EXPECT_NEAR(m.Gamma()(0) / (G * (1.0 - E) / a), 1.0, 1e-12);
  EXPECT_NEAR(m.Gamma()(1) / (p.rg_mm_per_rad * G / a * (Ts - (1.0 - E) / a)), 1.0, 1e-9);
}

// Oracle: a pure inertia (B = 0) under PD, continuous time: L(s) = K (Kp + Kd s) / s^2,
// K = Ka Kt rg / J. Gain crossover from |L| = 1: w^4 = K^2 (Kp^2 + Kd^2 w^2);
// PM = atan(Kd wc / Kp); -3 dB bandwidth of T = L/(1+L):
// w^2 = (b + sqrt(b^2 + 4 K^2 Kp^2)) / 2, b = 2 K Kp + K^2 Kd^2; no finite gain margin.
// At Ts = 1e-6 s the ZOH and the backward difference lag by about wc Ts (rad),
// 0.1 deg here: tolerance 0.3 deg on PM and 0.5 % on the frequencies.
TEST(LinearAnalysis, PureInertiaUnderPdMatchesContinuousClosedForms) {
  LinearPlant p = fadal_x();
  p.B_kg_m2_per_s = 0.0;
  const controller::PositionLoopParams g = pd_loop(500.0, 1.0);
  const double Ts_s = 1e-6;
  const DiscreteLoopModel m(p, g, Ts_s);
  const LoopAnalysis a = analyse_loop(m, 0.1, 6000);
  const double K = p.Ka_A_per_V * p.Kt_Nm_per_A * p.rg_mm_per_rad / p.J_kg_m2;
  const double Kp = g.Kp_V_per_mm, Kd = g.Kd_V_s_per_mm;
  const double w2 = 0.5 * (K * K * Kd * Kd + std::sqrt(std::pow(K * K * Kd * Kd, 2) + 4.0 * K * K * Kp * Kp));
  const double wc = std::sqrt(w2);
  const double pm = std::atan(Kd * wc / Kp) * kDegPerRad;
  const double b = 2.0 * K * Kp + K * K * Kd * Kd;
  const double wb = std::sqrt(0.5 * (b + std::sqrt(b * b + 4.0 * K * K * Kp * Kp)));
  ASSERT_TRUE(a.stable);
  EXPECT_NEAR(a.gain_crossover_Hz / (wc / (2.0 * kPi)), 1.0, 5e-3);
  EXPECT_NEAR(a.phase_margin_deg, pm, 0.3);
  EXPECT_LT(a.phase_margin_deg, pm);  // the discretisation only adds lag
  EXPECT_NEAR(a.bandwidth_Hz / (wb / (2.0 * kPi)), 1.0, 5e-3);
  EXPECT_GT(a.gain_margin_dB, 40.0);
  // Sensitivity peak against the continuous S = s^2 / (s^2 + K Kd s + K Kp) on a fine grid.
  double ms = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const double w = 0.1 * std::pow(10.0, 6.0 * i / 200000.0);
    const std::complex<double> s(0.0, w);
    ms = std::max(ms, std::abs(s * s / (s * s + K * Kd * s + K * Kp)));
  }
  EXPECT_NEAR(a.sensitivity_peak, ms, 5e-3 * ms);
}

// Oracle: the same PD loop with a lower phase margin (Kd small) at the real Ts: the
// continuous PM less the discretisation lag wc Ts (ZOH Ts/2 plus the backward
// difference on the D term, at most Ts/2): within [pm - wc Ts - 0.2 deg, pm].
TEST(LinearAnalysis, PhaseMarginAtRealTsLosesAtMostTheSampleLag) {
  LinearPlant p = fadal_x();
  p.B_kg_m2_per_s = 0.0;
  const controller::PositionLoopParams g = pd_loop(500.0, 0.3);
  const LoopAnalysis a = analyse_loop(DiscreteLoopModel(p, g, kTs_s));
  const double K = p.Ka_A_per_V * p.Kt_Nm_per_A * p.rg_mm_per_rad / p.J_kg_m2;
  const double Kp = g.Kp_V_per_mm, Kd = g.Kd_V_s_per_mm;
  const double wc = std::sqrt(0.5 * (K * K * Kd * Kd + std::sqrt(std::pow(K * K * Kd * Kd, 2) + 4.0 * K * K * Kp * Kp)));
  const double pm = std::atan(Kd * wc / Kp) * kDegPerRad;
  const double lag = wc * kTs_s * kDegPerRad;
  EXPECT_LT(a.phase_margin_deg, pm);
  EXPECT_GT(a.phase_margin_deg, pm - lag - 0.2);
  // The ZOH makes the gain margin finite: read at Nyquist or below it.
  EXPECT_TRUE(std::isfinite(a.gain_margin_dB));
  EXPECT_LE(a.phase_crossover_Hz, 0.5 / kTs_s + 1e-9);
}

// Oracle: an independent closed-loop simulation (closed-form drive per tick and
// controller::PositionLoop). The error of a step obeys the characteristic recurrence
// prod (z - p_i) of the reported poles once the step has passed the law's memory (k >= 4).
// Tolerance 1e-9 of the step: rounding in the polynomial coefficients of poles near 1.
TEST(LinearAnalysis, PolesMatchAnIndependentStepResponse) {
  const LinearPlant p = fadal_x();
  const controller::PositionLoopParams g = table3_x();
  const DiscreteLoopModel m(p, g, kTs_s);
  const auto poles = m.poles();
  ASSERT_EQ(poles.size(), 4u);
  std::vector<std::complex<double>> c{1.0};  // c[0] z^n + c[1] z^{n-1} + ...
  for (const auto& z0 : poles) {
    std::vector<std::complex<double>> next(c.size() + 1, 0.0);
    for (std::size_t i = 0; i < c.size(); ++i) {
      next[i] += c[i];
      next[i + 1] -= z0 * c[i];
    }
    c = next;
  }
  const std::vector<double> x = reference_closed_loop(p, g, std::vector<double>(600, 0.01));
  double worst = 0.0;
  for (std::size_t k = 4; k + 4 < x.size(); ++k) {
    std::complex<double> s = 0.0;
    for (std::size_t i = 0; i <= 4; ++i) s += c[i] * (0.01 - x[k + 4 - i]);
    worst = std::max(worst, std::abs(s));
  }
  EXPECT_LT(worst, 1e-9 * 0.01);
  EXPECT_TRUE(m.stable());
}

// Oracle: the same independent simulation with feedforward on a smooth move
// (x_ref = 5 mm (1 - cos(2 pi 3 t))/2). The model's own time simulation must agree
// to 1e-9 mm: both are exact discretisations, only rounding differs.
TEST(LinearAnalysis, SimulationMatchesIndependentClosedLoopWithFeedforward) {
  const LinearPlant p = fadal_x();
  controller::PositionLoopParams g = table3_x();
  const FeedforwardGains ff = model_feedforward(p);
  g.K1_V_s2_per_mm = ff.K1_V_s2_per_mm;
  g.K2_V_s_per_mm = ff.K2_V_s_per_mm;
  std::vector<double> r(4000);
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = 2.5 * (1.0 - std::cos(2.0 * kPi * 3.0 * 1e-4 * static_cast<double>(k)));
  const auto x1 = DiscreteLoopModel(p, g, kTs_s).simulate(r);
  const auto x2 = reference_closed_loop(p, g, r);
  for (std::size_t k = 0; k < r.size(); ++k) ASSERT_NEAR(x1[k], x2[k], 1e-9) << "k=" << k;
}

// Oracles: (1) the independent closed loop with the drive applying the command of two
// ticks before, on the smooth move with the model feedforward: the model's time response
// with a 0.2 ms dead time matches it to 1e-9 mm (both exact discretisations); (2) a dead
// time of d ticks multiplies L by z^-d, which leaves |L|, and so the gain crossover, where
// it was and takes 360 f_c d Ts degrees of phase there: the phase margin with it is the
// one without less that (tolerance 1e-6 deg, the bisection's).
TEST(LinearAnalysis, ACommandDelayIsADeadTimeInTheLoop) {
  LinearPlant p = fadal_x();
  controller::PositionLoopParams g = table3_x();
  const FeedforwardGains ff = model_feedforward(p);
  g.K1_V_s2_per_mm = ff.K1_V_s2_per_mm;
  g.K2_V_s_per_mm = ff.K2_V_s_per_mm;
  const LoopAnalysis without = analyse_loop(DiscreteLoopModel(p, g, kTs_s));
  p.command_delay_s = 2e-4;
  const DiscreteLoopModel m(p, g, kTs_s);
  ASSERT_EQ(m.delay_ticks(), 2);
  std::vector<double> r(4000);
  for (std::size_t k = 0; k < r.size(); ++k) r[k] = 2.5 * (1.0 - std::cos(2.0 * kPi * 3.0 * 1e-4 * static_cast<double>(k)));
  const auto x1 = m.simulate(r);
  const auto x2 = reference_closed_loop(p, g, r, 2);
  for (std::size_t k = 0; k < r.size(); ++k) ASSERT_NEAR(x1[k], x2[k], 1e-9) << "k=" << k;
  const LoopAnalysis with = analyse_loop(m);
  EXPECT_NEAR(with.gain_crossover_Hz, without.gain_crossover_Hz, 1e-6 * without.gain_crossover_Hz);
  EXPECT_NEAR(with.phase_margin_deg, without.phase_margin_deg - 360.0 * without.gain_crossover_Hz * 2e-4, 1e-6);
  EXPECT_EQ(m.poles().size(), 4u + 2u);  // the loop's four and the two commands in flight
}

// Oracle: the steady sinusoidal tracking error of the independent simulation against
// |E/R| and |X/R| at that frequency (least-squares fit of sin, cos, offset and drift
// over the last 0.2 s, after 0.8 s of transient). Tolerance 1 % of the amplitude: the
// integrator's slow transient (Ki/Kp ~ 0.14/s) is absorbed by the drift terms.
TEST(LinearAnalysis, TrackingErrorTransferFunctionMatchesSinusoidalResponse) {
  const LinearPlant p = fadal_x();
  for (bool with_ff : {false, true}) {
    controller::PositionLoopParams g = table3_x();
    if (with_ff) {
      g.K1_V_s2_per_mm = 0.8 * model_feedforward(p).K1_V_s2_per_mm;
      g.K2_V_s_per_mm = model_feedforward(p).K2_V_s_per_mm;
    }
    const double f = 20.0, Ts = kTs_s;
    std::vector<double> r(10000);
    for (std::size_t k = 0; k < r.size(); ++k) r[k] = std::sin(2.0 * kPi * f * Ts * static_cast<double>(k));
    const auto x = reference_closed_loop(p, g, r);
    Eigen::MatrixXd A(2000, 4);
    Eigen::VectorXd y(2000);
    for (int i = 0; i < 2000; ++i) {
      const std::size_t k = 8000 + static_cast<std::size_t>(i);
      const double t = Ts * static_cast<double>(k);
      A.row(i) << std::sin(2.0 * kPi * f * t), std::cos(2.0 * kPi * f * t), 1.0, t - 0.9;
      y(i) = r[k] - x[k];
    }
    const Eigen::Vector4d c = A.colPivHouseholderQr().solve(y);
    const double amp = std::hypot(c(0), c(1));
    const DiscreteLoopModel m(p, g, kTs_s);
    EXPECT_NEAR(amp, std::abs(m.error_response(f)), 0.01 * std::abs(m.error_response(f))) << with_ff;
    EXPECT_NEAR(std::abs(1.0 - m.error_response(f) - m.position_response(f)), 0.0, 1e-12);
  }
}

// Oracle: model feedforward by definition K1 = J/(Ka Kt rg), K2 = B/(Ka Kt rg) (hand
// arithmetic for the FADAL X drive), and with it the linear tracking error is far below
// the error without it (|E/R| at 10 Hz at least 20x smaller).
TEST(LinearAnalysis, ModelFeedforwardCancelsThePlant) {
  const LinearPlant p = fadal_x();
  const FeedforwardGains ff = model_feedforward(p);
  EXPECT_NEAR(ff.K1_V_s2_per_mm, 0.0077736 / (6.4898 * 0.4769 * 1.5915), 1e-15);
  EXPECT_NEAR(ff.K2_V_s_per_mm, 0.019811 / (6.4898 * 0.4769 * 1.5915), 1e-15);
  controller::PositionLoopParams g = table3_x();
  const double without = analyse_loop(DiscreteLoopModel(p, g, kTs_s)).error_gain_10Hz;
  g.K1_V_s2_per_mm = ff.K1_V_s2_per_mm;
  g.K2_V_s_per_mm = ff.K2_V_s_per_mm;
  const double with = analyse_loop(DiscreteLoopModel(p, g, kTs_s)).error_gain_10Hz;
  EXPECT_LT(with, without / 20.0);
}

// Oracle: the Table 3 loop has a gain margin of about 39 dB, read at a phase crossover
// dominated by the D term; raising Kd 200x (46 dB) must leave the loop unstable.
TEST(LinearAnalysis, UnstableGainsAreReportedUnstable) {
  controller::PositionLoopParams g = table3_x();
  g.Kd_V_s_per_mm = 60.0;
  const LoopAnalysis a = analyse_loop(DiscreteLoopModel(fadal_x(), g, kTs_s));
  EXPECT_FALSE(a.stable);
  EXPECT_GT(a.max_pole_magnitude, 1.0);
}

TEST(LinearAnalysis, NonPhysicalPlantIsAConfigError) {
  LinearPlant p = fadal_x();
  p.J_kg_m2 = -1.0;
  EXPECT_THROW(DiscreteLoopModel(p, table3_x(), kTs_s, "x"), ConfigError);
}

}  // namespace
}  // namespace twin::analysis
