// Tests of the CNC interpolator. Oracles: closed-form jerk-limited (S-curve)
// profile times, the documented blend formula of docs/interpolator.md, the
// public corner formulas of design.md (grbl, LinuxCNC), the programmed
// geometry, and finite differences of the sampled reference checked against
// the per-axis limits.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "controller/interpolator.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::controller {
namespace {

constexpr double kTs_s = 1e-4;
constexpr double kA = 2000.0;    // mm/s^2, FADAL interpolator acceleration
constexpr double kJ = 50000.0;   // mm/s^3, FADAL interpolator jerk
constexpr double kRapid_mm_per_min = 10160.0;

MotionLimits fadal_limits(double j = kJ) {
  MotionLimits m;
  m.v_max_mm_per_s = {kRapid_mm_per_min / 60.0, kRapid_mm_per_min / 60.0, kRapid_mm_per_min / 60.0};
  m.a_max_mm_per_s2 = {kA, kA, kA};
  m.j_max_mm_per_s3 = {j, j, j};
  m.default_blend_tolerance_mm = 0.01;
  return m;
}

Trajectory plan(const std::string& text, const MotionLimits& lim = fadal_limits()) {
  return plan_trajectory(parse_gcode(text, "test.nc", {0, 0, 0}, kRapid_mm_per_min), lim, kTs_s);
}

std::vector<AxisArray<double>> sample_all(const Trajectory& t) {
  std::vector<AxisArray<double>> x;
  const std::int64_t n = t.num_ticks();
  x.reserve(static_cast<std::size_t>(n + 4));
  for (std::int64_t k = 0; k <= n + 3; ++k) x.push_back(t.sample(k).x_mm);
  return x;
}

/// Rest-to-rest time of a jerk-limited move of length L with cruise limit v,
/// written from the textbook S-curve: a ramp 0 -> vp takes Tr = vp/a + a/j
/// (or 2 sqrt(vp/j) when vp <= a^2/j) and covers vp Tr / 2.
double scurve_time(double L, double v, double a, double j) {
  auto Tr = [&](double vp) { return vp * j <= a * a ? 2.0 * std::sqrt(vp / j) : vp / a + a / j; };
  if (L >= v * Tr(v)) return L / v + Tr(v);
  // Peak below v: L = vp Tr(vp), solved in closed form in each regime.
  double vp = std::pow(L * std::sqrt(j) / 2.0, 2.0 / 3.0);
  if (vp * j > a * a) vp = 0.5 * a * (-a / j + std::sqrt(a * a / (j * j) + 4.0 * L / a));
  return 2.0 * Tr(vp);
}

struct LimitCheck {
  double max_v_ratio{0.0}, max_a_ratio{0.0}, max_j_ratio{0.0};
};

/// Largest |v|, |a|, |j| per axis from first, second and third differences,
/// as a fraction of the limit. A k-th difference divided by Ts^k is a
/// weighted mean of the k-th derivative over the stencil (B-spline kernel),
/// so it never exceeds the true maximum; rounding of positions (~1e-13 mm)
/// adds at most 8e-13/Ts^3 ~ 1 mm/s^3 to the jerk.
LimitCheck check_limits(const std::vector<AxisArray<double>>& x, const MotionLimits& lim) {
  LimitCheck r;
  for (std::size_t k = 0; k + 3 < x.size(); ++k) {
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      const double v = (x[k + 1][a] - x[k][a]) / kTs_s;
      const double acc = (x[k + 2][a] - 2 * x[k + 1][a] + x[k][a]) / (kTs_s * kTs_s);
      const double jerk = (x[k + 3][a] - 3 * x[k + 2][a] + 3 * x[k + 1][a] - x[k][a]) / (kTs_s * kTs_s * kTs_s);
      r.max_v_ratio = std::max(r.max_v_ratio, std::abs(v) / lim.v_max_mm_per_s[a]);
      r.max_a_ratio = std::max(r.max_a_ratio, std::abs(acc) / lim.a_max_mm_per_s2[a]);
      r.max_j_ratio = std::max(r.max_j_ratio, std::abs(jerk) / lim.j_max_mm_per_s3[a]);
    }
  }
  return r;
}

double dist_point_segment(const AxisArray<double>& p, const AxisArray<double>& a, const AxisArray<double>& b) {
  double ab2 = 0, t = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    ab2 += (b[i] - a[i]) * (b[i] - a[i]);
    t += (p[i] - a[i]) * (b[i] - a[i]);
  }
  t = ab2 > 0 ? std::clamp(t / ab2, 0.0, 1.0) : 0.0;
  double d2 = 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const double q = a[i] + t * (b[i] - a[i]) - p[i];
    d2 += q * q;
  }
  return std::sqrt(d2);
}

/// Largest distance of the samples from the programmed polyline (lines only).
double max_path_deviation(const std::vector<AxisArray<double>>& x, const Program& p) {
  double worst = 0.0;
  for (const auto& pt : x) {
    double best = 1e300;
    for (const Block& b : p.blocks) best = std::min(best, dist_point_segment(pt, b.start_mm, b.end_mm));
    worst = std::max(worst, best);
  }
  return worst;
}

struct LimitCase {
  const char* name;
  const char* program;
  double tolerance_mm;  // > 0: check the deviation from the programmed lines
};

class InterpolatorLimits : public ::testing::TestWithParam<LimitCase> {};

// Oracle: the per-axis limits themselves, on finite differences of every
// tick (see check_limits for why no slack beyond 1e-6 relative is needed);
// the end point must equal the programmed end exactly; lines-only programs
// must stay within the G64 tolerance of the programmed path.
TEST_P(InterpolatorLimits, NeverExceededAndEndReached) {
  const LimitCase& c = GetParam();
  const MotionLimits lim = fadal_limits();
  const Program prog = parse_gcode(c.program, c.name, {0, 0, 0}, kRapid_mm_per_min);
  const Trajectory t = plan_trajectory(prog, lim, kTs_s);
  const auto x = sample_all(t);
  const LimitCheck r = check_limits(x, lim);
  EXPECT_LE(r.max_v_ratio, 1.0 + 1e-6) << c.name;
  EXPECT_LE(r.max_a_ratio, 1.0 + 1e-6) << c.name;
  EXPECT_LE(r.max_j_ratio, 1.0 + 1e-3) << c.name;
  // A test that reaches the limits shows that they bind (not a trivially slow plan).
  EXPECT_GT(r.max_a_ratio, 0.3) << c.name;
  const ReferenceSample last = t.sample(t.num_ticks());
  EXPECT_TRUE(last.done);
  for (std::size_t a = 0; a < kNumAxes; ++a) {
    EXPECT_EQ(last.x_mm[a], prog.blocks.back().end_mm[a]) << c.name;
  }
  EXPECT_FALSE(t.sample(t.num_ticks() - 1).done);
  if (c.tolerance_mm > 0.0) {
    EXPECT_LE(max_path_deviation(x, prog), c.tolerance_mm * (1.0 + 1e-6)) << c.name;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Programs, InterpolatorLimits,
    ::testing::Values(
        LimitCase{"pocket_g64", "G64 P0.05\nG1 X40 F6000\nY30\nX0\nY0\nX20 Y15 Z-2\n", 0.05},
        LimitCase{"pocket_g64_loose", "G64 P2\nG1 X40 F9000\nY30\nX0 Y20\nX10 Y0\n", 2.0},
        LimitCase{"pocket_g61", "G61\nG1 X40 F6000\nY30\nX0\nY0\n", 1e-9},
        LimitCase{"arcs", "G61 G1 X10 F3000\nG3 X10 Y0 I-10 J0\nG2 X0 Y10 R10\nG3 X-5 Y5 I0 J-5 F6000\n", 0.0},
        LimitCase{"zigzag", "G64 P0.01 G91 G1 F3000\nX1 Y0.17\nX1 Y-0.17\nX1 Y0.17\nX1 Y-0.17\nX1 Y0.17\n"
                            "X1 Y-0.17\nX0.5 Y0.3\nX0.5 Y-0.3\nX0.2 Y0.05\nX0.2 Y-0.05\nX1 Y0\n", 0.01},
        LimitCase{"helix", "G1 X5 F6000 G61\nG3 X5 Y0 Z-3 I-5 J0\nG3 X5 Y0 Z-6 I-5 J0 F1200\n", 0.0},
        LimitCase{"rapids", "G0 X100 Y-50 Z10\nG0 X0\nG1 Z0 F2000\n", 1e-9}),
    [](const ::testing::TestParamInfo<LimitCase>& i) { return std::string(i.param.name); });

// Oracle: the blend of docs/interpolator.md. At a 90 degree corner between
// axis-aligned lines the blend ramps use the full axis limits a and j; with
// the tolerance binding and v_b <= a^2/j the ramp half-distance is
// d = v_b^1.5 / (6 sqrt(j)) and the corner deviation sqrt(2) d = T, so
// v_b = (3 sqrt(2) T sqrt(j))^(2/3) and the speed at the corner is
// v_b cos(45 deg). The planner finds v_b by bisection to 1e-13 relative.
TEST(InterpolatorCorner, NinetyDegreeBlendSpeedMatchesFormula) {
  const double T = 0.01;
  const Trajectory t = plan("G64 P0.01\nG1 X50 F6000\nY50\n");
  ASSERT_EQ(t.corners().size(), 1u);
  const Corner& c = t.corners()[0];
  EXPECT_NEAR(c.turn_angle_deg, 90.0, 1e-9);
  EXPECT_FALSE(c.exact_stop);
  const double v_b = std::pow(3.0 * std::sqrt(2.0) * T * std::sqrt(kJ), 2.0 / 3.0);
  ASSERT_LE(v_b, kA * kA / kJ);  // the regime the formula is written for
  const double v_corner = v_b * std::cos(kPi / 4.0);
  EXPECT_NEAR(c.v_ref_mm_per_s, v_corner, 1e-9 * v_corner);
  // The reference passes the corner at distance T at the blend midpoint
  // (1e-9 relative: bisection), and no sample comes closer.
  const auto mid = t.at_time(c.t_s).x_mm;
  EXPECT_NEAR(std::hypot(mid[0] - 50.0, mid[1]), T, 1e-9 * T);
  double closest = 1e9;
  for (std::int64_t k = 0; k <= t.num_ticks(); ++k) {
    const auto x = t.sample(k).x_mm;
    closest = std::min(closest, std::hypot(x[0] - 50.0, x[1]));
  }
  EXPECT_GE(closest, T * (1.0 - 1e-9));
  EXPECT_LE(closest, T * (1.0 + 1e-3));
  // The time of the corner: the sample there has the corner speed (1e-4:
  // the speed is stationary at the blend midpoint).
  const auto k = static_cast<std::int64_t>(std::llround(c.t_s / kTs_s));
  EXPECT_NEAR(t.sample(k).path_speed_mm_per_s, v_corner, 1e-4 * v_corner);
}

// Oracle: with a loose tolerance the overlap is capped by the part of the
// ramps whose shape does not depend on the top speed (v/a = 0.05 s at F 100
// mm/s), so T_b = F/a and tau = T_b/2 = 0.025 s lies in the jerk phase
// (<= a/j): the corner speed is sqrt(2) j tau^2/2 and the closest distance
// sqrt(2) j tau^3/6 (1e-9 relative: closed form against closed form).
TEST(InterpolatorCorner, LooseToleranceCappedByRampShape) {
  const double F = 100.0;
  const Trajectory t = plan("G64 P5\nG1 X50 F6000\nY50\n");
  ASSERT_EQ(t.corners().size(), 1u);
  const double tau = 0.5 * F / kA;
  ASSERT_LE(tau, kA / kJ);
  const Corner& c = t.corners()[0];
  EXPECT_NEAR(c.v_ref_mm_per_s, std::sqrt(2.0) * kJ * tau * tau / 2.0, 1e-9 * c.v_ref_mm_per_s);
  const auto mid = t.at_time(c.t_s).x_mm;
  const double dev = std::sqrt(2.0) * kJ * tau * tau * tau / 6.0;
  EXPECT_NEAR(std::hypot(mid[0] - 50.0, mid[1]), dev, 1e-9 * dev);
  for (std::int64_t k = 0; k <= t.num_ticks(); ++k) {
    const auto x = t.sample(k).x_mm;
    ASSERT_GE(std::hypot(x[0] - 50.0, x[1]), dev * (1.0 - 1e-9)) << "k " << k;
  }
}

// Oracle: with the jerk limit out of the way the blend is a parabolic blend
// with constant acceleration a: d = v_b^2/(8a), v_corner = sqrt(2 sqrt(2) a T).
// Compared with design.md's public formulas: grbl's junction deviation
// sqrt(2.414 a T) and LinuxCNC's circular blend sqrt(0.866 a 2.414 T); ours
// lies above both by the ratio of the constants, sqrt(2.828/2.414) = 1.082 and
// sqrt(2.828/2.091) = 1.163 (the blend uses each axis' full acceleration).
TEST(InterpolatorCorner, ParabolicLimitAgainstPublicFormulas) {
  const double T = 0.01;
  const Trajectory t = plan("G64 P0.01\nG1 X50 F6000\nY50\n", fadal_limits(1e12));
  ASSERT_EQ(t.corners().size(), 1u);
  const double ours = t.corners()[0].v_ref_mm_per_s;
  const double formula = std::sqrt(2.0 * std::sqrt(2.0) * kA * T);
  EXPECT_NEAR(ours, formula, 1e-4 * formula);  // jerk phases of a/j = 2e-9 s
  const double grbl = std::sqrt((1.0 + std::sqrt(2.0)) * kA * T);
  const double linuxcnc = std::sqrt(0.866 * kA * (1.0 + std::sqrt(2.0)) * T);
  EXPECT_NEAR(ours / grbl, std::sqrt(2.0 * std::sqrt(2.0) / (1.0 + std::sqrt(2.0))), 1e-3);
  EXPECT_NEAR(ours / linuxcnc, std::sqrt(2.0 * std::sqrt(2.0) / (0.866 * (1.0 + std::sqrt(2.0)))), 1e-3);
}

// Oracle: a rest-to-rest S-curve line of length L at feed F > a^2/j takes
// L/F + F/a + a/j. Four G61 sides therefore take 4 (L/F + F/a + a/j), i.e.
// each exact stop costs F/a + a/j against passing at full speed. Tolerance
// 1e-9 s: the plan is closed form up to the bisection of the peak speed.
TEST(InterpolatorExactStop, TimeLossPerCorner) {
  const double F = 100.0, L = 50.0;
  const Trajectory t = plan("G61 G1 X50 F6000\nY50\nX0\nY0\n");
  const double loss_per_corner = (t.duration_s() - 4.0 * L / F) / 4.0;
  EXPECT_NEAR(loss_per_corner, F / kA + kA / kJ, 1e-9);
  ASSERT_EQ(t.corners().size(), 3u);
  for (const Corner& c : t.corners()) {
    EXPECT_TRUE(c.exact_stop);
    EXPECT_EQ(c.v_ref_mm_per_s, 0.0);
    EXPECT_NEAR(c.turn_angle_deg, 90.0, 1e-9);
  }
  // G64 P0.05 on the same square: each corner saves the overlap time T_b of
  // the stop and start ramps. In the jerk phase (T_b/2 <= a/j) the tolerance
  // sqrt(2) j (T_b/2)^3 / 6 = P gives T_b = 2 (3 sqrt(2) P / j)^(1/3).
  const double P = 0.05;
  const double T_b = 2.0 * std::cbrt(3.0 * std::sqrt(2.0) * P / kJ);
  ASSERT_LE(0.5 * T_b, kA / kJ);
  const Trajectory blended = plan("G64 P0.05 G1 X50 F6000\nY50\nX0\nY0\n");
  EXPECT_NEAR(t.duration_s() - blended.duration_s(), 3.0 * T_b, 1e-9);
}

// Oracle: look-ahead joins 100 collinear 1 mm blocks into one rest-to-rest
// profile, so the cycle time is the closed-form S-curve time of one 100 mm
// line and the speed reaches the programmed feed. Under G61 each block
// stops: 100 rest-to-rest 1 mm profiles, 2.8 times as long.
TEST(InterpolatorLookAhead, ShortCollinearSegmentsReachFeed) {
  std::string prog = "G64 P0.01 G91 G1 F2000\n";
  for (int i = 0; i < 100; ++i) prog += "X1\n";
  const Trajectory t = plan(prog);
  const double F = 2000.0 / 60.0;
  double v_max = 0.0;
  for (std::int64_t k = 0; k <= t.num_ticks(); ++k) v_max = std::max(v_max, t.sample(k).path_speed_mm_per_s);
  EXPECT_NEAR(v_max, F, 1e-9 * F);
  EXPECT_NEAR(t.duration_s(), scurve_time(100.0, F, kA, kJ), 1e-9);
  std::string prog_stop = "G61 G91 G1 F2000\n";
  for (int i = 0; i < 100; ++i) prog_stop += "X1\n";
  const Trajectory stop = plan(prog_stop);
  EXPECT_NEAR(stop.duration_s(), 100.0 * scurve_time(1.0, F, kA, kJ), 1e-8);
  EXPECT_GT(stop.duration_s(), 2.5 * t.duration_s());
}

// Oracle: the closed-form S-curve time (scurve_time) for the three regimes:
// cruise at F, peak between a^2/j and F, peak below a^2/j. A diagonal line
// (3,4)/5 has the path limits a/0.8 and j/0.8 (min over axes of limit/|u|).
TEST(InterpolatorLine, CycleTimeAndLengthMatchClosedForm) {
  struct Case {
    std::string code;
    double L, F, a, j;
  };
  for (const Case& c : {Case{"G1 X100 F6000", 100, 100, kA, kJ}, Case{"G1 X20 F10000", 20, 10000.0 / 60, kA, kJ},
                        Case{"G1 X0.5 F6000", 0.5, 100, kA, kJ},
                        Case{"G1 X30 Y40 F9000", 50, 150, kA / 0.8, kJ / 0.8}}) {
    const Trajectory t = plan(c.code + "\n");
    ASSERT_EQ(t.block_timings().size(), 1u);
    EXPECT_NEAR(t.block_timings()[0].length_mm, c.L, 1e-12) << c.code;
    EXPECT_NEAR(t.duration_s(), scurve_time(c.L, c.F, c.a, c.j), 1e-9) << c.code;
    EXPECT_EQ(t.num_ticks(), static_cast<std::int64_t>(std::ceil(t.duration_s() / kTs_s - 1e-9))) << c.code;
  }
}

// Oracle: uniform circular motion. A full circle of R = 5 mm at F 6000 is
// limited by the centripetal share v^2/R <= a/2 to v = sqrt(a R / 2); the
// reference stays on the circle (1e-9 mm: cos/sin rounding).
TEST(InterpolatorArc, CentripetalSpeedLimitAndRadius) {
  const Trajectory t = plan("G1 X5 F6000 G61\nG3 X5 Y0 I-5 J0\n");
  double v_max = 0.0;
  const double t0 = t.block_timings()[1].t_start_s;
  for (std::int64_t k = static_cast<std::int64_t>(t0 / kTs_s) + 1; k < t.num_ticks(); ++k) {
    const ReferenceSample s = t.sample(k);
    EXPECT_NEAR(std::hypot(s.x_mm[0], s.x_mm[1]), 5.0, 1e-9);
    v_max = std::max(v_max, s.path_speed_mm_per_s);
  }
  EXPECT_NEAR(v_max, std::sqrt(0.5 * kA * 5.0), 1e-6);
}

// Oracle: the program text (which block, spindle, cutting or rapid) and a
// central difference of the samples for the analytic velocity: its error is
// at most j_max Ts^2 / 6 = 8e-5 mm/s, so 1e-3 mm/s.
TEST(InterpolatorSample, FieldsFollowTheProgram) {
  const Trajectory t = plan("S1000 M3\nG0 X10\nG1 Y10 F1200\nG4 P0.2\nM5\nG1 X0\nM30\n");
  const auto& bt = t.block_timings();
  ASSERT_EQ(bt.size(), 4u);
  auto at = [&](double ts) { return t.sample(static_cast<std::int64_t>(ts / kTs_s)); };
  const ReferenceSample r = at(0.5 * (bt[0].t_start_s + bt[0].t_end_s));
  EXPECT_EQ(r.block, 0);
  EXPECT_FALSE(r.cutting_move);
  EXPECT_DOUBLE_EQ(r.spindle_rpm, 1000.0);
  EXPECT_NEAR(r.feed_programmed_mm_per_s, kRapid_mm_per_min / 60.0, 1e-12);
  const ReferenceSample f = at(0.5 * (bt[1].t_start_s + bt[1].t_end_s));
  EXPECT_EQ(f.block, 1);
  EXPECT_TRUE(f.cutting_move);
  EXPECT_NEAR(f.feed_programmed_mm_per_s, 20.0, 1e-12);
  const ReferenceSample d = at(0.5 * (bt[2].t_start_s + bt[2].t_end_s));
  EXPECT_EQ(d.block, 2);
  EXPECT_FALSE(d.cutting_move);
  EXPECT_EQ(d.path_speed_mm_per_s, 0.0);
  EXPECT_NEAR(bt[2].t_end_s - bt[2].t_start_s, 0.2, 1e-12);
  const ReferenceSample m5 = at(0.5 * (bt[3].t_start_s + bt[3].t_end_s));
  EXPECT_EQ(m5.block, 3);
  EXPECT_EQ(m5.spindle_rpm, 0.0);
  const ReferenceSample end = t.sample(t.num_ticks() + 10);
  EXPECT_TRUE(end.done);
  EXPECT_EQ(end.block, -1);
  for (std::int64_t k = 1; k < t.num_ticks(); k += 37) {
    const ReferenceSample a = t.sample(k - 1), b = t.sample(k), c = t.sample(k + 1);
    for (std::size_t ax = 0; ax < kNumAxes; ++ax) {
      EXPECT_NEAR(b.v_mm_per_s[ax], (c.x_mm[ax] - a.x_mm[ax]) / (2 * kTs_s), 1e-3) << "k " << k;
    }
  }
}

// Oracle: the error contract. A hand-built arc whose end is off its circle
// must be refused naming file:line; bad limits name the field.
TEST(InterpolatorErrors, BadArcAndLimits) {
  Program p;
  p.source_name = "hand.nc";
  Block b;
  b.line = 7;
  b.kind = MotionKind::kArcCcw;
  b.start_mm = {10, 0, 0};
  b.end_mm = {0, 11, 0};
  b.center_mm = {0, 0, 0};
  b.feed_mm_per_min = 100;
  p.blocks.push_back(b);
  try {
    plan_trajectory(p, fadal_limits(), kTs_s);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("hand.nc:7:"), std::string::npos) << e.what();
  }
  MotionLimits bad = fadal_limits();
  bad.a_max_mm_per_s2[1] = -1.0;
  try {
    plan(std::string("G1 X1 F100\n"), bad);
    ADD_FAILURE() << "no error";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("y.a_max"), std::string::npos) << e.what();
  }
}

// Durations no run can count (issue 19). Oracle: the program's length over
// the feed is beyond 2^53 ticks (1e300 mm at any speed), or not finite.
// Before: num_ticks() cast inf to int64 (undefined) and the run never ended.
TEST(InterpolatorErrors, AstronomicalDurationsRefusedWithTheLine) {
  auto expect_refused = [](const std::string& text, const std::string& where) {
    try {
      const Trajectory t = plan(text);
      ADD_FAILURE() << "planned " << t.duration_s() << " s for " << text.substr(0, 40);
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
    }
  };
  expect_refused("G21 G90\nG1 X1" + std::string(300, '0') + " F1000\n", "test.nc:2:");
  const std::string big = "1" + std::string(307, '0');
  expect_refused("G91\nG1 X" + big + " F1000\nX" + big + "\n", "test.nc:2:");
  expect_refused("G1 X1 F1000\nG4 P" + std::string(20, '9') + "\n", "test.nc:2:");
  // A plan that fits keeps its exact tick count: 1e5 s of dwell at 1e-4 s.
  const Trajectory t = plan("G4 P100000\n");
  EXPECT_EQ(t.num_ticks(), 1000000000);
}

// Travel (issue 19). Oracle: plane geometry of the programmed moves. The
// twin has no work offset, so a program fits when its span fits the travel.
TEST(InterpolatorTravel, SpanOfMovesAndArcExtremesChecked) {
  const AxisArray<double> lo{0.0, 0.0, -508.0}, hi{559.0, 406.0, 0.0};
  auto check = [&](const std::string& text, AxisArray<double> start = {0, 0, 0}) {
    check_travel(parse_gcode(text, "t.nc", start, kRapid_mm_per_min), lo, hi);
  };
  auto expect_refused = [&](const std::string& text, const std::string& what, AxisArray<double> start = {0, 0, 0}) {
    try {
      check(text, start);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const ConfigError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  // Exactly the travel, in any place (negative work coordinates included).
  EXPECT_NO_THROW(check("G0 X559 Y406 Z-508\n"));
  EXPECT_NO_THROW(check("G0 X-300\nX259\n"));
  expect_refused("G0 X1\nX700 Y-100 Z-300\n", "t.nc:2: the move takes x to 700 mm");
  expect_refused("G0 X-300\nX259.01\n", "t.nc:2:");
  expect_refused("G0 Y-10\nG91 Y200\nY200\nY20\n", "t.nc:4:");
  // Arcs are checked at their extremes, not only at their ends: both ends of
  // this one are at x = 0, 20 mm apart in y, but counter-clockwise the long
  // way round the centre (300, 10) it reaches x = 300 + 300.17 mm.
  expect_refused("G3 X0 Y20 I300 J10 F100\n", "the move takes x to 600.167 mm");
  // Full circles: radius 200 spans 400 mm in x and y (fits 559 and 406),
  // radius 300 spans 600 mm in x.
  EXPECT_NO_THROW(check("G3 X100 Y0 I200 J0 F100\n", {100, 0, 0}));
  expect_refused("G3 X0 Y0 I300 J0 F100\n", "in x");
  // A quarter circle of radius 280 (span 280 in x and y) fits.
  EXPECT_NO_THROW(check("G2 X-280 Y0 I0 J280 F100\n", {0, -280, 0}));
}

}  // namespace
}  // namespace twin::controller
