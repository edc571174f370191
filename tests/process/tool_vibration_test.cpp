#include "process/tool_vibration.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>
#include <numbers>

#include "process/chatter_spectrum.hpp"
#include "process/milling_process.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

constexpr double kPi = std::numbers::pi;

// A step force on one mode against the closed-form step response of a damped
// oscillator, x(t) = F/k (1 - e^(-s t) (cos wd t + s/wd sin wd t)). The
// zero-order-hold discretisation is exact for a force held over each step,
// so after 300 steps (several periods) only rounding remains: 1e-12 of F/k.
TEST(ToolVibration, StepForceMatchesTheClosedFormStepResponse) {
  ToolTipFrf frf;
  frf.x = {ToolTipMode{2100.0, 0.03, 1.2e7}};
  frf.y = {ToolTipMode{900.0, 0.2, 5.0e6}};
  ToolVibration v(frf);
  const double F = 150.0;
  const double dt = 3.7e-5;
  for (int n = 1; n <= 300; ++n) {
    v.advance((n - 1) * dt, dt, {F, -F}, 1.0);
    const double t = n * dt;
    for (int d = 0; d < 2; ++d) {
      const ToolTipMode& m = d == 0 ? frf.x[0] : frf.y[0];
      const double wn = 2 * kPi * m.fn_Hz, s = m.zeta * wn, wd = wn * std::sqrt(1 - m.zeta * m.zeta);
      const double x_mm = (d == 0 ? F : -F) / m.k_N_per_m * 1e3 *
                          (1 - std::exp(-s * t) * (std::cos(wd * t) + s / wd * std::sin(wd * t)));
      ASSERT_NEAR(v.deflection_mm()[static_cast<std::size_t>(d)], x_mm, 1e-12 * F / m.k_N_per_m * 1e3) << n;
    }
  }
}

// A single mode's frequency response from the model against the modal
// formula H(w) = 1 / (k (1 - r^2 + 2 i zeta r)), r = w / wn (Altintas,
// Manufacturing Automation, ch. 3), at r = 0.5, 1 and 1.5: the time-domain
// model (exact zero-order hold) driven by a sinusoid sampled at the middle of
// steps of 1/2000 of its period and held over each, after 12 time constants
// 1/(zeta wn) of transient (e^-12, 6e-6, left), amplitude and phase by
// correlation over 10 whole periods. A held midpoint sample carries the
// sinusoid's first harmonic with an amplitude error of (w dt)^2 / 24, 4e-7,
// and no delay: so 2e-5 in amplitude and 1e-3 deg in phase (measured: under
// 2e-6 and 3e-5 deg). The lobes' own FRF (ToolTipFrf::direct_mm_per_N) is
// the formula itself: to 1e-12.
TEST(ToolVibration, SingleModeFrequencyResponseIsTheModalFormula) {
  const ToolTipMode mode{1000.0, 0.05, 1.0e7};
  ToolTipFrf frf;
  frf.x = {mode};
  const double wn = 2 * kPi * mode.fn_Hz;
  for (double r : {0.5, 1.0, 1.5}) {
    const double w = r * wn, period = 2 * kPi / w, dt = period / 2000.0;
    const std::complex<double> H_m_per_N = 1.0 / (mode.k_N_per_m * std::complex<double>(1 - r * r, 2 * mode.zeta * r));
    const std::complex<double> H_lobes = ToolTipFrf::direct_mm_per_N(frf.x, w) * 1e-3;
    EXPECT_NEAR(std::abs(H_lobes - H_m_per_N), 0.0, 1e-12 * std::abs(H_m_per_N)) << r;
    ToolVibration v(frf);
    const double F = 100.0;
    const auto settle = static_cast<long>(std::ceil(12.0 / (mode.zeta * wn) / period)) * 2000;
    double c = 0.0, s = 0.0;
    const long measure = 10 * 2000;
    for (long n = 0; n < settle + measure; ++n) {
      const double t_mid = (static_cast<double>(n) + 0.5) * dt;
      v.advance(static_cast<double>(n) * dt, dt, {F * std::cos(w * t_mid), 0.0}, dt);
      if (n < settle) continue;
      const double t = static_cast<double>(n + 1) * dt;
      c += v.deflection_mm()[0] * std::cos(w * t);
      s += v.deflection_mm()[0] * std::sin(w * t);
    }
    // x(t) = |H| F cos(w t + phase): c = N/2 |H| F cos(phase), s = -N/2 |H| F sin(phase).
    const std::complex<double> X_mm(2.0 * c / measure, -2.0 * s / measure);
    const std::complex<double> H_model_m_per_N = X_mm / F * 1e-3;
    EXPECT_NEAR(std::abs(H_model_m_per_N) / std::abs(H_m_per_N), 1.0, 2e-5) << "r = " << r;
    EXPECT_NEAR(std::arg(H_model_m_per_N / H_m_per_N) * 180.0 / kPi, 0.0, 1e-3) << "r = " << r;
  }
}

// Two modes in one direction add (the FRF is their sum): the static
// deflection under a long-held force is F (1/k1 + 1/k2), to 1e-9 after 200
// periods of the slower mode at 5 % damping (e^-63 of the transient left).
TEST(ToolVibration, ModesInOneDirectionAdd) {
  ToolTipFrf frf;
  frf.y = {ToolTipMode{500.0, 0.05, 4.0e6}, ToolTipMode{3000.0, 0.05, 2.0e7}};
  ToolVibration v(frf);
  const double dt = 2e-5;
  for (int n = 0; n < 20000; ++n) v.advance(n * dt, dt, {0.0, 80.0}, 1e-3);
  EXPECT_NEAR(v.deflection_mm()[1], 80.0 * (1 / 4.0e6 + 1 / 2.0e7) * 1e3, 1e-9);
  EXPECT_EQ(v.deflection_mm()[0], 0.0);
}

// The recorded deflection: linear between the recorded points, zero before
// the first (the tool at rest), the latest after the last; points older than
// the kept span are forgotten. The predicted state equals the advanced one.
TEST(ToolVibration, HistoryInterpolatesAndForgets) {
  ToolTipFrf frf;
  frf.x = {ToolTipMode{1000.0, 0.05, 1.0e7}};
  ToolVibration v(frf);
  const double dt = 1e-4;
  std::vector<double> u{0.0};
  for (int n = 0; n < 50; ++n) {
    const auto pred = v.predict_mm(dt, {100.0, 0.0});
    v.advance(n * dt, dt, {100.0, 0.0}, 2e-3);
    EXPECT_EQ(pred[0], v.deflection_mm()[0]);
    u.push_back(v.deflection_mm()[0]);
  }
  EXPECT_NEAR(v.deflection_at_mm(45.25 * dt)[0], 0.75 * u[45] + 0.25 * u[46], 1e-15);
  EXPECT_EQ(v.deflection_at_mm(60 * dt)[0], u[50]);
  EXPECT_EQ(v.deflection_at_mm(-1.0)[0], 0.0);   // before anything was recorded: at rest
  EXPECT_EQ(v.deflection_at_mm(10 * dt)[0], 0.0);   // forgotten (older than 2 ms before t = 5 ms)
}

// Surface location error in a slot, quasi-static: four straight flutes,
// linear coefficients, no edge force, feed +x, depth 0.2 mm (below the
// lobes' minimum, about 0.5 mm for these modes: at 1 mm the slot chatters).
// When a flute passes a wall (phi = 0, normal +y, or phi = 180 deg, normal
// -y), the flute 90 deg behind it has chip fz and the other two cut nothing,
// so the force on the tool is Fy = Ktc a fz and the tool stands at Fy / k_y:
// |SLE| = Ktc a fz / k_y (into the +y wall, away from the -y wall). At 600 rpm the
// tooth frequency (40 Hz) is 1/22 of the 900 Hz mode: the dynamic part of the
// response is of order (40/900)^2 = 0.2 % plus the ring-down of the force's
// harmonics; the force is sampled at 1.5 deg (flute 1 within 0.75 deg of 90
// deg: cos 0.75 deg = 0.99991). Tolerance 2 %.
TEST(ToolVibration, SlotSurfaceLocationErrorIsTheStaticDeflectionAtTheWall) {
  ProcessSetup setup;
  setup.tool.diameter_mm = 10.0;
  setup.tool.flutes = 4;
  setup.tool.helix_deg = 0.0;
  setup.tool.flute_length_mm = 20.0;
  const double Ktc = 700.0, a = 0.2, fz = 0.05, ky = 8.0e6;
  setup.coefficients = CuttingCoefficients::linear(Ktc, 210.0, 0.0, 0.0, 0.0, 0.0);
  setup.stock.outline_mm = StockSpec::rectangle(-20.0, -7.0, 60.0, 7.0);
  setup.stock.top_z_mm = 0.0;
  setup.stock.bottom_z_mm = -5.0;
  setup.stock.cell_mm = 0.05;
  setup.options.dz_mm = 0.1;
  setup.tool_tip.x = {ToolTipMode{900.0, 0.05, 8.0e6}};
  setup.tool_tip.y = {ToolTipMode{900.0, 0.05, ky}};
  MillingProcess p(setup);
  p.remove_swept({-30.0, 0.0, -a}, {0.0, 0.0, -a});
  const double rpm = 600.0, v = fz * 4 * rpm / 60.0, Ts = 1e-4;
  ProcessOutput out;
  for (int k = 0; k < 4000; ++k) {
    ProcessInput in;
    in.k = k;
    in.t_s = k * Ts;
    in.Ts_s = Ts;
    in.p_mm = {v * k * Ts, 0.0, -a};
    in.v_mm_per_s = {v, 0.0, 0.0};
    in.spindle_rpm = rpm;
    out = p.step(in);
  }
  ASSERT_TRUE(out.tool_modes);
  EXPECT_NEAR(std::abs(out.sle_mm), Ktc * a * fz / ky * 1e3, 0.02 * Ktc * a * fz / ky * 1e3);
}

// The spectrum ratio on a synthetic force: a mean of 100 N in x, a tooth
// harmonic of 30 N at 400 Hz in y and a 2 N line at 1030 Hz in x, 0.1 s at
// 10 kHz (both frequencies on the 10 Hz grid). With a Hann window a line of
// amplitude A on the grid reads A n / 4 and the mean M reads M n / 2, so
// r = (2 n / 4) / (100 n / 2) = 0.01 exactly (to rounding), at 1030 Hz; the
// harmonic at 400 Hz (and the mean) are not counted as non-harmonic.
TEST(ChatterSpectrum, RatioOfALineToTheMeanUnderAHannWindow) {
  const double Ts = 1e-4;
  std::vector<std::array<double, 2>> F;
  for (int i = 0; i < 1000; ++i) {
    const double t = i * Ts;
    F.push_back({100.0 + 2.0 * std::cos(2 * kPi * 1030.0 * t + 0.3), 30.0 * std::sin(2 * kPi * 400.0 * t)});
  }
  const ChatterSpectrum s = chatter_spectrum(F, 0, F.size(), Ts, 400.0, 300.0, 3000.0);
  EXPECT_NEAR(s.ratio, 0.01, 1e-9);
  EXPECT_EQ(s.chatter_Hz, 1030.0);
  EXPECT_TRUE(chatter_verdict(0.01, 0.06));    // a limit cycle
  EXPECT_TRUE(chatter_verdict(0.004, 0.005));  // growing above the floor
  EXPECT_FALSE(chatter_verdict(0.005, 0.004)); // ringing down
  EXPECT_FALSE(chatter_verdict(0.001, 0.0019)); // growing within the floor
}

TEST(ToolVibration, BadModesAreRefused) {
  ToolTipFrf frf;
  frf.x = {ToolTipMode{1000.0, 0.0, 1.0e7}};
  EXPECT_THROW(ToolVibration{frf}, ConfigError);
}

}  // namespace
}  // namespace twin::process
