// The cascade position loop (spec/measured-data.md, "Position loops of real
// machines") closed around the SUNDIALS-integrated drive, against the exact
// discrete response of the same loop: the plant J dw/dt = T - B w,
// dx/dt = rg w under the zero-order hold, discretised with Eigen's matrix
// exponential, and the law written again here from the spec's equations.
// Friction off and an ideal encoder make the loop linear, so the only
// difference is the integrator's error over one tick: 1e-9 mm bounds it
// (the drive's fixed-step ERK is ~1e-12 mm from the exact solution on the
// FADAL loop, docs/feeddrive.md). The same holds for the torque's mean over
// a period's velocity-loop ticks (AxisSnapshot::period_mean), summed tick by
// tick in the exact response.
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Dense>
#include <unsupported/Eigen/MatrixFunctions>

#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/sim/cosimulation.hpp"

namespace twin {
namespace {

sim::MachineDefinition cascade_x(double Ts_s, const controller::CascadeGains& g) {
  sim::MachineDefinition m = io::load_machine(io::resolve_machine_path("fadal2216"));
  m.axes[index(Axis::kY)].present = false;
  m.axes[index(Axis::kZ)].present = false;
  m.Ts_s = Ts_s;
  m.encoder_resolution_mm = 0.0;
  sim::AxisDefinition& x = m.axes[index(Axis::kX)];
  x.drive.Tc_pos_Nm = 0.0;
  x.drive.Tc_neg_Nm = 0.0;
  x.following_error_limit_mm = 50.0;  // a P loop lags v / Kv: several mm at these speeds
  x.loop.cascade = g;
  sim::set_machine_loop_law(m, controller::LoopLaw::kCascade);
  return m;
}

// A smooth move: 10 mm in 0.1 s with a sine-squared speed profile, then rest.
std::vector<double> reference(double Ts_s, std::size_t n) {
  std::vector<double> r(n, 0.0);
  const double T = 0.1, L = 10.0;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * Ts_s;
    r[k] = t >= T ? L : L * (t / T - std::sin(2.0 * M_PI * t / T) / (2.0 * M_PI));
  }
  return r;
}

struct Exact {
  std::vector<double> x_mm, torque;
  std::vector<double> command;  ///< the velocity loop's torque, before the current loop's lag
  /// torque and command as their means over the velocity loop's ticks of
  /// each period, summed here tick by tick (the period from tick k to k+1)
  std::vector<double> torque_mean, command_mean;
};

Exact exact_response(const sim::MachineDefinition& m, const std::vector<double>& r) {
  const auto& ax = m.axes[index(Axis::kX)];
  const double J = ax.drive.J_kg_m2, B = ax.drive.B_kg_m2_per_s, rg = ax.drive.rg_mm_per_rad, Ts = m.Ts_s;
  const controller::CascadeGains& g = ax.loop.cascade;
  // The velocity loop's ticks a period (Tv divides Ts; 0: one).
  const int n = g.Tv_s > 0.0 ? static_cast<int>(std::lround(Ts / g.Tv_s)) : 1;
  const double Tv = Ts / n;
  // Augmented [w, x, T]: T constant over the velocity loop's tick.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  A(0, 0) = -B / J;
  A(0, 2) = 1.0 / J;
  A(1, 0) = rg;
  const Eigen::Matrix3d E = (A * Tv).exp();
  const double lag = g.tau_i_s > 0.0 ? std::exp(-Tv / g.tau_i_s) : 0.0;
  // The reference the loop follows: the CNC's smoothing (command_average_s,
  // command_lag_s) and dead time (command_delay_s) written again here: the
  // mean of the last N references (the first one before the run), then
  // y = a y + (1 - a) u, then y as it was D ticks before (the first before the run).
  std::vector<double> smoothed(r.size()), followed(r.size());
  const int N = g.command_average_s > 0.0 ? static_cast<int>(std::lround(g.command_average_s / Ts)) : 1;
  const double a_cmd = g.command_lag_s > 0.0 ? std::exp(-Ts / g.command_lag_s) : 0.0;
  const auto D = static_cast<std::size_t>(std::lround(g.command_delay_s / Ts));
  double y = r[0];
  for (std::size_t k = 0; k < r.size(); ++k) {
    double sum = 0.0;
    for (int j = 0; j < N; ++j) sum += r[k >= static_cast<std::size_t>(j) ? k - static_cast<std::size_t>(j) : 0];
    y = a_cmd * y + (1.0 - a_cmd) * sum / N;
    smoothed[k] = y;
    followed[k] = smoothed[k >= D ? k - D : 0];
  }
  Exact out;
  double w = 0.0, x = r[0], Iv = 0.0, Tf = 0.0, r_prev = r[0], v_prev = 0.0;
  for (std::size_t k = 0; k < r.size(); ++k) {
    // The feedforward from the reference as given where the law says so.
    const double rk = g.feedforward_unsmoothed == 1.0 ? r[k] : followed[k];
    const double e = followed[k] - x;
    const double v_ref = (rk - r_prev) / Ts;
    const double a_ref = (v_ref - v_prev) / Ts;
    const double vcmd = g.Kv_per_s * e + g.kff * v_ref;
    out.x_mm.push_back(x);
    double T_sum = 0.0, cmd_sum = 0.0;
    for (int q = 0; q < n; ++q) {
      const double ev = (vcmd - rg * w) / rg;
      Iv += Tv * ev;
      const double T =
          g.Kvp_torque_s_per_rad * (ev + (g.Tn_s > 0 ? Iv / g.Tn_s : 0.0)) + g.Jff_torque_s2_per_rad * a_ref / rg;
      Tf = lag * Tf + (1.0 - lag) * T;
      if (q == 0) {
        out.torque.push_back(Tf);
        out.command.push_back(T);
      }
      T_sum += Tf;
      cmd_sum += T;
      const Eigen::Vector3d s = E * Eigen::Vector3d(w, x, Tf);
      w = s(0);
      x = s(1);
    }
    out.torque_mean.push_back(T_sum / n);
    out.command_mean.push_back(cmd_sum / n);
    r_prev = rk;
    v_prev = v_ref;
  }
  return out;
}

void expect_matches_exact(const controller::CascadeGains& g, double Ts_s) {
  const sim::MachineDefinition m = cascade_x(Ts_s, g);
  const std::size_t n = static_cast<std::size_t>(0.3 / Ts_s);
  const std::vector<double> r = reference(Ts_s, n);
  const Exact ex = exact_response(m, r);
  AxisArray<std::vector<double>> ref;
  ref[index(Axis::kX)] = r;
  sim::CoSimulation cs(m, std::make_shared<sim::SampledReference>(ref, Ts_s), nullptr, {0, 0, 0});
  double worst = 0.0, e_max = 0.0, mean_apart = 0.0, T_peak = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const sim::Snapshot& s = cs.step();
    worst = std::max(worst, std::abs(s.axes[0].x_true_mm - ex.x_mm[k]));
    e_max = std::max(e_max, std::abs(r[k] - ex.x_mm[k]));
    ASSERT_NEAR(s.axes[0].Tm_Nm, ex.torque[k], 1e-9 * (1.0 + std::abs(ex.torque[k]))) << "tick " << k;
    ASSERT_NEAR(s.axes[0].Tcmd_Nm, ex.command[k], 1e-9 * (1.0 + std::abs(ex.command[k]))) << "tick " << k;
    // The means a drive that averages its trace logs at row k: over the
    // period before it (at row 0, the row's own).
    const double T_mean = k > 0 ? ex.torque_mean[k - 1] : ex.torque[0];
    const double cmd_mean = k > 0 ? ex.command_mean[k - 1] : ex.command[0];
    ASSERT_NEAR(s.axes[0].period_mean.Tm_Nm, T_mean, 1e-9 * (1.0 + std::abs(T_mean))) << "tick " << k;
    ASSERT_NEAR(s.axes[0].period_mean.Tcmd_Nm, cmd_mean, 1e-9 * (1.0 + std::abs(cmd_mean))) << "tick " << k;
    mean_apart = std::max(mean_apart, std::abs(s.axes[0].period_mean.Tm_Nm - s.axes[0].Tm_Nm));
    T_peak = std::max(T_peak, std::abs(s.axes[0].Tm_Nm));
  }
  // With one tick a period the mean is the period before's torque; with
  // several, their mean: either way not the row's own on this move.
  EXPECT_GT(mean_apart, 1e-3 * T_peak) << "the period's mean must differ from the row's torque";
  EXPECT_LT(worst, 1e-9) << "largest difference from the exact discrete response, mm";
  EXPECT_GT(e_max, 1e-4) << "the move must load the loop, or the comparison shows nothing";
}

TEST(CascadeLoop, PIVelocityLoopMatchesTheExactDiscreteResponse) {
  controller::CascadeGains g{.Kv_per_s = 60.0, .Kvp_torque_s_per_rad = 0.4, .Tn_s = 0.01};
  expect_matches_exact(g, 1e-4);
}

TEST(CascadeLoop, FeedforwardAndCurrentLagMatchTheExactDiscreteResponse) {
  controller::CascadeGains g{.Kv_per_s = 40.0, .kff = 0.9, .Kvp_torque_s_per_rad = 0.3, .Tn_s = 0.02, .tau_i_s = 5e-4,
                             .Jff_torque_s2_per_rad = 0.005};
  expect_matches_exact(g, 1e-4);
  expect_matches_exact(g, 1e-3);
}

// A velocity loop that runs 8 (4) times a position-loop period, as most
// drives run it under a 1 ms position loop: the co-simulation's drives
// advance in the velocity loop's ticks, and the exact response above steps
// the law and the plant's matrix exponential at Tv. A stiff velocity loop
// (Kvp Ts / J about 0.24 at 1 ms) makes the fast loop's response differ
// from the one-tick loop's by far more than the tolerance.
TEST(CascadeLoop, VelocityLoopFasterThanThePositionLoopMatchesTheExactDiscreteResponse) {
  controller::CascadeGains g{.Kv_per_s = 40.0, .kff = 0.6, .Kvp_torque_s_per_rad = 2.0, .Tn_s = 0.01,
                             .Tv_s = 1.25e-4};
  expect_matches_exact(g, 1e-3);
  controller::CascadeGains lagged = g;
  lagged.Tv_s = 2.5e-4;
  lagged.tau_i_s = 5e-4;
  lagged.Jff_torque_s2_per_rad = 0.004;
  expect_matches_exact(lagged, 1e-3);

  controller::CascadeGains once = g;
  once.Tv_s = 0.0;
  const std::size_t n = 300;
  const std::vector<double> r = reference(1e-3, n);
  const Exact fast = exact_response(cascade_x(1e-3, g), r), slow = exact_response(cascade_x(1e-3, once), r);
  double apart = 0.0;
  for (std::size_t k = 0; k < n; ++k) apart = std::max(apart, std::abs(fast.x_mm[k] - slow.x_mm[k]));
  EXPECT_GT(apart, 1e-4) << "the velocity loop's period must show in the motion, mm";
}

// A CNC that smooths its reference after the interpolator (a moving average,
// then a first-order lag) before the position loop: the same loop on the
// smoothed reference, which the exact response computes apart. The
// smoothing must move the motion by far more than the tolerance.
TEST(CascadeLoop, SmoothedReferenceMatchesTheExactDiscreteResponse) {
  controller::CascadeGains g{.Kv_per_s = 40.0, .kff = 0.9, .Kvp_torque_s_per_rad = 0.3, .Tn_s = 0.02, .tau_i_s = 5e-4};
  g.command_average_s = 8e-3;
  expect_matches_exact(g, 1e-3);
  g.command_lag_s = 3e-3;
  expect_matches_exact(g, 1e-3);
  g.feedforward_unsmoothed = 1.0;
  expect_matches_exact(g, 1e-3);
  g.command_average_s = 0.0;
  expect_matches_exact(g, 1e-4);
  g.feedforward_unsmoothed = 0.0;
  expect_matches_exact(g, 1e-4);
  // A dead time after the smoothing, alone and behind both.
  g.command_delay_s = 6e-3;
  expect_matches_exact(g, 1e-3);
  g.command_average_s = 4e-3;
  g.feedforward_unsmoothed = 1.0;
  expect_matches_exact(g, 1e-3);
  g.command_lag_s = 0.0;
  g.command_average_s = 0.0;
  g.feedforward_unsmoothed = 0.0;
  g.command_delay_s = 3e-4;
  expect_matches_exact(g, 1e-4);
  g.command_delay_s = 0.0;
  g.command_lag_s = 3e-3;

  controller::CascadeGains plain = g;
  plain.command_lag_s = 0.0;
  const std::vector<double> r = reference(1e-4, 3000);
  const Exact smoothed = exact_response(cascade_x(1e-4, g), r), not_smoothed = exact_response(cascade_x(1e-4, plain), r);
  double apart = 0.0;
  for (std::size_t k = 0; k < r.size(); ++k) apart = std::max(apart, std::abs(smoothed.x_mm[k] - not_smoothed.x_mm[k]));
  EXPECT_GT(apart, 0.1) << "a 3 ms lag at 100 mm/s must show in the motion, mm";
  controller::CascadeGains delayed = plain;
  delayed.command_delay_s = 3e-3;
  const Exact late = exact_response(cascade_x(1e-4, delayed), r);
  apart = 0.0;
  for (std::size_t k = 0; k < r.size(); ++k) apart = std::max(apart, std::abs(late.x_mm[k] - not_smoothed.x_mm[k]));
  EXPECT_GT(apart, 0.1) << "a 3 ms dead time at 100 mm/s must show in the motion, mm";
}

// A moving average of N periods delays a ramp by (N - 1) Ts / 2, the
// discrete lag y = a y + (1 - a) u by Ts a / (1 - a), and a dead time of D
// periods by D Ts: at constant speed the
// error against the reference given settles to v times those plus the P
// loop's (1 - kff) / Kv. A run started in that steady motion
// (start_in_steady_motion) holds it from its first tick.
TEST(CascadeLoop, ASmoothedReferenceAddsItsDelayToTheFollowingError) {
  controller::CascadeGains g{.Kv_per_s = 50.0, .kff = 0.5, .Kvp_torque_s_per_rad = 0.5, .Tn_s = 0.01};
  g.command_average_s = 5e-3;
  g.command_lag_s = 2e-3;
  g.command_delay_s = 3e-3;
  const double Ts = 1e-3, v = 100.0;
  const double a = std::exp(-Ts / g.command_lag_s);
  // The dead time of 3 periods adds v 3 Ts.
  const double e_steady = v * ((1.0 - g.kff) / g.Kv_per_s + 0.5 * (5 - 1) * Ts + Ts * a / (1.0 - a) + 3 * Ts);
  sim::MachineDefinition m = cascade_x(Ts, g);
  const std::size_t n = 2000;
  std::vector<double> r(n);
  for (std::size_t k = 0; k < n; ++k) r[k] = v * static_cast<double>(k) * Ts;
  AxisArray<std::vector<double>> ref;
  ref[index(Axis::kX)] = r;
  {
    sim::CoSimulation cs(m, std::make_shared<sim::SampledReference>(ref, Ts), nullptr, {0, 0, 0});
    sim::Snapshot last;
    for (std::size_t k = 0; k < n; ++k) last = cs.step();
    EXPECT_NEAR(last.axes[0].e_mm, e_steady, 1e-6);
    EXPECT_NEAR(last.axes[0].vcmd_mm_per_s, v, 1e-3);
  }
  sim::CoSimulation cs(m, std::make_shared<sim::SampledReference>(ref, Ts), nullptr, {0, 0, 0});
  const std::int64_t k0 = 500;
  AxisArray<std::optional<sim::ReferenceAtStart>> at;
  at[index(Axis::kX)] = sim::ReferenceAtStart{r[k0], r[k0 - 1], r[k0 - 2], v};
  sim::start_in_steady_motion(cs, at, k0);
  for (int k = 0; k < 50; ++k) {
    const sim::Snapshot& s = cs.step();
    ASSERT_NEAR(s.axes[0].e_mm, e_steady, 1e-6) << "tick " << k0 + k << " after a start in steady motion";
  }
}

TEST(CascadeLoop, AVelocityLoopPeriodThatDoesNotDivideTsIsRefused) {
  controller::CascadeGains g{.Kv_per_s = 40.0, .Kvp_torque_s_per_rad = 0.4, .Tn_s = 0.01, .Tv_s = 3e-4};
  const sim::MachineDefinition m = cascade_x(1e-3, g);
  AxisArray<std::vector<double>> ref;
  ref[index(Axis::kX)] = std::vector<double>(10, 0.0);
  try {
    sim::CoSimulation cs(m, std::make_shared<sim::SampledReference>(ref, 1e-3), nullptr, {0, 0, 0});
    FAIL() << "a Tv of 0.3 ms under a 1 ms loop was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("Tv = 0.0003 s must divide Ts = 0.001 s"), std::string::npos) << e.what();
  }
}

TEST(CascadeLoop, HoldsTheFollowingErrorOfAPLoopAtConstantSpeed) {
  // At constant speed v with an integral velocity loop, the position loop's
  // following error settles to v (1 - kff) / Kv (the P loop's steady state).
  controller::CascadeGains g{.Kv_per_s = 50.0, .kff = 0.5, .Kvp_torque_s_per_rad = 0.5, .Tn_s = 0.01};
  const double Ts = 1e-4, v = 100.0;
  sim::MachineDefinition m = cascade_x(Ts, g);
  m.axes[index(Axis::kX)].drive.Tc_pos_Nm = 0.2;  // friction: the integral must carry it
  m.axes[index(Axis::kX)].drive.Tc_neg_Nm = 0.2;
  const std::size_t n = 10000;
  std::vector<double> r(n);
  for (std::size_t k = 0; k < n; ++k) r[k] = v * static_cast<double>(k) * Ts;
  AxisArray<std::vector<double>> ref;
  ref[index(Axis::kX)] = r;
  sim::CoSimulation cs(m, std::make_shared<sim::SampledReference>(ref, Ts), nullptr, {0, 0, 0});
  sim::Snapshot last;
  for (std::size_t k = 0; k < n; ++k) last = cs.step();
  EXPECT_NEAR(last.axes[0].e_mm, v * (1.0 - g.kff) / g.Kv_per_s, 1e-6);
  EXPECT_NEAR(last.axes[0].vcmd_mm_per_s, v, 1e-3);
}

TEST(CascadeLoop, MachineFileChoosesTheLawAndRefusesTheOtherLawsGains) {
  sim::MachineDefinition m = cascade_x(1e-3, controller::CascadeGains{30.0, 0.0, 0.2, 0.01, 0.0, 5.0, 0.0});
  const std::string yaml = io::machine_to_yaml(m, "test");
  EXPECT_NE(yaml.find("controller: cascade"), std::string::npos);
  EXPECT_EQ(yaml.find("Kp:"), std::string::npos);
  EXPECT_NE(yaml.find("Kvp:"), std::string::npos);
  EXPECT_NE(yaml.find("torque_command_logged: 0"), std::string::npos);
  EXPECT_NE(yaml.find("torque_log_filter: 0"), std::string::npos);
  const auto dir = std::filesystem::temp_directory_path() / "twin_cascade_machine_test";
  std::filesystem::create_directories(dir);
  io::write_file_atomic(dir / "m.yaml", yaml);
  const sim::MachineDefinition back = io::load_machine(dir / "m.yaml");
  EXPECT_EQ(back.axes[0].loop.law, controller::LoopLaw::kCascade);
  EXPECT_DOUBLE_EQ(back.axes[0].loop.cascade.Kv_per_s, 30.0);
  EXPECT_DOUBLE_EQ(back.axes[0].loop.cascade.T_max, 5.0);
  sim::MachineDefinition s = back;
  EXPECT_THROW(sim::apply_set(s, "x.Kp=100"), ConfigError);
  EXPECT_NO_THROW(sim::apply_set(s, "x.Kv=45"));
  EXPECT_NO_THROW(sim::apply_set(s, "x.torque_command_logged=1"));
  EXPECT_DOUBLE_EQ(s.axes[0].torque_command_logged, 1.0);
  EXPECT_NO_THROW(s.validate());
  sim::apply_set(s, "x.torque_command_logged=0.5");
  EXPECT_THROW(s.validate(), ConfigError);
  sim::apply_set(s, "x.torque_command_logged=0");
  EXPECT_NO_THROW(sim::apply_set(s, "x.torque_log_filter=0.002"));
  EXPECT_DOUBLE_EQ(s.axes[0].logged_torque_filter_s, 0.002);
  EXPECT_NO_THROW(s.validate());
  sim::apply_set(s, "x.torque_log_filter=-0.001");
  EXPECT_THROW(s.validate(), ConfigError);
  sim::apply_set(s, "x.torque_log_filter=0");
  EXPECT_NE(yaml.find("torque_log_mean: 0"), std::string::npos);
  EXPECT_NO_THROW(sim::apply_set(s, "x.torque_log_mean=1"));
  EXPECT_DOUBLE_EQ(s.axes[0].logged_torque_period_mean, 1.0);
  EXPECT_NO_THROW(s.validate());
  sim::apply_set(s, "x.torque_log_mean=0.5");
  EXPECT_THROW(s.validate(), ConfigError);
  io::write_file_atomic(dir / "bad.yaml", yaml + "    Kd: 0.1\n");
  EXPECT_THROW(io::load_machine(dir / "bad.yaml"), ConfigError);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace twin
