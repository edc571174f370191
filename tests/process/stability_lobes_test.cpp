// Zero-order stability lobes (process/stability_lobes.*) against
//  - the closed-form directional coefficients of a slot (Altintas,
//    Manufacturing Automation, ch. 4.4: alpha_xx = alpha_yy = -pi Kr,
//    alpha_xy = -pi, alpha_yx = pi);
//  - the single-degree-of-freedom solution, written here from the turning
//    (orthogonal) chatter equation 1 + a K (1 - exp(-i w T)) G = 0: a tool
//    flexible in y only turns the milling loop into it with the oriented
//    coefficient K = N Ks, Ks = -Ktc alpha_yy / (4 pi), so
//      a_lim(w) = -1 / (2 Ks N Re G(w)),  w T = 2 arg G + 3 pi + 2 k pi,
//    and its minimum over w is a_lim = -1 / (2 Ks N Re[G]min) with the exact
//    Re[G]min = -1 / (4 k zeta (1 + zeta)) at (w/wn)^2 = 1 + 2 zeta;
//  - a time-domain regenerative simulation written here (two modes, discrete
//    teeth, the chip from the present and the previous tooth's vibration, a
//    tooth that leaves the cut cuts nothing), which knows nothing of the
//    averaged theory.
#include <gtest/gtest.h>

#include <cmath>
#include <deque>
#include <numbers>
#include <vector>

#include "process/stability_lobes.hpp"
#include "twin/core/error.hpp"

namespace twin::process {
namespace {

constexpr double kPi = std::numbers::pi;

TEST(StabilityLobes, SlotDirectionalCoefficientsAreTheClosedForm) {
  const double Kr = 0.3;
  const Immersion slot = Immersion::of_cut(10.0, 10.0, MillingMode::kUp, "slot");
  EXPECT_DOUBLE_EQ(slot.phi_st_rad, 0.0);
  EXPECT_NEAR(slot.phi_ex_rad, kPi, 1e-12);
  const DirectionalCoefficients a = DirectionalCoefficients::of(slot, Kr);
  EXPECT_NEAR(a.xx, -kPi * Kr, 1e-12);
  EXPECT_NEAR(a.yy, -kPi * Kr, 1e-12);
  EXPECT_NEAR(a.xy, -kPi, 1e-12);
  EXPECT_NEAR(a.yx, kPi, 1e-12);
  // Half immersion: up milling 0..pi/2, down milling pi/2..pi.
  const Immersion up = Immersion::of_cut(5.0, 10.0, MillingMode::kUp, "up");
  const Immersion down = Immersion::of_cut(5.0, 10.0, MillingMode::kDown, "down");
  EXPECT_NEAR(up.phi_ex_rad, 0.5 * kPi, 1e-12);
  EXPECT_NEAR(down.phi_st_rad, 0.5 * kPi, 1e-12);
  EXPECT_THROW(Immersion::of_cut(12.0, 10.0, MillingMode::kUp, "too wide"), ConfigError);
}

struct SdofCase {
  ToolTipMode mode{600.0, 0.03, 5.0e6};
  LobeSettings settings;
  SdofCase() {
    settings.teeth = 4;
    settings.Ktc_N_per_mm2 = 700.0;
    settings.Kr_ratio = 0.3;
    settings.immersion = Immersion::of_cut(10.0, 10.0, MillingMode::kUp, "slot");
    settings.frequencies = 4000;
  }
  double Ks() const {
    const DirectionalCoefficients a = DirectionalCoefficients::of(settings.immersion, settings.Kr_ratio);
    return -settings.Ktc_N_per_mm2 * a.yy / (4.0 * kPi);
  }
};

TEST(StabilityLobes, SingleModeMatchesTheOrthogonalChatterSolution) {
  SdofCase c;
  ToolTipFrf frf;
  frf.y = {c.mode};
  const StabilityLobes lobes = zero_order_lobes(frf, c.settings);
  const double N = c.settings.teeth;
  int checked = 0;
  for (const Lobe& lobe : lobes.lobes) {
    for (const LobePoint& p : lobe.points) {
      const double w = 2 * kPi * p.chatter_Hz;
      const std::complex<double> G = ToolTipFrf::direct_mm_per_N(frf.y, w);
      // Depth: closed form, to round-off (both are the same number reached two ways).
      const double a_expected = -1.0 / (2.0 * c.Ks() * N * G.real());
      ASSERT_NEAR(p.a_lim_mm, a_expected, 1e-9 * a_expected);
      // Speed: w T = 2 arg G + 3 pi + 2 k pi (arg G in (-pi, -pi/2) where a_lim > 0).
      const double T = (2.0 * std::arg(G) + 3.0 * kPi + 2.0 * kPi * lobe.number) / w;
      ASSERT_NEAR(p.spindle_rpm, 60.0 / (N * T), 1e-9 * p.spindle_rpm);
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
  // The minimum: -1 / (2 Ks N Re[G]min), Re[G]min exact; within 1 % (the scan's
  // frequency grid is 4000 log-spaced points over two octaves, so the sampled
  // minimum sits within 1e-5 of the true one).
  const double ReGmin_mm_per_N = -1e3 / (4.0 * c.mode.k_N_per_m * c.mode.zeta * (1.0 + c.mode.zeta));
  const double a_min = -1.0 / (2.0 * c.Ks() * N * ReGmin_mm_per_N);
  EXPECT_NEAR(lobes.a_lim_min_mm, a_min, 0.01 * a_min);
  EXPECT_NEAR(lobes.a_lim_min_chatter_Hz, c.mode.fn_Hz * std::sqrt(1.0 + 2.0 * c.mode.zeta), 0.01 * c.mode.fn_Hz);
}

TEST(StabilityLobes, FeedAlongYSeesTheXModeAsTheFeedNormalOne) {
  // A tool flexible in x only, feeding along +y: the feed frame's y_f is the
  // machine's -x, so the mode is feed-normal and the lobes equal those of a y
  // mode feeding along +x.
  SdofCase c;
  ToolTipFrf fy, fx;
  fy.y = {c.mode};
  fx.x = {c.mode};
  LobeSettings along_y = c.settings;
  along_y.feed_angle_deg = 90.0;
  const StabilityLobes a = zero_order_lobes(fy, c.settings);
  const StabilityLobes b = zero_order_lobes(fx, along_y);
  EXPECT_NEAR(a.a_lim_min_mm, b.a_lim_min_mm, 1e-9 * a.a_lim_min_mm);
  for (double n : {3000.0, 6000.0, 9000.0, 12000.0})
    EXPECT_NEAR(a.critical_depth_mm(n), b.critical_depth_mm(n), 1e-6 * a.critical_depth_mm(n)) << n;
}

// Time-domain regenerative milling of a tool with one mode per direction
// (semi-implicit Euler at 256 steps per tooth period, the delay an exact number
// of steps). Returns the spread of the once-per-tooth samples of y over the
// last 40 of 400 tooth periods divided by their mean (the static deflection).
// A stable cut settles to a tooth-periodic forced response, so its
// once-per-tooth samples converge (ratio below 1e-6 here); chatter grows to a
// limit cycle bounded by teeth leaving the cut (ratio of order one or more).
double regenerative_growth(const ToolTipFrf& frf, const LobeSettings& s, double rpm, double a_mm, double ft_mm) {
  const int N = s.teeth;
  const int steps_per_tooth = 256;
  const double T = 60.0 / (rpm * N);
  const double dt = T / steps_per_tooth;
  const double w_spin = 2 * kPi * rpm / 60.0;
  auto modal = [](const ToolTipMode& m) {
    const double wn = 2 * kPi * m.fn_Hz;
    const double mass = m.k_N_per_m / (wn * wn);
    return std::array<double, 3>{mass, 2 * m.zeta * wn * mass, m.k_N_per_m};
  };
  const auto mx = modal(frf.x.front()), my = modal(frf.y.front());
  double x = 1e-6, vx = 0, y = 1e-6, vy = 0;  // m; a small kick
  std::deque<std::array<double, 2>> hist(static_cast<std::size_t>(steps_per_tooth), {0.0, 0.0});
  const int periods = 400;
  std::vector<double> samples;
  for (int n = 0; n < periods * steps_per_tooth; ++n) {
    const double t = n * dt;
    const auto [x0, y0] = hist.front();
    double Fx = 0, Fy = 0;
    for (int j = 0; j < N; ++j) {
      double phi = std::fmod(w_spin * t + j * 2 * kPi / N, 2 * kPi);
      if (phi < s.immersion.phi_st_rad || phi > s.immersion.phi_ex_rad) continue;
      const double h = ft_mm * std::sin(phi) + 1e3 * ((x - x0) * std::sin(phi) + (y - y0) * std::cos(phi));
      if (h <= 0) continue;
      const double Ft = s.Ktc_N_per_mm2 * a_mm * h, Fr = s.Kr_ratio * Ft;
      Fx += -Ft * std::cos(phi) - Fr * std::sin(phi);
      Fy += Ft * std::sin(phi) - Fr * std::cos(phi);
    }
    vx += dt * (Fx - mx[1] * vx - mx[2] * x) / mx[0];
    vy += dt * (Fy - my[1] * vy - my[2] * y) / my[0];
    x += dt * vx;
    y += dt * vy;
    hist.pop_front();
    hist.push_back({x, y});
    if ((n + 1) % steps_per_tooth == 0) samples.push_back(y);
  }
  auto spread = [&](std::size_t from, std::size_t to) {
    double lo = 1e9, hi = -1e9;
    for (std::size_t i = from; i < to; ++i) lo = std::min(lo, samples[i]), hi = std::max(hi, samples[i]);
    return hi - lo;
  };
  const std::size_t n = samples.size();
  double mean = 0;
  for (std::size_t i = n - 40; i < n; ++i) mean += samples[i] / 40.0;
  return spread(n - 40, n) / std::max(std::abs(mean), 1e-15);
}

TEST(StabilityLobes, TimeDomainRegenerationAgreesWithTheLobes) {
  // Slot, 4 teeth, symmetric tool modes: the case where the zero-order
  // solution is close to the exact one (two teeth in the cut at any time). At
  // 0.9 of the lobe's depth the cut settles; at 1.1 it chatters: the lobe is
  // right to 10 % at three speeds (a lobe peak's flank, a trough, another
  // lobe). Euler at 256 steps per tooth (about 120 per mode period) adds
  // damping of order 1e-3 of the mode's, far inside that margin.
  ToolTipFrf frf;
  frf.x = {ToolTipMode{900.0, 0.04, 8.0e6}};
  frf.y = {ToolTipMode{900.0, 0.04, 8.0e6}};
  LobeSettings s;
  s.teeth = 4;
  s.Ktc_N_per_mm2 = 700.0;
  s.Kr_ratio = 0.3;
  s.immersion = Immersion::of_cut(10.0, 10.0, MillingMode::kUp, "slot");
  const StabilityLobes lobes = zero_order_lobes(frf, s);
  for (double rpm : {7000.0, 9500.0, 13000.0}) {
    const double a = lobes.critical_depth_mm(rpm);
    ASSERT_TRUE(std::isfinite(a)) << rpm;
    EXPECT_LT(regenerative_growth(frf, s, rpm, 0.9 * a, 0.05), 1e-3) << rpm << " rpm, a_lim " << a;
    EXPECT_GT(regenerative_growth(frf, s, rpm, 1.1 * a, 0.05), 0.1) << rpm << " rpm, a_lim " << a;
  }
}

TEST(StabilityLobes, BadInputIsRefused) {
  ToolTipFrf frf;
  LobeSettings s;
  s.Ktc_N_per_mm2 = 700.0;
  s.immersion = Immersion::of_cut(5.0, 10.0, MillingMode::kDown, "cut");
  EXPECT_THROW(zero_order_lobes(frf, s), ConfigError);  // no mode
  frf.y = {ToolTipMode{600.0, 1.5, 1e6}};
  EXPECT_THROW(zero_order_lobes(frf, s), ConfigError);  // zeta >= 1
  frf.y = {ToolTipMode{600.0, 0.03, 1e6}};
  s.teeth = 0;
  EXPECT_THROW(zero_order_lobes(frf, s), ConfigError);
}

}  // namespace
}  // namespace twin::process
