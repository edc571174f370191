// The FADAL position-loop law of spec/measured-data.md, evaluated here term
// by term from the specification's equations, against PositionLoop. The
// same arithmetic in the same order: equality to a few ulps.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "controller/encoder.hpp"
#include "controller/position_loop.hpp"
#include "twin/core/error.hpp"

namespace twin {
namespace {

constexpr double kTs_s = 1e-4;

controller::PositionLoopParams fadal_x() {
  controller::PositionLoopParams p;
  p.Kp_V_per_mm = 500;
  p.Ki_V_per_s_mm = 70;
  p.Kd_V_s_per_mm = 0.3;
  p.K1_V_s2_per_mm = 1e-4;
  p.K2_V_s_per_mm = 0.01;
  p.u_max_V = 10;
  return p;
}

TEST(PositionLoop, FollowsTheSpecifiedLaw) {
  const auto p = fadal_x();
  controller::PositionLoop loop(p, kTs_s);
  std::vector<double> ref, meas;
  for (int k = 0; k < 200; ++k) {
    ref.push_back(0.5 * std::sin(0.03 * k) + 1e-3 * k);
    meas.push_back(ref.back() - 2e-4 * std::cos(0.05 * k));
  }
  double I = 0.0, e_prev = ref[0] - meas[0], r_prev = ref[0], v_prev = 0.0;
  for (int k = 0; k < 200; ++k) {
    const double e = ref[k] - meas[k];
    const double v = (ref[k] - r_prev) / kTs_s;
    const double a = (v - v_prev) / kTs_s;
    I += kTs_s * e;
    double u = p.Kp_V_per_mm * e + p.Ki_V_per_s_mm * I + p.Kd_V_s_per_mm * (e - e_prev) / kTs_s +
               p.K1_V_s2_per_mm * a + p.K2_V_s_per_mm * v;
    u = std::fmax(-10.0, std::fmin(10.0, u));
    const auto out = loop.step(k, ref[k], meas[k]);
    EXPECT_NEAR(out.u_V, u, 1e-12 * std::max(1.0, std::abs(u))) << "tick " << k;
    e_prev = e;
    r_prev = ref[k];
    v_prev = v;
  }
}

TEST(PositionLoop, ClampsAndReportsSaturation) {
  controller::PositionLoop loop(fadal_x(), kTs_s);
  loop.step(0, 0.0, 0.0);
  const auto out = loop.step(1, 1.0, 0.0);  // 1 mm step: Kd term alone is 3000 V
  EXPECT_EQ(out.u_V, 10.0);
  EXPECT_TRUE(out.saturated);
  EXPECT_GT(out.u_unclamped_V, 10.0);
}

TEST(PositionLoop, RefusesOutOfOrderTicks) {
  controller::PositionLoop loop(fadal_x(), kTs_s);
  loop.step(5, 0.0, 0.0);
  EXPECT_THROW(loop.step(7, 0.0, 0.0), InternalError);
  EXPECT_THROW(loop.step(5, 0.0, 0.0), InternalError);
}

TEST(PositionLoop, RejectsBadGains) {
  auto p = fadal_x();
  p.Kp_V_per_mm = std::nan("");
  EXPECT_THROW((controller::PositionLoop{p, kTs_s}), ConfigError);
  p = fadal_x();
  EXPECT_THROW((controller::PositionLoop{p, 0.0}), ConfigError);
}

TEST(Encoder, QuantisesToTheNearestCount) {
  const controller::Encoder enc{0.001};
  EXPECT_DOUBLE_EQ(enc.measure_mm(0.0014), 0.001);
  EXPECT_DOUBLE_EQ(enc.measure_mm(0.0016), 0.002);
  EXPECT_DOUBLE_EQ(enc.measure_mm(-0.0016), -0.002);
  EXPECT_DOUBLE_EQ(controller::Encoder{0.0}.measure_mm(0.12345), 0.12345);
}

}  // namespace
}  // namespace twin
