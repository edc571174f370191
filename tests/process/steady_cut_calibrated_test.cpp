// `twin cut` reproducing a calibrated cut: a wear state (a factor on every
// coefficient) and a sensor mode in the force output.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "process/steady_cut.hpp"
#include "process_test_util.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

SteadyCutSpec slot() {
  return {.tool = testing::flat_tool(10.0, 2, 30.0),
          .coefficients = CuttingCoefficients::linear(850.0, 280.0, 120.0, 22.0, 28.0, 4.0),
          .spindle_rpm = 6000.0,
          .feed_per_tooth_mm = 0.05,
          .ae_mm = 10.0,
          .ap_mm = 2.0,
          .angle_step_deg = 1.0,
          .dz_mm = 0.05};
}

// The force is linear in the coefficients (dF = (K h + Ke) db): a factor on
// all of them scales every sample by it (1e-9 relative).
TEST(SteadyCutCalibrated, WearScaleScalesTheForce) {
  SteadyCutSpec s = slot();
  const SteadyCutResult r0 = run_steady_cut(s);
  s.coefficient_scale = 1.2;
  const SteadyCutResult r1 = run_steady_cut(s);
  ASSERT_EQ(r0.rows.size(), r1.rows.size());
  for (std::size_t k = 0; k < r0.rows.size(); ++k)
    for (std::size_t a = 0; a < 3; ++a)
      EXPECT_NEAR(r1.rows[k].F_N[a], 1.2 * r0.rows[k].F_N[a], 1e-9 * (1.0 + std::abs(r0.rows[k].F_N[a])));
}

// Oracle: the sensor ODE x'' + 2 zeta wn x' + wn^2 x = wn^2 F integrated by
// RK4 at 1/20 of the angle step over 30 revolutions of the rigid force
// (linear between the samples), its last revolution against the steady
// response `twin cut` gives per harmonic. Tolerance 1 % of the peak-to-peak:
// linear interpolation against the trigonometric one, at a 1 deg step. The
// mean is unchanged (unit DC gain; 1e-9).
TEST(SteadyCutCalibrated, SensorModeIsTheSteadyResponseOfTheOde) {
  SteadyCutSpec s = slot();
  const SteadyCutResult rigid = run_steady_cut(s);
  s.sensor_f_hz = 1150.0;
  s.sensor_zeta = 0.03;
  const SteadyCutResult moded = run_steady_cut(s);
  const std::size_t M = rigid.rows.size();
  const double T_rev = 60.0 / s.spindle_rpm;
  const double wn = 2 * std::numbers::pi * 1150.0;
  const int sub = 20;
  const double dt = T_rev / M / sub;
  for (std::size_t a = 0; a < 3; ++a) {
    EXPECT_NEAR(moded.mean_F_N[a], rigid.mean_F_N[a], 1e-9 * (1.0 + std::abs(rigid.mean_F_N[a])));
    double x = rigid.rows[0].F_N[a], v = 0.0;
    std::vector<double> last(M);
    double lo = 1e300, hi = -1e300;
    for (int rev = 0; rev < 30; ++rev)
      for (std::size_t m = 0; m < M; ++m) {
        if (rev == 29) last[m] = x;
        const double f0 = rigid.rows[m].F_N[a], f1 = rigid.rows[(m + 1) % M].F_N[a];
        for (int q = 0; q < sub; ++q) {
          auto F = [&](double u) { return f0 + (f1 - f0) * u; };
          auto acc = [&](double xx, double vv, double u) { return wn * wn * (F(u) - xx) - 2 * 0.03 * wn * vv; };
          const double u0 = double(q) / sub, uh = (q + 0.5) / sub, u1 = (q + 1.0) / sub;
          const double k1x = v, k1v = acc(x, v, u0);
          const double k2x = v + 0.5 * dt * k1v, k2v = acc(x + 0.5 * dt * k1x, v + 0.5 * dt * k1v, uh);
          const double k3x = v + 0.5 * dt * k2v, k3v = acc(x + 0.5 * dt * k2x, v + 0.5 * dt * k2v, uh);
          const double k4x = v + dt * k3v, k4v = acc(x + dt * k3x, v + dt * k3v, u1);
          x += dt / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
          v += dt / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
        }
      }
    for (double y : last) {
      lo = std::min(lo, y);
      hi = std::max(hi, y);
    }
    for (std::size_t m = 0; m < M; ++m)
      EXPECT_NEAR(moded.rows[m].F_N[a], last[m], 0.01 * (hi - lo)) << "axis " << a << " sample " << m;
  }
}

TEST(SteadyCutCalibrated, BadOptionsAreErrors) {
  SteadyCutSpec s = slot();
  s.coefficient_scale = 0.0;
  EXPECT_THROW(run_steady_cut(s), ConfigError);
  s = slot();
  s.sensor_f_hz = 1000.0;
  s.sensor_zeta = 0.0;
  EXPECT_THROW(run_steady_cut(s), ConfigError);
}

}  // namespace
}  // namespace twin::process
