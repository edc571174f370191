// Tests of the CNC interpolator. Oracles: closed-form jerk-limited (S-curve)
// profile times, the documented blend formula of docs/interpolator.md, the
// public corner formulas of design.md (grbl, LinuxCNC), the programmed
// geometry, and finite differences of the sampled reference checked against
// the per-axis limits.
#include <algorithm>
#include <cmath>
#include <cstdio>
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
LimitCheck check_limits(const std::vector<AxisArray<double>>& x, const MotionLimits& lim,
                        const std::vector<double>& jerk_exempt_s = {}) {
  LimitCheck r;
  for (std::size_t k = 0; k + 3 < x.size(); ++k) {
    const double t0 = static_cast<double>(k) * kTs_s;
    const bool exempt = std::any_of(jerk_exempt_s.begin(), jerk_exempt_s.end(),
                                    [&](double t) { return t >= t0 - 1e-12 && t <= t0 + 3.0 * kTs_s + 1e-12; });
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      const double v = (x[k + 1][a] - x[k][a]) / kTs_s;
      const double acc = (x[k + 2][a] - 2 * x[k + 1][a] + x[k][a]) / (kTs_s * kTs_s);
      const double jerk = (x[k + 3][a] - 3 * x[k + 2][a] + 3 * x[k + 1][a] - x[k][a]) / (kTs_s * kTs_s * kTs_s);
      r.max_v_ratio = std::max(r.max_v_ratio, std::abs(v) / lim.v_max_mm_per_s[a]);
      r.max_a_ratio = std::max(r.max_a_ratio, std::abs(acc) / lim.a_max_mm_per_s2[a]);
      if (!exempt) r.max_j_ratio = std::max(r.max_j_ratio, std::abs(jerk) / lim.j_max_mm_per_s3[a]);
    }
  }
  return r;
}

/// Times where the planned path changes curvature (a line meets an arc or a
/// blend arc, or two arcs of different radius meet): the acceleration steps
/// there by v^2/R (docs/interpolator.md, section 6), a jerk impulse.
std::vector<double> curvature_steps(const Trajectory& t) {
  std::vector<double> out;
  const auto& s = t.segments();
  using K = Trajectory::SegmentKind;
  for (std::size_t i = 0; i + 1 < s.size(); ++i) {
    const bool line0 = s[i].kind == K::kLine, line1 = s[i + 1].kind == K::kLine;
    if (line0 && line1) continue;
    if (!line0 && !line1 && s[i].r1_mm == s[i + 1].r0_mm && s[i].kind == s[i + 1].kind) continue;
    out.push_back(s[i].t_end_s);
  }
  return out;
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
// tick (see check_limits for why no slack beyond 1e-6 relative is needed;
// the jerk everywhere but across the curvature steps of blend arcs and
// arcs, where it is an impulse: docs/interpolator.md, section 6);
// the end point must equal the programmed end exactly; lines-only programs
// must stay within the G64 tolerance of the programmed path.
TEST_P(InterpolatorLimits, NeverExceededAndEndReached) {
  const LimitCase& c = GetParam();
  const MotionLimits lim = fadal_limits();
  const Program prog = parse_gcode(c.program, c.name, {0, 0, 0}, kRapid_mm_per_min);
  const Trajectory t = plan_trajectory(prog, lim, kTs_s);
  const auto x = sample_all(t);
  const LimitCheck r = check_limits(x, lim, curvature_steps(t));
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

// Oracle: the blend arc of docs/interpolator.md, section 4, written here from
// its geometry. Between lines turning by theta, the arc tangent to both that
// passes at P from the corner has R_tol = P cos(theta/2) / (1 - cos(theta/2));
// it takes d = R tan(theta/2) of each line, at most half of either, so
// R <= (L/2) / tan(theta/2); it runs at v = min(F, sqrt(sqrt(3)/2 a R),
// cbrt(j R^2 / 3)); and the planner picks the smallest radius that lets F
// through, R = max(F^2 / (sqrt(3)/2 a), sqrt(3 F^3 / j)), when that is below
// the largest. Tolerances: 1e-9 relative (closed forms evaluated in double on
// both sides); the sampled path 1e-9 mm (cos/sin of the arc).
struct BlendCase {
  double turn_deg, P_mm, F_mm_per_min, L_mm;
};

void check_blend_case(const BlendCase& c, double j) {
  SCOPED_TRACE(::testing::Message() << "turn " << c.turn_deg << " P " << c.P_mm << " F " << c.F_mm_per_min << " L "
                                    << c.L_mm << " j " << j);
  const double th = c.turn_deg * kPi / 180.0;
  const double F = c.F_mm_per_min / 60.0;
  const double kN = std::sqrt(3.0) / 2.0;
  const double R_tol = c.P_mm * std::cos(th / 2) / (1.0 - std::cos(th / 2));
  const double R_max = std::min(R_tol, 0.5 * c.L_mm / std::tan(th / 2));
  const double R_goal = std::max(F * F / (kN * kA), std::sqrt(3.0 * F * F * F / j));
  const double R = std::min(R_max, R_goal);
  const double v = std::min({F, std::sqrt(kN * kA * R), std::cbrt(j * R * R / 3.0)});
  const double ex = c.L_mm + c.L_mm * std::cos(th), ey = c.L_mm * std::sin(th);
  const std::string text =
      "G64 P" + std::to_string(c.P_mm) + "\nG1 X" + std::to_string(c.L_mm) + " F" + std::to_string(c.F_mm_per_min) +
      "\nX" + std::to_string(ex) + " Y" + std::to_string(ey) + "\n";
  const Program prog = parse_gcode(text, "blend.nc", {0, 0, 0}, kRapid_mm_per_min);
  const MotionLimits lim = fadal_limits(j);
  const Trajectory t = plan_trajectory(prog, lim, kTs_s);
  ASSERT_EQ(t.corners().size(), 1u);
  const Corner& k = t.corners()[0];
  EXPECT_NEAR(k.turn_angle_deg, c.turn_deg, 1e-6);
  EXPECT_FALSE(k.exact_stop);
  EXPECT_NEAR(k.blend_radius_mm, R, 1e-9 * R);
  EXPECT_NEAR(k.v_ref_mm_per_s, v, 1e-9 * v);
  const double dev = R * (1.0 / std::cos(th / 2) - 1.0);
  EXPECT_NEAR(k.deviation_mm, dev, 1e-9 * c.P_mm);
  EXPECT_LE(k.deviation_mm, c.P_mm * (1.0 + 1e-12));
  if (v < F) {
    EXPECT_NEAR(k.deviation_mm, R == R_tol ? c.P_mm : dev, 1e-9 * c.P_mm);
  }
  // The sampled reference: at the corner time it is at dev from the corner,
  // no sample comes closer, none leaves the programmed lines by more than dev.
  const auto mid = t.at_time(k.t_s).x_mm;
  EXPECT_NEAR(std::hypot(mid[0] - c.L_mm, mid[1]), dev, 1e-9);
  const auto x = sample_all(t);
  double closest = 1e9;
  for (const auto& p : x) closest = std::min(closest, std::hypot(p[0] - c.L_mm, p[1]));
  EXPECT_GE(closest, dev - 1e-9);
  EXPECT_LE(max_path_deviation(x, prog), dev + 1e-9);
  const LimitCheck r = check_limits(x, lim);
  EXPECT_LE(r.max_v_ratio, 1.0 + 1e-6);
  EXPECT_LE(r.max_a_ratio, 1.0 + 1e-6);
}

TEST(InterpolatorCorner, BlendArcSpeedFollowsToleranceAngleAndFeedJerkOff) {
  for (double turn : {45.0, 90.0, 135.0})
    for (double P : {0.01, 0.05, 0.2, 5.0})
      for (double F : {500.0, 3000.0, 6000.0}) check_blend_case({turn, P, F, 20.0}, 1e12);
}

TEST(InterpolatorCorner, BlendArcSpeedWithJerkLimit) {
  for (double turn : {45.0, 90.0, 135.0})
    for (double P : {0.01, 0.05}) check_blend_case({turn, P, 500.0, 20.0}, kJ);
}

// Oracle: LinuxCNC's circular blend (design.md): at 90 degrees the arc that
// passes at P from the corner has R = P / (sqrt(2) - 1) = 2.414 P and runs at
// sqrt(0.866 a R) (LinuxCNC's 0.866 = sqrt(3)/2 to 1e-5). With jerk off and F
// above it, the twin's corner speed is that figure (1e-4: LinuxCNC's
// rounded 0.866), and grbl's junction-deviation speed sqrt(2.414 a P) is
// above it by sqrt(1/0.866).
TEST(InterpolatorCorner, NinetyDegreesMatchesLinuxCncCircularBlend) {
  const double P = 0.01;
  const Trajectory t = plan("G64 P0.01\nG1 X50 F6000\nY50\n", fadal_limits(1e12));
  ASSERT_EQ(t.corners().size(), 1u);
  const double ours = t.corners()[0].v_ref_mm_per_s;
  const double linuxcnc = std::sqrt(0.866 * kA * (1.0 + std::sqrt(2.0)) * P);
  EXPECT_NEAR(ours, linuxcnc, 1e-4 * linuxcnc);
  const double grbl = std::sqrt((1.0 + std::sqrt(2.0)) * kA * P);
  EXPECT_NEAR(grbl / ours, std::sqrt(1.0 / 0.866), 1e-4);
}

/// Distance from p to the programmed path, arcs included (XY circles).
double dist_to_program(const AxisArray<double>& p, const Program& prog) {
  double best = 1e300;
  for (const Block& b : prog.blocks) {
    if (b.kind == MotionKind::kArcCw || b.kind == MotionKind::kArcCcw) {
      const double cx = b.center_mm[0], cy = b.center_mm[1];
      const double R = std::hypot(b.start_mm[0] - cx, b.start_mm[1] - cy);
      const double a0 = std::atan2(b.start_mm[1] - cy, b.start_mm[0] - cx);
      const double a1 = std::atan2(b.end_mm[1] - cy, b.end_mm[0] - cx);
      const double ap = std::atan2(p[1] - cy, p[0] - cx);
      auto ccw_from = [](double from, double to) {
        double d = std::fmod(to - from, 2.0 * kPi);
        return d < 0.0 ? d + 2.0 * kPi : d;
      };
      const bool ccw = b.kind == MotionKind::kArcCcw;
      const double sweep = ccw ? ccw_from(a0, a1) : ccw_from(a1, a0);
      const double at = ccw ? ccw_from(a0, ap) : ccw_from(ap, a0);
      double d = std::min(std::hypot(p[0] - b.start_mm[0], p[1] - b.start_mm[1]),
                          std::hypot(p[0] - b.end_mm[0], p[1] - b.end_mm[1]));
      if (at <= sweep) d = std::min(d, std::abs(std::hypot(p[0] - cx, p[1] - cy) - R));
      best = std::min(best, d);
    } else {
      best = std::min(best, dist_point_segment(p, b.start_mm, b.end_mm));
    }
  }
  return best;
}

// Oracle: the programmed geometry (lines and circles) and the per-axis
// limits. A non-tangent junction with an arc under G64 P is blended: the
// corner is passed at a speed well above zero (before: 0.06 mm/s; at least
// the speed of the arc of radius R_tol/4 that the blend is never smaller
// than here), the path stays within P of the programmed lines and arcs
// (1e-9 mm: cos/sin), and velocity and acceleration stay within the limits
// on finite differences of every tick.
TEST(InterpolatorCorner, LineArcAndArcArcJunctionsAreBlended) {
  const double P = 0.05;
  for (const char* body : {"G1 X40 F3000\nG2 X44 Y4 I4 J0\n",                 // line -> arc, 90 deg
                           "G2 X10 Y10 I10 J0 F3000\nG1 X10 Y20\n",           // arc -> line, 90 deg
                           "G3 X10 Y10 I0 J10 F3000\nG2 X20 Y20 I0 J10\n",    // arc -> arc, 90 deg
                           "G1 X10 F3000\nG3 X20 Y0 I5 J0\nG1 X30 Y0\n"}) {    // line -> arc -> line
    SCOPED_TRACE(body);
    for (double j : {kJ, 1e12}) {
      const MotionLimits lim = fadal_limits(j);
      const Program prog = parse_gcode(std::string("G64 P0.05\n") + body, "arc.nc", {0, 0, 0}, kRapid_mm_per_min);
      const Trajectory t = plan_trajectory(prog, lim, kTs_s);
      ASSERT_FALSE(t.corners().empty());
      for (const Corner& c : t.corners()) {
        EXPECT_FALSE(c.exact_stop);
        EXPECT_GT(c.blend_radius_mm, 0.0);
        EXPECT_LE(c.deviation_mm, P * (1.0 + 1e-9));
        const double R_floor = 0.25 * P * std::cos(kPi / 4) / (1.0 - std::cos(kPi / 4));
        EXPECT_GT(c.v_ref_mm_per_s, std::min(std::sqrt(0.5 * kA * R_floor), std::cbrt(j * R_floor * R_floor / 3.0)));
      }
      const auto x = sample_all(t);
      double worst = 0.0;
      for (const auto& p : x) worst = std::max(worst, dist_to_program(p, prog));
      EXPECT_LE(worst, P + 1e-9);
      const LimitCheck r = check_limits(x, lim);
      EXPECT_LE(r.max_v_ratio, 1.0 + 1e-6);
      EXPECT_LE(r.max_a_ratio, 1.0 + 1e-6);
    }
  }
}

// Oracle: G61 (LinuxCNC's exact path) does not blend: the same 90 degree
// corner stops (speed 0) under G61 and under G61.1 (exact stop); a tangent
// line-arc junction is passed at speed under G61 but stops under G61.1.
TEST(InterpolatorCorner, ExactPathAndExactStopModes) {
  for (const char* mode : {"G61", "G61.1"}) {
    const Trajectory t = plan(std::string(mode) + "\nG1 X50 F6000\nY50\n");
    ASSERT_EQ(t.corners().size(), 1u);
    EXPECT_TRUE(t.corners()[0].exact_stop) << mode;
    EXPECT_EQ(t.corners()[0].v_ref_mm_per_s, 0.0) << mode;
  }
  auto speed_at_junction = [&](const char* mode) {
    const Trajectory t = plan(std::string(mode) + "\nG1 X10 F3000\nG3 X20 Y10 I0 J10\n");
    return t.at_time(t.block_timings()[1].t_start_s).path_speed_mm_per_s;
  };
  EXPECT_GT(speed_at_junction("G61"), 10.0);  // the arc's cap is sqrt(sqrt(3)/2 a 10) = 132 mm/s > F = 50
  EXPECT_EQ(speed_at_junction("G61.1"), 0.0);
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
  // G64 P0.05 on the same square with jerk off (j = 1e12: jerk phases of
  // a/j = 2e-9 s, hence 1e-7 s): each corner is a quarter arc of radius
  // R = P / (sqrt(2) - 1) (tolerance-bound: F^2 / (sqrt(3)/2 a) = 5.8 mm is
  // larger) taking d = R of each line, run at v_c = sqrt(sqrt(3)/2 a R); the
  // lines are trapezoids v_in -> F -> v_out. The sum of those closed forms
  // is the cycle time.
  const double P = 0.05;
  const double R = P / (std::sqrt(2.0) - 1.0);
  const double v_c = std::sqrt(std::sqrt(3.0) / 2.0 * kA * R);
  auto trapezoid = [&](double len, double v0, double v1) {
    return (len - (F * F - v0 * v0) / (2 * kA) - (F * F - v1 * v1) / (2 * kA)) / F + (F - v0) / kA + (F - v1) / kA;
  };
  const double expected = trapezoid(L - R, 0.0, v_c) + 2.0 * trapezoid(L - 2 * R, v_c, v_c) +
                          trapezoid(L - R, v_c, 0.0) + 3.0 * (R * kPi / 2.0) / v_c;
  const Trajectory blended = plan("G64 P0.05 G1 X50 F6000\nY50\nX0\nY0\n", fadal_limits(1e12));
  EXPECT_NEAR(blended.duration_s(), expected, 1e-7);
  for (const Corner& c : blended.corners()) EXPECT_NEAR(c.v_ref_mm_per_s, v_c, 1e-9 * v_c);
}

// Oracle: look-ahead joins 100 collinear 1 mm blocks into one rest-to-rest
// profile, so the cycle time is the closed-form S-curve time of one 100 mm
// line and the speed reaches the programmed feed. Under G61 each block
// (G61.1, exact stop) each block stops: 100 rest-to-rest 1 mm profiles, 2.8
// times as long.
TEST(InterpolatorLookAhead, ShortCollinearSegmentsReachFeed) {
  std::string prog = "G64 P0.01 G91 G1 F2000\n";
  for (int i = 0; i < 100; ++i) prog += "X1\n";
  const Trajectory t = plan(prog);
  const double F = 2000.0 / 60.0;
  double v_max = 0.0;
  for (std::int64_t k = 0; k <= t.num_ticks(); ++k) v_max = std::max(v_max, t.sample(k).path_speed_mm_per_s);
  EXPECT_NEAR(v_max, F, 1e-9 * F);
  EXPECT_NEAR(t.duration_s(), scurve_time(100.0, F, kA, kJ), 1e-9);
  std::string prog_stop = "G61.1 G91 G1 F2000\n";
  for (int i = 0; i < 100; ++i) prog_stop += "X1\n";
  const Trajectory stop = plan(prog_stop);
  EXPECT_NEAR(stop.duration_s(), 100.0 * scurve_time(1.0, F, kA, kJ), 1e-8);
  EXPECT_GT(stop.duration_s(), 2.5 * t.duration_s());
  // G61 (exact path) passes collinear junctions: the time of one line.
  std::string prog_path = "G61 G91 G1 F2000\n";
  for (int i = 0; i < 100; ++i) prog_path += "X1\n";
  EXPECT_NEAR(plan(prog_path).duration_s(), scurve_time(100.0, F, kA, kJ), 1e-9);
}

// Oracle: the blend geometry of docs/interpolator.md on a polygon. 60 chords
// of a circle of radius 1 mm (0.09996 mm each, turning by 0.1 rad at each
// vertex) at F 3000 under G64 P0.01: every blend may take half of each chord,
// so its radius is (c/2) / tan(0.05) = cos(0.05) mm (the tolerance would allow
// 8 mm), and the speed its curvature allows is sqrt(sqrt(3)/2 a cos(0.05)) =
// 41.6 mm/s, below F = 50 mm/s. Look-ahead spans the whole program, so the
// chain reaches that speed and holds it between the junctions (1e-6
// relative: bisection of the peak speeds); under G61.1 every chord stops.
// Jerk off: with jerk on the chain accelerates far more slowly (every move
// starts and ends at zero tangential acceleration; docs/interpolator.md
// section 3).
TEST(InterpolatorLookAhead, ChainOfShortSegmentsReachesTheSpeedItsCurvatureAllows) {
  auto chain = [](const char* mode) {
    std::string p = std::string(mode) + "\nG1 X1 Y0 F3000\n";
    char buf[96];
    for (int k = 1; k <= 60; ++k) {
      std::snprintf(buf, sizeof buf, "X%.17g Y%.17g\n", std::cos(0.1 * k), std::sin(0.1 * k));
      p += buf;
    }
    return p;
  };
  const MotionLimits lim = fadal_limits(1e12);
  const Trajectory t = plan(chain("G64 P0.01"), lim);
  const double v_curv = std::sqrt(std::sqrt(3.0) / 2.0 * kA * std::cos(0.05));
  ASSERT_LT(v_curv, 50.0);
  const auto& bt = t.block_timings();
  ASSERT_EQ(bt.size(), 61u);
  double v_max = 0.0, v_min_middle = 1e9;
  for (std::int64_t k = 0; k <= t.num_ticks(); ++k) {
    const double ts = static_cast<double>(k) * kTs_s;
    const double v = t.sample(k).path_speed_mm_per_s;
    if (ts >= bt[1].t_start_s) v_max = std::max(v_max, v);
    if (ts >= bt[20].t_start_s && ts <= bt[40].t_end_s) v_min_middle = std::min(v_min_middle, v);
  }
  EXPECT_NEAR(v_max, v_curv, 1e-6 * v_curv);
  EXPECT_NEAR(v_min_middle, v_curv, 1e-6 * v_curv);
  for (const Corner& c : t.corners()) EXPECT_FALSE(c.exact_stop);
  const Trajectory stop = plan(chain("G61.1"), lim);
  EXPECT_GT(stop.duration_s(), 3.0 * t.duration_s());
  const auto x = sample_all(t);
  const LimitCheck r = check_limits(x, lim);
  EXPECT_LE(r.max_v_ratio, 1.0 + 1e-6);
  EXPECT_LE(r.max_a_ratio, 1.0 + 1e-6);
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

// Oracle: uniform circular motion. A full circle is limited by the
// centripetal share v^2/R <= (sqrt(3)/2) a (LinuxCNC's sqrt(0.866 a R),
// leaving a/2 for the tangential part) and, with jerk on, by the rotation of
// the centripetal acceleration v^3/R^2 <= j/3. R = 5 mm at F 6000: 93.06 mm/s
// with jerk off, cbrt(j R^2 / 3) = 74.7 mm/s with j = 50000; R = 2 mm with
// jerk off: 58.9 mm/s (before: sqrt(a R / 2) = 44.7). The reference stays
// on the circle (1e-9 mm: cos/sin rounding); speeds to 1e-6 relative
// (bisection of the peak speed).
TEST(InterpolatorArc, CentripetalSpeedLimitAndRadius) {
  struct Case {
    double R, j, v;
  };
  const double kN = std::sqrt(3.0) / 2.0;
  for (const Case& c : {Case{5.0, 1e12, std::sqrt(kN * kA * 5.0)}, Case{5.0, kJ, std::cbrt(kJ * 25.0 / 3.0)},
                        Case{2.0, 1e12, std::sqrt(kN * kA * 2.0)}}) {
    const std::string R = std::to_string(c.R);
    const Trajectory t = plan("G1 X" + R + " F6000 G61\nG3 X" + R + " Y0 I-" + R + " J0\n", fadal_limits(c.j));
    double v_max = 0.0;
    const double t0 = t.block_timings()[1].t_start_s;
    for (std::int64_t k = static_cast<std::int64_t>(t0 / kTs_s) + 1; k < t.num_ticks(); ++k) {
      const ReferenceSample s = t.sample(k);
      EXPECT_NEAR(std::hypot(s.x_mm[0], s.x_mm[1]), c.R, 1e-9);
      v_max = std::max(v_max, s.path_speed_mm_per_s);
    }
    EXPECT_NEAR(v_max, c.v, 1e-6 * c.v) << "R " << c.R << " j " << c.j;
  }
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
