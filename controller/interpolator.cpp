#include "controller/interpolator.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>

#include <fmt/format.h>

#include "twin/core/check.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::controller {
namespace {

/// Junctions that cannot be blended (a helix, a move out of the XY plane
/// next to an arc) and turn by at most this much are passed without
/// stopping; the velocity step v*theta is kept below 0.5 a_max Ts.
constexpr double kTangentAngle_rad = 0.5 * kRadPerDeg;
/// Junctions below this turn are passed with the same velocity-step cap
/// instead of a blend (a blend arc of radius L/(2 tan(theta/2)) would be
/// needlessly large); at a = 2000 mm/s^2 and Ts = 1e-4 s the cap is
/// 1000 mm/s.
constexpr double kKinkAngle_rad = 1e-4;
/// Turns beyond this are reversals: no blend, the moves stop.
constexpr double kMaxBlendTurn_rad = kPi - 1e-3;
/// Straight-on junctions below this turn need no cap at all.
constexpr double kCollinearAngle_rad = 1e-9;
/// Blend arcs smaller than this are not planned (the moves stop).
constexpr double kMinBlendRadius_mm = 1e-6;
/// Corners reported by Trajectory::corners().
constexpr double kCornerReportAngle_deg = 1.0;
/// On arcs (programmed and blend) the centripetal part may use this share of
/// the acceleration limit and the tangential part kArcTangentShare: with
/// sqrt(3)/2 and 1/2 the two add up to exactly a (LinuxCNC's ratio,
/// 0.866 / 0.5). The jerk is split in three (tangential, centripetal
/// rotation v^3 k^2, coupling 3 v a_t k).
constexpr double kArcNormalShare = 0.86602540378443865;
constexpr double kArcTangentShare = 0.5;
constexpr double kArcJerkShare = 1.0 / 3.0;
constexpr double kArcRadiusTolerance_mm = 0.002;
constexpr double kArcRadiusTolerance_rel = 1e-3;
constexpr double kMinLength_mm = 1e-9;
/// The tick counter of a run is an int64 read back as a double: a plan must
/// fit in 2^53 ticks so that every tick time k Ts is exact in k.
constexpr double kMaxTicks = 9007199254740992.0;

/// Times of a jerk-limited speed change by dv with zero acceleration at both
/// ends: jerk phases Tj and a constant-acceleration phase Ta.
struct Transition {
  double Tj_s{0.0};
  double Ta_s{0.0};
  double total_s() const { return 2.0 * Tj_s + Ta_s; }
};

Transition transition(double dv, double a, double j) {
  dv = std::abs(dv);
  if (!(dv > 0.0)) return {};
  if (dv * j <= a * a) return {std::sqrt(dv / j), 0.0};
  return {a / j, dv / a - a / j};
}

/// Distance covered by a speed change v0 -> v1: the acceleration profile is
/// symmetric, so the mean speed is (v0 + v1) / 2.
double transition_distance(double v0, double v1, double a, double j) {
  return 0.5 * (v0 + v1) * transition(v1 - v0, a, j).total_s();
}

/// Largest x in [lo, hi] with ok(x), for ok monotone (true up to a point).
template <class F>
double bisect_max(double lo, double hi, F&& ok) {
  if (ok(hi)) return hi;
  for (int it = 0; it < 200 && hi - lo > 1e-13 * std::max(1.0, hi); ++it) {
    const double mid = 0.5 * (lo + hi);
    if (ok(mid)) {
      lo = mid;
    } else {
      hi = mid;
    }
  }
  return lo;
}

/// Largest speed v <= v_cap from which speed v_end is reached within L.
double reachable_speed(double v_end, double L_mm, double a, double j, double v_cap) {
  if (v_end >= v_cap) return v_cap;
  return bisect_max(v_end, v_cap, [&](double v) { return transition_distance(v, v_end, a, j) <= L_mm; });
}

/// Builds the constant-jerk pieces of one scalar law.
class LawBuilder {
 public:
  LawBuilder(std::vector<LawPiece>& pieces, double t_s, double v0) : pieces_(pieces), t_s_(t_s), v_(v0) {}
  void transition_to(double v1, double a, double j) {
    const Transition tr = transition(v1 - v_, a, j);
    const double sign = v1 >= v_ ? 1.0 : -1.0;
    const double a_peak = sign * j * tr.Tj_s;
    push(tr.Tj_s, 0.0, sign * j);
    push(tr.Ta_s, a_peak, 0.0);
    push(tr.Tj_s, a_peak, -sign * j);
    v_ = v1;
  }
  void cruise(double distance_mm) {
    if (distance_mm > 0.0 && v_ > 0.0) push(distance_mm / v_, 0.0, 0.0);
  }
  double t_s() const { return t_s_; }
  double s_mm() const { return s_mm_; }

 private:
  void push(double duration_s, double a0, double jerk) {
    if (!(duration_s > 0.0)) return;
    pieces_.push_back({t_s_, s_mm_, v_, a0, jerk});
    const double d = duration_s;
    s_mm_ += v_ * d + a0 * d * d / 2.0 + jerk * d * d * d / 6.0;
    v_ += a0 * d + jerk * d * d / 2.0;
    t_s_ += d;
  }
  std::vector<LawPiece>& pieces_;
  double t_s_;
  double s_mm_{0.0};
  double v_;
};

/// Path limits of one move: cruise speed cap, tangential acceleration and jerk.
struct PathLimits {
  double v_cap{0.0};
  double a{0.0};
  double j{0.0};
};

enum class JunctionKind { kStop, kTangent, kBlend };

struct Junction {
  JunctionKind kind{JunctionKind::kStop};
  double v_mm_per_s{0.0};  // upper bound, then the planned speed
  double turn_rad{0.0};
};

/// Path limits of an arc of curvature k and torsion tau whose axis-speed cap
/// is v_axes, with acceleration a and jerk j shared between its tangential
/// and normal parts (docs/interpolator.md, section 1).
PathLimits arc_limits(double kappa, double torsion, double v_axes, double a, double j) {
  PathLimits pl;
  pl.v_cap = std::min({v_axes, std::sqrt(kArcNormalShare * a / kappa),
                       std::cbrt(kArcJerkShare * j / (kappa * (kappa + torsion)))});
  pl.a = std::min(kArcTangentShare * a, kArcJerkShare * j / (3.0 * pl.v_cap * kappa));
  pl.j = kArcJerkShare * j;
  return pl;
}

/// Smallest radius of a plane arc whose arc_limits let speed v through:
/// v^2 / R <= (sqrt(3)/2) a and v^3 / R^2 <= j/3.
double radius_for_speed(double v, double a, double j) {
  return std::max(v * v / (kArcNormalShare * a), std::sqrt(v * v * v / (kArcJerkShare * j)));
}

double min_over_axes(const AxisArray<double>& lim, const AxisArray<double>& comp) {
  double r = std::numeric_limits<double>::infinity();
  for (std::size_t a = 0; a < kNumAxes; ++a)
    if (std::abs(comp[a]) > 1e-15) r = std::min(r, lim[a] / std::abs(comp[a]));
  return r;
}

double min_of(const AxisArray<double>& v) { return std::min({v[0], v[1], v[2]}); }

AxisArray<double> normalized(const AxisArray<double>& v) {
  const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return {v[0] / n, v[1] / n, v[2] / n};
}

double angle_between(const AxisArray<double>& a, const AxisArray<double>& b) {
  const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const AxisArray<double> c{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  return std::atan2(std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), dot);
}

using Segment = Trajectory::Segment;
using SegmentKind = Trajectory::SegmentKind;

AxisArray<double> arc_tangent(const Segment& s, double lambda) {
  const double r = s.r0_mm + (s.r1_mm - s.r0_mm) * lambda;
  const double phi = s.phi0_rad + s.dphi_rad * lambda;
  const double dr = s.r1_mm - s.r0_mm;
  return normalized({dr * std::cos(phi) - r * s.dphi_rad * std::sin(phi),
                     dr * std::sin(phi) + r * s.dphi_rad * std::cos(phi), s.end_mm[2] - s.start_mm[2]});
}

AxisArray<double> blend_tangent(const Segment& s, double phi) {
  const double c = std::cos(phi), sn = std::sin(phi);
  return {-sn * s.e1[0] + c * s.e2[0], -sn * s.e1[1] + c * s.e2[1], -sn * s.e1[2] + c * s.e2[2]};
}
AxisArray<double> entry_tangent(const Segment& s) {
  if (s.kind == SegmentKind::kBlend) return blend_tangent(s, s.phi0_rad);
  return s.kind == SegmentKind::kLine ? s.u : arc_tangent(s, 0.0);
}
AxisArray<double> exit_tangent(const Segment& s) {
  if (s.kind == SegmentKind::kBlend) return blend_tangent(s, s.phi0_rad + s.dphi_rad);
  return s.kind == SegmentKind::kLine ? s.u : arc_tangent(s, 1.0);
}

AxisArray<double> operator-(const AxisArray<double>& a, const AxisArray<double>& b) {
  return {a[0] - b[0], a[1] - b[1], a[2] - b[2]};
}
AxisArray<double> axpy(const AxisArray<double>& x, double s, const AxisArray<double>& d) {
  return {x[0] + s * d[0], x[1] + s * d[1], x[2] + s * d[2]};
}
double dot3(const AxisArray<double>& a, const AxisArray<double>& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm3(const AxisArray<double>& a) { return std::sqrt(dot3(a, a)); }

/// A blend arc between the move before and the move after a corner point C:
/// tangent to both, of radius R, taking d0 of arc length from the end of the
/// move before and d1 from the start of the move after. The arc is
/// x = c + R (cos phi e1 + sin phi e2), phi in [0, sweep].
struct Fillet {
  bool valid{false};
  double R_mm{0.0};
  double d0_mm{0.0};
  double d1_mm{0.0};
  AxisArray<double> c_mm{}, e1{}, e2{};
  double sweep_rad{0.0};
  double deviation_mm{0.0};  ///< distance from C to the arc
  double split_rad{0.0};     ///< angle of the arc's point closest to C
};

/// Between two lines (any plane): tangent length d = R tan(theta/2), the
/// centre on the bisector at R / cos(theta/2) from C, deviation
/// R (1 / cos(theta/2) - 1).
Fillet line_line_fillet(const AxisArray<double>& C, const AxisArray<double>& u0, const AxisArray<double>& u1,
                        double turn_rad, double R) {
  Fillet f;
  const double d = R * std::tan(0.5 * turn_rad);
  const double h = R / std::cos(0.5 * turn_rad);
  const AxisArray<double> b = normalized(u1 - u0);
  f.c_mm = axpy(C, h, b);
  AxisArray<double> e1 = axpy(C, -d, u0) - f.c_mm;
  e1 = axpy(e1, -dot3(e1, u0), u0);  // exactly orthogonal to u0
  f.e1 = normalized(e1);
  f.e2 = u0;
  f.R_mm = R;
  f.d0_mm = f.d1_mm = d;
  f.sweep_rad = turn_rad;
  f.deviation_mm = h - R;
  f.split_rad = 0.5 * turn_rad;
  f.valid = true;
  return f;
}

/// A move near a corner, in the XY plane: a line (unit direction t) or a
/// circle (centre o, radius rho, dir +1 counter-clockwise, -1 clockwise).
struct PlaneCurve {
  bool line{true};
  double tx{0.0}, ty{0.0};
  double ox{0.0}, oy{0.0}, rho{0.0}, dir{1.0};
};

double cross2(double ax, double ay, double bx, double by) { return ax * by - ay * bx; }
double signed_angle2(double ax, double ay, double bx, double by) {
  return std::atan2(cross2(ax, ay, bx, by), ax * bx + ay * by);
}

/// Points at distance R from both curves on the side sigma (+1 left of the
/// direction of travel), i.e. the intersections of the two offset curves; the
/// one nearest to C (cx, cy), or false.
bool fillet_centre(const PlaneCurve& a, const PlaneCurve& b, double cx, double cy, double sigma, double R,
                   double& px, double& py) {
  struct Offset {
    bool line;
    double x, y, tx, ty, r;
  };
  auto offset = [&](const PlaneCurve& c) {
    if (c.line) return Offset{true, cx - sigma * R * c.ty, cy + sigma * R * c.tx, c.tx, c.ty, 0.0};
    return Offset{false, c.ox, c.oy, 0.0, 0.0, c.rho - sigma * c.dir * R};
  };
  const Offset A = offset(a), B = offset(b);
  if ((!A.line && !(A.r > 0.0)) || (!B.line && !(B.r > 0.0))) return false;
  double best = std::numeric_limits<double>::infinity();
  auto take = [&](double x, double y) {
    const double dd = std::hypot(x - cx, y - cy);
    if (dd < best) {
      best = dd;
      px = x;
      py = y;
    }
  };
  auto line_circle = [&](const Offset& L, const Offset& Cc) {
    const double fx = L.x - Cc.x, fy = L.y - Cc.y;
    const double bh = L.tx * fx + L.ty * fy;
    const double disc = bh * bh - (fx * fx + fy * fy - Cc.r * Cc.r);
    if (disc < 0.0) return;
    const double sq = std::sqrt(disc);
    for (double s : {-bh - sq, -bh + sq}) take(L.x + s * L.tx, L.y + s * L.ty);
  };
  if (A.line && B.line) {
    const double den = cross2(A.tx, A.ty, B.tx, B.ty);
    if (std::abs(den) < 1e-15) return false;
    const double s = cross2(B.x - A.x, B.y - A.y, B.tx, B.ty) / den;
    take(A.x + s * A.tx, A.y + s * A.ty);
  } else if (A.line) {
    line_circle(A, B);
  } else if (B.line) {
    line_circle(B, A);
  } else {
    const double dx = B.x - A.x, dy = B.y - A.y;
    const double D = std::hypot(dx, dy);
    if (!(D > 0.0) || D > A.r + B.r || D < std::abs(A.r - B.r)) return false;
    const double along = (A.r * A.r - B.r * B.r + D * D) / (2.0 * D);
    const double hh = std::sqrt(std::max(0.0, A.r * A.r - along * along));
    const double mx = A.x + along * dx / D, my = A.y + along * dy / D;
    take(mx - hh * dy / D, my + hh * dx / D);
    take(mx + hh * dy / D, my - hh * dx / D);
  }
  return std::isfinite(best);
}

/// Fillet of radius R between two XY curves meeting at C (height z), turning
/// to the side sigma; d0 <= d0_max and d1 <= d1_max.
Fillet plane_fillet(const PlaneCurve& a, const PlaneCurve& b, const AxisArray<double>& C, double sigma, double R,
                    double d0_max, double d1_max) {
  Fillet f;
  double px = 0.0, py = 0.0;
  if (!fillet_centre(a, b, C[0], C[1], sigma, R, px, py)) return f;
  // Tangent points, the arc length each takes, and each move's tangent there.
  auto touch = [&](const PlaneCurve& c, bool before, double& tx_, double& ty_, double& d, double& dirx, double& diry) {
    if (c.line) {
      tx_ = px + sigma * R * c.ty;
      ty_ = py - sigma * R * c.tx;
      d = before ? (C[0] - tx_) * c.tx + (C[1] - ty_) * c.ty : (tx_ - C[0]) * c.tx + (ty_ - C[1]) * c.ty;
      dirx = c.tx;
      diry = c.ty;
      return;
    }
    const double rx = px - c.ox, ry = py - c.oy, rn = std::hypot(rx, ry);
    tx_ = c.ox + c.rho * rx / rn;
    ty_ = c.oy + c.rho * ry / rn;
    const double ang = before ? signed_angle2(tx_ - c.ox, ty_ - c.oy, C[0] - c.ox, C[1] - c.oy)
                              : signed_angle2(C[0] - c.ox, C[1] - c.oy, tx_ - c.ox, ty_ - c.oy);
    d = c.rho * c.dir * ang;
    dirx = -c.dir * (ty_ - c.oy) / c.rho;
    diry = c.dir * (tx_ - c.ox) / c.rho;
  };
  double t0x = 0, t0y = 0, t1x = 0, t1y = 0, g0x = 0, g0y = 0, g1x = 0, g1y = 0;
  touch(a, true, t0x, t0y, f.d0_mm, g0x, g0y);
  touch(b, false, t1x, t1y, f.d1_mm, g1x, g1y);
  if (!(f.d0_mm > 0.0 && f.d0_mm <= d0_max && f.d1_mm > 0.0 && f.d1_mm <= d1_max)) return f;
  const double e1x = (t0x - px) / R, e1y = (t0y - py) / R;
  const double e2x = -sigma * e1y, e2y = sigma * e1x;
  f.sweep_rad = sigma * signed_angle2(t0x - px, t0y - py, t1x - px, t1y - py);
  // The arc must leave along the move before and arrive along the move after.
  if (!(f.sweep_rad > 0.0) || e2x * g0x + e2y * g0y < 0.999) return f;
  const double endx = -std::sin(f.sweep_rad) * e1x + std::cos(f.sweep_rad) * e2x;
  const double endy = -std::sin(f.sweep_rad) * e1y + std::cos(f.sweep_rad) * e2y;
  if (endx * g1x + endy * g1y < 0.999) return f;
  f.c_mm = {px, py, C[2]};
  f.e1 = {e1x, e1y, 0.0};
  f.e2 = {e2x, e2y, 0.0};
  f.R_mm = R;
  const double alpha = sigma * signed_angle2(e1x, e1y, C[0] - px, C[1] - py);
  f.split_rad = std::clamp(alpha, 0.1 * f.sweep_rad, 0.9 * f.sweep_rad);
  f.deviation_mm = alpha >= 0.0 && alpha <= f.sweep_rad
                       ? std::abs(std::hypot(C[0] - px, C[1] - py) - R)
                       : std::min(std::hypot(C[0] - t0x, C[1] - t0y), std::hypot(C[0] - t1x, C[1] - t1y));
  f.valid = true;
  return f;
}


}  // namespace

void MotionLimits::validate() const {
  auto positive = [](const char* name, const AxisArray<double>& v) {
    for (std::size_t a = 0; a < kNumAxes; ++a)
      if (!(v[a] > 0.0) || !std::isfinite(v[a]))
        throw ConfigError(fmt::format("motion limits: {}.{} = {} must be finite and > 0", axis_name(a), name, v[a]));
  };
  positive("v_max_mm_per_s", v_max_mm_per_s);
  positive("a_max_mm_per_s2", a_max_mm_per_s2);
  positive("j_max_mm_per_s3", j_max_mm_per_s3);
  if (!(default_blend_tolerance_mm >= 0.0) || !std::isfinite(default_blend_tolerance_mm))
    throw ConfigError(fmt::format("motion limits: default_blend_tolerance_mm = {} must be finite and >= 0",
                                  default_blend_tolerance_mm));
}

double Trajectory::duration_s() const noexcept { return duration_s_; }

std::int64_t Trajectory::num_ticks() const noexcept {
  // plan_trajectory keeps duration / Ts below kMaxTicks; the guard keeps the
  // cast defined for any state a Trajectory can be in.
  const double q = std::ceil(duration_s_ / Ts_s_);
  if (!(q < kMaxTicks)) return static_cast<std::int64_t>(kMaxTicks);
  auto k = static_cast<std::int64_t>(q);
  while (k > 0 && static_cast<double>(k - 1) * Ts_s_ >= duration_s_) --k;
  while (static_cast<double>(k) * Ts_s_ < duration_s_) ++k;
  return k;
}

void Trajectory::eval_segment(const Segment& seg, double t_s, AxisArray<double>& x_mm,
                              AxisArray<double>& v_mm_per_s) const {
  v_mm_per_s = {0.0, 0.0, 0.0};
  if (seg.kind == SegmentKind::kDwell || t_s >= seg.t_end_s) {
    x_mm = seg.end_mm;
    return;
  }
  if (t_s < seg.t_start_s || seg.num_pieces == 0) {
    x_mm = seg.start_mm;
    return;
  }
  const auto first = pieces_.begin() + static_cast<std::ptrdiff_t>(seg.first_piece);
  const auto last = first + static_cast<std::ptrdiff_t>(seg.num_pieces);
  auto it = std::upper_bound(first, last, t_s, [](double t, const LawPiece& p) { return t < p.t0_s; });
  if (it != first) --it;
  const double tau = t_s - it->t0_s;
  double s = it->s0_mm + it->v0_mm_per_s * tau + it->a0_mm_per_s2 * tau * tau / 2.0 +
             it->j_mm_per_s3 * tau * tau * tau / 6.0;
  double sdot = it->v0_mm_per_s + it->a0_mm_per_s2 * tau + it->j_mm_per_s3 * tau * tau / 2.0;
  s = std::clamp(s, 0.0, seg.length_mm);
  sdot = std::max(sdot, 0.0);
  if (seg.kind == SegmentKind::kLine) {
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      x_mm[a] = seg.start_mm[a] + seg.u[a] * s;
      v_mm_per_s[a] = seg.u[a] * sdot;
    }
    return;
  }
  if (seg.kind == SegmentKind::kBlend) {
    const double phi = seg.phi0_rad + s / seg.r0_mm;
    const double c = std::cos(phi), sn = std::sin(phi);
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      x_mm[a] = seg.c_mm[a] + seg.r0_mm * (c * seg.e1[a] + sn * seg.e2[a]);
      v_mm_per_s[a] = (c * seg.e2[a] - sn * seg.e1[a]) * sdot;
    }
    return;
  }
  const double lambda = s / seg.length_mm;
  const double dr = seg.r1_mm - seg.r0_mm;
  const double r = seg.r0_mm + dr * lambda;
  const double phi = seg.phi0_rad + seg.dphi_rad * lambda;
  const double c = std::cos(phi), sn = std::sin(phi);
  const double dz = seg.end_mm[2] - seg.start_mm[2];
  x_mm = {seg.cx_mm + r * c, seg.cy_mm + r * sn, seg.start_mm[2] + dz * lambda};
  const double k = sdot / seg.length_mm;
  v_mm_per_s = {(dr * c - r * seg.dphi_rad * sn) * k, (dr * sn + r * seg.dphi_rad * c) * k, dz * k};
}

ReferenceSample Trajectory::sample(std::int64_t k) const {
  return at_time(static_cast<double>(std::max<std::int64_t>(k, 0)) * Ts_s_);
}

ReferenceSample Trajectory::at_time(double t_s) const {
  ReferenceSample out;
  if (segments_.empty() || !(t_s < duration_s_)) {
    out.x_mm = end_mm_;
    out.spindle_rpm = segments_.empty() ? spindle_rpm_at_start_ : spindle_rpm_at_end_;
    out.done = true;
    return out;
  }
  auto it = std::upper_bound(segments_.begin(), segments_.end(), t_s,
                             [](double t, const Segment& s) { return t < s.t_start_s; });
  if (it == segments_.begin()) {
    out.x_mm = start_mm_;
    out.spindle_rpm = spindle_rpm_at_start_;
    return out;
  }
  --it;
  const Segment* reported = &*it;
  eval_segment(*reported, t_s, out.x_mm, out.v_mm_per_s);
  const auto& v = out.v_mm_per_s;
  out.path_speed_mm_per_s = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  out.feed_programmed_mm_per_s = reported->feed_mm_per_s;
  out.block = reported->block;
  out.spindle_rpm = reported->spindle_rpm;
  out.cutting_move = reported->cutting;
  return out;
}

void check_travel(const Program& program, const AxisArray<double>& travel_min_mm,
                  const AxisArray<double>& travel_max_mm) {
  // Points exactly one travel apart fit; the slack covers decimal
  // coordinates scaled by 25.4 (G20).
  constexpr double kSlack_mm = 1e-6;
  if (program.blocks.empty()) return;
  AxisArray<double> lo = program.blocks.front().start_mm, hi = lo;
  for (const Block& b : program.blocks) {
    AxisArray<double> reached_lo = b.end_mm, reached_hi = b.end_mm;
    if (b.kind == MotionKind::kArcCw || b.kind == MotionKind::kArcCcw) {
      // The extreme points of the circle in X and Y that the sweep passes.
      const double cx = b.center_mm[0], cy = b.center_mm[1];
      const double r0 = std::hypot(b.start_mm[0] - cx, b.start_mm[1] - cy);
      const double r1 = std::hypot(b.end_mm[0] - cx, b.end_mm[1] - cy);
      const double phi0 = std::atan2(b.start_mm[1] - cy, b.start_mm[0] - cx);
      double sweep = std::atan2(b.end_mm[1] - cy, b.end_mm[0] - cx) - phi0;
      const bool ccw = b.kind == MotionKind::kArcCcw;
      if (!ccw) sweep = -sweep;
      while (sweep <= 1e-9) sweep += 2.0 * kPi;
      for (int q = 0; q < 4; ++q) {
        const double theta = q * 0.5 * kPi;
        double delta = std::fmod(ccw ? theta - phi0 : phi0 - theta, 2.0 * kPi);
        if (delta < 0.0) delta += 2.0 * kPi;
        if (!(delta <= sweep)) continue;
        const double r = r0 + (r1 - r0) * delta / sweep;
        const AxisArray<double> p{cx + r * std::cos(theta), cy + r * std::sin(theta), 0.0};
        for (std::size_t a = 0; a < 2; ++a) {
          reached_lo[a] = std::min(reached_lo[a], p[a]);
          reached_hi[a] = std::max(reached_hi[a], p[a]);
        }
      }
    }
    for (std::size_t a = 0; a < kNumAxes; ++a) {
      lo[a] = std::min(lo[a], reached_lo[a]);
      hi[a] = std::max(hi[a], reached_hi[a]);
      const double span = travel_max_mm[a] - travel_min_mm[a];
      if (hi[a] - lo[a] <= span + kSlack_mm) continue;
      const double bad = reached_hi[a] >= hi[a] ? reached_hi[a] : reached_lo[a];
      throw ConfigError(fmt::format("{}:{}: the move takes {} to {:.6g} mm: the program then spans [{:.6g}, {:.6g}] mm "
                                    "in {}, more than the machine's travel of {:g} mm ([{:g}, {:g}])",
                                    program.source_name, b.line, axis_name(a), bad, lo[a], hi[a], axis_name(a),
                                    span, travel_min_mm[a], travel_max_mm[a]));
    }
  }
}

namespace {

ConfigError block_error(const Program& program, const Block& b, const std::string& what, const std::string& value) {
  return ConfigError(fmt::format("{}:{}: {} ({})", program.source_name, b.line, what, value));
}

/// The programmed moves (zero-length moves and zero dwells dropped) with
/// their path limits, in program order.
struct ProgrammedMoves {
  std::vector<Segment> moves;
  std::vector<PathLimits> lims;
};

/// A line or rapid: direction and path limits; false for a zero-length move.
bool plan_line(const Program& program, const Block& b, const MotionLimits& limits, Segment& s, PathLimits& pl) {
  AxisArray<double> d{};
  for (std::size_t a = 0; a < kNumAxes; ++a) d[a] = b.end_mm[a] - b.start_mm[a];
  s.length_mm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (!std::isfinite(s.length_mm))
    throw block_error(program, b, "move length is not finite", fmt::format("{:g} mm", s.length_mm));
  if (s.length_mm < kMinLength_mm) return false;
  s.kind = SegmentKind::kLine;
  s.u = normalized(d);
  pl.v_cap = std::min(s.feed_mm_per_s, min_over_axes(limits.v_max_mm_per_s, s.u));
  pl.a = min_over_axes(limits.a_max_mm_per_s2, s.u);
  pl.j = min_over_axes(limits.j_max_mm_per_s3, s.u);
  return true;
}

/// Signed sweep of an arc from phi0 to phi1 in its direction, in (0, 2 pi]
/// counter-clockwise and [-2 pi, 0) clockwise.
double arc_sweep_rad(double phi0, double phi1, bool ccw) {
  double d = phi1 - phi0;
  if (ccw) {
    while (d <= 1e-9) d += 2.0 * kPi;
    while (d > 2.0 * kPi + 1e-9) d -= 2.0 * kPi;
  } else {
    while (d >= -1e-9) d -= 2.0 * kPi;
    while (d < -2.0 * kPi - 1e-9) d += 2.0 * kPi;
  }
  return d;
}

/// An arc or helix: centre, radii, sweep and path limits.
PathLimits plan_arc(const Program& program, const Block& b, const MotionLimits& limits, Segment& s) {
  s.kind = SegmentKind::kArc;
  s.cx_mm = b.center_mm[0];
  s.cy_mm = b.center_mm[1];
  s.r0_mm = std::hypot(b.start_mm[0] - s.cx_mm, b.start_mm[1] - s.cy_mm);
  s.r1_mm = std::hypot(b.end_mm[0] - s.cx_mm, b.end_mm[1] - s.cy_mm);
  const std::string radii = fmt::format("r_start {:.6g} mm, r_end {:.6g} mm", s.r0_mm, s.r1_mm);
  if (!(s.r0_mm > 1e-9)) throw block_error(program, b, "arc radius must be > 0", radii);
  if (std::abs(s.r1_mm - s.r0_mm) > std::max(kArcRadiusTolerance_mm, kArcRadiusTolerance_rel * s.r0_mm))
    throw block_error(program, b, "arc end not on its circle", radii);
  s.phi0_rad = std::atan2(b.start_mm[1] - s.cy_mm, b.start_mm[0] - s.cx_mm);
  const double phi1 = std::atan2(b.end_mm[1] - s.cy_mm, b.end_mm[0] - s.cx_mm);
  const double d = arc_sweep_rad(s.phi0_rad, phi1, b.kind == MotionKind::kArcCcw);
  s.dphi_rad = d;
  const double R = 0.5 * (s.r0_mm + s.r1_mm);
  const double dz = b.end_mm[2] - b.start_mm[2];
  s.length_mm = std::hypot(R * std::abs(d), dz);
  if (!std::isfinite(s.length_mm)) throw block_error(program, b, "arc length is not finite", radii);
  // Helix: pitch per radian h, curvature k = R/(R^2+h^2), torsion tau = h/(R^2+h^2).
  const double h = dz / std::abs(d);
  const double ell2 = R * R + h * h;
  const double c_xy = R / std::sqrt(ell2);
  const double c_z = std::abs(h) / std::sqrt(ell2);
  double v_axes = std::min({s.feed_mm_per_s, limits.v_max_mm_per_s[0] / c_xy, limits.v_max_mm_per_s[1] / c_xy});
  if (c_z > 1e-15) v_axes = std::min(v_axes, limits.v_max_mm_per_s[2] / c_z);
  return arc_limits(R / ell2, std::abs(h) / ell2, v_axes, min_of(limits.a_max_mm_per_s2),
                    min_of(limits.j_max_mm_per_s3));
}

/// One block as a move; false when it moves nowhere (a zero-length move or a
/// zero dwell).
bool plan_move(const Program& program, std::size_t bi, const MotionLimits& limits, Segment& s, PathLimits& pl) {
  const Block& b = program.blocks[bi];
  for (std::size_t a = 0; a < kNumAxes; ++a)
    if (!std::isfinite(b.start_mm[a]) || !std::isfinite(b.end_mm[a]) || !std::isfinite(b.center_mm[a]))
      throw block_error(program, b, "non-finite coordinate", std::string(axis_name(a)));
  s.block = static_cast<int>(bi);
  s.start_mm = b.start_mm;
  s.end_mm = b.end_mm;
  s.spindle_rpm = b.spindle_rpm;
  s.feed_mm_per_s = b.feed_mm_per_min / kSPerMin;
  if (b.kind == MotionKind::kDwell) {
    if (!(b.dwell_s >= 0.0) || !std::isfinite(b.dwell_s))
      throw block_error(program, b, "dwell must be >= 0 s", fmt::format("{}", b.dwell_s));
    s.kind = SegmentKind::kDwell;
    s.feed_mm_per_s = 0.0;
    s.end_mm = s.start_mm;
    return b.dwell_s != 0.0;
  }
  if (!(b.feed_mm_per_min > 0.0) || !std::isfinite(b.feed_mm_per_min))
    throw block_error(program, b, "feed must be > 0", fmt::format("F{}", b.feed_mm_per_min));
  s.cutting = b.kind != MotionKind::kRapid;
  if (b.kind == MotionKind::kRapid || b.kind == MotionKind::kLinear) return plan_line(program, b, limits, s, pl);
  pl = plan_arc(program, b, limits, s);
  return true;
}

/// 1. Geometry and path limits of every programmed move.
ProgrammedMoves programmed_moves(const Program& program, const MotionLimits& limits) {
  ProgrammedMoves out;
  for (std::size_t bi = 0; bi < program.blocks.size(); ++bi) {
    Segment s;
    PathLimits pl;
    if (!plan_move(program, bi, limits, s, pl)) continue;
    out.moves.push_back(s);
    out.lims.push_back(pl);
  }
  return out;
}

/// Acceleration, jerk and speed limits of an arc whose plane is spanned by p
/// and q: the smallest of the axes it moves.
struct PlaneLimits {
  double a{0.0};
  double j{0.0};
  double v{0.0};
};

PlaneLimits plane_limits(const MotionLimits& limits, const AxisArray<double>& p, const AxisArray<double>& q) {
  AxisArray<double> a_lim{}, j_lim{}, v_lim{};
  for (std::size_t a = 0; a < kNumAxes; ++a) {
    const bool used = std::abs(p[a]) > 1e-12 || std::abs(q[a]) > 1e-12;
    const double inf = std::numeric_limits<double>::infinity();
    a_lim[a] = used ? limits.a_max_mm_per_s2[a] : inf;
    j_lim[a] = used ? limits.j_max_mm_per_s3[a] : inf;
    v_lim[a] = used ? limits.v_max_mm_per_s[a] : inf;
  }
  return {min_of(a_lim), min_of(j_lim), min_of(v_lim)};
}

/// The junctions between programmed moves (stop, pass-through or blend) and
/// the blend arcs of the blended ones.
struct Junctions {
  std::vector<Junction> at;
  std::vector<Fillet> fillets;
};

/// The line or planar curve of a move at one of its ends, for plane_fillet.
PlaneCurve plane_curve(const Segment& s, bool at_end) {
  PlaneCurve c;
  c.line = s.kind == SegmentKind::kLine;
  c.tx = s.u[0];
  c.ty = s.u[1];
  c.ox = s.cx_mm;
  c.oy = s.cy_mm;
  c.rho = at_end ? s.r1_mm : s.r0_mm;
  c.dir = s.dphi_rad >= 0.0 ? 1.0 : -1.0;
  return c;
}

/// The blend arc at a corner of turn J.turn_rad deviating at most P from it,
/// the smallest that lets v_both through; sets J to a blend when one fits.
Fillet plan_blend(const Segment& s0, const Segment& s1, double P, double v_both, const MotionLimits& limits,
                  Junction& J) {
  const AxisArray<double> t0 = exit_tangent(s0), t1 = entry_tangent(s1);
  const bool lines = s0.kind == SegmentKind::kLine && s1.kind == SegmentKind::kLine;
  // Axes the blend arc moves: its acceleration, jerk and speed limits.
  const PlaneLimits plane = plane_limits(limits, t0, t1);
  const double d0_max = 0.5 * s0.length_mm, d1_max = 0.5 * s1.length_mm;
  const AxisArray<double> C = s0.end_mm;
  std::function<Fillet(double)> make;
  double R_max = 0.0;
  const double R_tol = P * std::cos(0.5 * J.turn_rad) / (1.0 - std::cos(0.5 * J.turn_rad));
  if (lines) {
    make = [&](double R) { return line_line_fillet(C, s0.u, s1.u, J.turn_rad, R); };
    R_max = std::min(R_tol, std::min(d0_max, d1_max) / std::tan(0.5 * J.turn_rad));
  } else {
    const PlaneCurve c0 = plane_curve(s0, true), c1 = plane_curve(s1, false);
    const double sigma = cross2(t0[0], t0[1], t1[0], t1[1]) >= 0.0 ? 1.0 : -1.0;
    make = [&, c0, c1, sigma](double R) { return plane_fillet(c0, c1, C, sigma, R, d0_max, d1_max); };
    R_max = bisect_max(0.0, 4.0 * R_tol, [&](double R) {
      const Fillet f = make(R);
      return f.valid && f.deviation_mm <= P;
    });
  }
  // The smallest arc that lets the slower neighbour's speed through (a
  // larger one would only deviate more).
  const double R = std::min(R_max, radius_for_speed(v_both, plane.a, plane.j));
  if (!(R >= kMinBlendRadius_mm)) return Fillet{};
  Fillet f = make(R);
  if (!f.valid) return f;
  J.kind = JunctionKind::kBlend;
  J.v_mm_per_s = arc_limits(1.0 / R, 0.0, std::min(v_both, plane.v), plane.a, plane.j).v_cap;
  return f;
}

bool planar(const Segment& s) {
  return s.kind == SegmentKind::kLine ? std::abs(s.u[2]) < 1e-12 : s.end_mm[2] == s.start_mm[2];
}

/// 2. The junction after programmed move i: stop, pass-through, or blend.
void plan_junction(const Program& program, const ProgrammedMoves& pm, std::size_t i, const MotionLimits& limits,
                   double Ts_s, Junctions& out) {
  Junction& J = out.at[i];
  const Segment& s0 = pm.moves[i];
  const Segment& s1 = pm.moves[i + 1];
  const Block& b0 = program.blocks[static_cast<std::size_t>(s0.block)];
  const Block& b1 = program.blocks[static_cast<std::size_t>(s1.block)];
  if (s0.kind == SegmentKind::kDwell || s1.kind == SegmentKind::kDwell) return;
  J.turn_rad = angle_between(exit_tangent(s0), entry_tangent(s1));
  if (b0.kind == MotionKind::kRapid || b1.kind == MotionKind::kRapid || b0.exact_stop) return;
  const double v_both = std::min(pm.lims[i].v_cap, pm.lims[i + 1].v_cap);
  const bool lines = s0.kind == SegmentKind::kLine && s1.kind == SegmentKind::kLine;
  const bool blendable = lines || (planar(s0) && planar(s1));
  const double kink_limit_rad = blendable ? kKinkAngle_rad : kTangentAngle_rad;
  if (J.turn_rad <= kink_limit_rad) {
    J.kind = JunctionKind::kTangent;
    J.v_mm_per_s = J.turn_rad <= kCollinearAngle_rad
                       ? v_both
                       : std::min(v_both, 0.5 * min_of(limits.a_max_mm_per_s2) * Ts_s / J.turn_rad);
    return;
  }
  if (!blendable || b0.exact_path || J.turn_rad > kMaxBlendTurn_rad) return;
  const double P = b0.blend_tolerance_mm > 0.0 ? b0.blend_tolerance_mm : limits.default_blend_tolerance_mm;
  if (!(P > 0.0)) return;
  out.fillets[i] = plan_blend(s0, s1, P, v_both, limits, J);
}

Junctions plan_junctions(const Program& program, const ProgrammedMoves& pm, const MotionLimits& limits,
                         double Ts_s) {
  const std::size_t nm = pm.moves.size();
  Junctions out;
  out.at.resize(nm > 0 ? nm - 1 : 0);
  out.fillets.resize(out.at.size());
  for (std::size_t i = 0; i + 1 < nm; ++i) plan_junction(program, pm, i, limits, Ts_s, out);
  return out;
}

/// One half of the blend arc of fillet f: the first reports the block before
/// (owner: the move before), the second the block after.
Segment blend_half(const Fillet& f, const Segment& owner, bool second) {
  Segment h = owner;
  h.kind = SegmentKind::kBlend;
  h.c_mm = f.c_mm;
  h.e1 = f.e1;
  h.e2 = f.e2;
  h.r0_mm = h.r1_mm = f.R_mm;
  h.phi0_rad = second ? f.split_rad : 0.0;
  h.dphi_rad = second ? f.sweep_rad - f.split_rad : f.split_rad;
  h.length_mm = f.R_mm * h.dphi_rad;
  for (std::size_t a = 0; a < kNumAxes; ++a) {
    h.start_mm[a] = f.c_mm[a] + f.R_mm * (std::cos(h.phi0_rad) * f.e1[a] + std::sin(h.phi0_rad) * f.e2[a]);
    const double p1 = h.phi0_rad + h.dphi_rad;
    h.end_mm[a] = f.c_mm[a] + f.R_mm * (std::cos(p1) * f.e1[a] + std::sin(p1) * f.e2[a]);
  }
  return h;
}

/// A programmed move shortened by d_in at its start and d_out at its end (the
/// blends there).
void trim_move(Segment& m, double d_in, double d_out, bool blend_out) {
  if (m.kind == SegmentKind::kLine) {
    m.start_mm = axpy(m.start_mm, d_in, m.u);
    if (blend_out) m.end_mm = axpy(m.end_mm, -d_out, m.u);
    m.length_mm -= d_in + d_out;
  } else if (m.kind == SegmentKind::kArc && (d_in > 0.0 || d_out > 0.0)) {
    // Planar arc: trim by angle, keeping the radius law r(lambda).
    const double L = m.length_mm;
    const double l0 = d_in / L, l1 = 1.0 - d_out / L;
    const double r0 = m.r0_mm + (m.r1_mm - m.r0_mm) * l0, r1 = m.r0_mm + (m.r1_mm - m.r0_mm) * l1;
    m.phi0_rad += m.dphi_rad * l0;
    m.dphi_rad *= (l1 - l0);
    m.r0_mm = r0;
    m.r1_mm = r1;
    m.length_mm = 0.5 * (r0 + r1) * std::abs(m.dphi_rad);
    m.start_mm = {m.cx_mm + r0 * std::cos(m.phi0_rad), m.cy_mm + r0 * std::sin(m.phi0_rad), m.start_mm[2]};
    if (blend_out) {
      const double p1 = m.phi0_rad + m.dphi_rad;
      m.end_mm = {m.cx_mm + r1 * std::cos(p1), m.cy_mm + r1 * std::sin(p1), m.end_mm[2]};
    }
  }
}

/// The planned moves in time order with their limits and the junctions
/// between them; corner_seg[i] is, for the junction after programmed move i,
/// the second half of its blend or else the first segment after it.
class PlannedPath {
 public:
  std::vector<Segment> segs;
  std::vector<PathLimits> lims;
  std::vector<Junction> junc;
  std::vector<std::size_t> corner_seg;

  /// The next segment, after a junction of the kind set by pass() (a
  /// tangent one with no cap of its own between pieces of one move).
  void push(const Segment& s, const PathLimits& pl) {
    if (!segs.empty()) {
      Junction J;
      J.kind = pending_;
      J.turn_rad = pending_turn_;
      J.v_mm_per_s = pending_ == JunctionKind::kStop ? 0.0 : pending_v_;  // capped by both neighbours later
      junc.push_back(J);
    }
    segs.push_back(s);
    lims.push_back(pl);
    pending_ = JunctionKind::kTangent;
    pending_v_ = std::numeric_limits<double>::infinity();
    pending_turn_ = 0.0;
  }
  /// The next segment starts after programmed junction J (a blend's second
  /// half follows its first tangentially).
  void pass(const Junction& J) {
    pending_ = J.kind == JunctionKind::kBlend ? JunctionKind::kTangent : J.kind;
    pending_v_ = J.kind == JunctionKind::kTangent ? J.v_mm_per_s : std::numeric_limits<double>::infinity();
    pending_turn_ = J.kind == JunctionKind::kTangent ? J.turn_rad : 0.0;
  }

 private:
  JunctionKind pending_{JunctionKind::kStop};
  double pending_v_{0.0};
  double pending_turn_{0.0};
};

/// 3. Each programmed move trimmed by the blends at its ends, each blend arc
/// split in two halves, and the junctions between them.
PlannedPath assemble_path(const ProgrammedMoves& pm, const Junctions& jn) {
  const std::size_t nm = pm.moves.size();
  const std::vector<Junction>& mj = jn.at;
  PlannedPath path;
  path.corner_seg.assign(mj.size(), 0);
  for (std::size_t i = 0; i < nm; ++i) {
    const bool blend_in = i > 0 && mj[i - 1].kind == JunctionKind::kBlend;
    const bool blend_out = i + 1 < nm && mj[i].kind == JunctionKind::kBlend;
    if (i > 0) {
      path.pass(mj[i - 1]);
      path.corner_seg[i - 1] = path.segs.size();
    }
    Segment m = pm.moves[i];
    const double d_in = blend_in ? jn.fillets[i - 1].d1_mm : 0.0;
    const double d_out = blend_out ? jn.fillets[i].d0_mm : 0.0;
    if (blend_in) path.push(blend_half(jn.fillets[i - 1], pm.moves[i], true), PathLimits{});
    trim_move(m, d_in, d_out, blend_out);
    if (m.kind == SegmentKind::kDwell || m.length_mm >= kMinLength_mm) path.push(m, pm.lims[i]);
    if (blend_out) path.push(blend_half(jn.fillets[i], pm.moves[i], false), PathLimits{});
  }
  return path;
}

/// Blend halves get the limits of their arc; every pass-through junction is
/// capped by both neighbours' speed caps.
void limit_path(PlannedPath& path, const MotionLimits& limits) {
  const std::size_t n = path.segs.size();
  for (std::size_t k = 0; k < n; ++k) {
    const Segment& s = path.segs[k];
    if (s.kind != SegmentKind::kBlend) continue;
    // The axes of the arc's plane (spanned by e1 and e2).
    const PlaneLimits plane = plane_limits(limits, s.e1, s.e2);
    path.lims[k] = arc_limits(1.0 / s.r0_mm, 0.0, std::min(s.feed_mm_per_s, plane.v), plane.a, plane.j);
  }
  for (std::size_t k = 0; k + 1 < n; ++k) {
    Junction& J = path.junc[k];
    if (J.kind == JunctionKind::kStop) continue;
    J.v_mm_per_s = std::min({J.v_mm_per_s, path.lims[k].v_cap, path.lims[k + 1].v_cap});
  }
}

double v_in(const PlannedPath& path, std::size_t i) { return i == 0 ? 0.0 : path.junc[i - 1].v_mm_per_s; }
double v_out(const PlannedPath& path, std::size_t i) {
  return i + 1 == path.segs.size() ? 0.0 : path.junc[i].v_mm_per_s;
}

/// 4. Look-ahead over the whole program: a backward and a forward pass over
/// the pass-through junction speeds.
void look_ahead(PlannedPath& path) {
  const std::size_t n = path.segs.size();
  auto& junc = path.junc;
  for (std::size_t i = n - 1; n > 1 && i-- > 0;) {
    if (junc[i].kind == JunctionKind::kStop) continue;
    const PathLimits& pl = path.lims[i + 1];
    junc[i].v_mm_per_s = std::min(
        junc[i].v_mm_per_s, reachable_speed(v_out(path, i + 1), path.segs[i + 1].length_mm, pl.a, pl.j, pl.v_cap));
  }
  for (std::size_t i = 0; i + 1 < n; ++i) {
    if (junc[i].kind == JunctionKind::kStop) continue;
    const PathLimits& pl = path.lims[i];
    junc[i].v_mm_per_s =
        std::min(junc[i].v_mm_per_s, reachable_speed(v_in(path, i), path.segs[i].length_mm, pl.a, pl.j, pl.v_cap));
  }
}

/// The jerk-limited law of one move from v0 to v1 within its length, as fast
/// as its limits allow; returns its duration.
double move_law(std::vector<LawPiece>& pieces, double t_s, double L, double v0, double v1, const PathLimits& pl) {
  const double v_top = std::max({v0, v1, pl.v_cap});
  auto needed = [&](double v) { return transition_distance(v0, v, pl.a, pl.j) + transition_distance(v, v1, pl.a, pl.j); };
  TWIN_DEMAND(needed(std::max(v0, v1)) <= L + 1e-9 * std::max(1.0, L));
  const double peak = bisect_max(std::max(v0, v1), v_top, [&](double v) { return needed(v) <= L; });
  LawBuilder law(pieces, t_s, v0);
  law.transition_to(peak, pl.a, pl.j);
  law.cruise(L - needed(peak));
  law.transition_to(v1, pl.a, pl.j);
  return law.t_s() - t_s;
}

/// 5. Time laws, one after the other; returns the program's duration.
double time_laws(const Program& program, PlannedPath& path, double Ts_s, std::vector<LawPiece>& pieces) {
  double t_s = 0.0;
  for (std::size_t i = 0; i < path.segs.size(); ++i) {
    Segment& s = path.segs[i];
    const Block& b = program.blocks[static_cast<std::size_t>(s.block)];
    s.first_piece = pieces.size();
    s.t_start_s = t_s;
    const double duration_s = s.kind == SegmentKind::kDwell
                                  ? b.dwell_s
                                  : move_law(pieces, t_s, s.length_mm, v_in(path, i), v_out(path, i), path.lims[i]);
    s.t_end_s = t_s + duration_s;
    if (!std::isfinite(duration_s))
      throw ConfigError(fmt::format("{}:{}: the planned duration of this move is not finite ({} s)",
                                    program.source_name, b.line, duration_s));
    if (!(s.t_end_s / Ts_s < kMaxTicks))
      throw ConfigError(fmt::format("{}:{}: the program's planned duration reaches {:.6g} s here, {:.3g} ticks of "
                                    "{} s: more than a run can count",
                                    program.source_name, b.line, s.t_end_s, s.t_end_s / Ts_s, Ts_s));
    s.num_pieces = pieces.size() - s.first_piece;
    t_s = s.t_end_s;
  }
  return t_s;
}

/// 6. Each block's start, end, length and programmed feed.
std::vector<BlockTiming> block_timings(const Program& program, const std::vector<Segment>& S) {
  const auto& blocks = program.blocks;
  std::vector<BlockTiming> out(blocks.size());
  double cursor_s = 0.0;
  std::size_t next_seg = 0;
  for (std::size_t bi = 0; bi < blocks.size(); ++bi) {
    BlockTiming& bt = out[bi];
    bt.feed_programmed_mm_per_s = blocks[bi].kind == MotionKind::kDwell ? 0.0 : blocks[bi].feed_mm_per_min / kSPerMin;
    bt.t_start_s = bt.t_end_s = cursor_s;
    bool first = true;
    while (next_seg < S.size() && S[next_seg].block == static_cast<int>(bi)) {
      const Segment& s = S[next_seg++];
      if (first) bt.t_start_s = s.t_start_s;
      first = false;
      bt.t_end_s = s.t_end_s;
      bt.length_mm += s.length_mm;
      cursor_s = s.t_end_s;
    }
  }
  return out;
}

/// The corner between programmed move i and the next move k that is not a
/// dwell, when it turns by more than kCornerReportAngle_deg.
std::optional<Corner> corner_after(const Trajectory& traj, const ProgrammedMoves& pm, const Junctions& jn,
                                   const std::vector<std::size_t>& corner_seg, std::size_t i, std::size_t k) {
  const auto& S = traj.segments();
  const Segment& s0 = pm.moves[i];
  const Segment& s1 = pm.moves[k];
  const bool dwell_between = k > i + 1;
  const double turn = angle_between(exit_tangent(s0), entry_tangent(s1));
  if (turn * kDegPerRad <= kCornerReportAngle_deg) return std::nullopt;
  Corner c;
  c.block_before = s0.block;
  c.block_after = s1.block;
  c.turn_angle_deg = turn * kDegPerRad;
  c.p_mm = s0.end_mm;
  const Junction& J = jn.at[i];
  c.exact_stop = dwell_between || J.kind == JunctionKind::kStop;
  const std::size_t at = corner_seg[i];
  c.t_s = at < S.size() ? S[at].t_start_s : traj.duration_s();
  c.t_blend_begin_s = c.t_blend_end_s = c.t_s;
  if (!dwell_between && J.kind == JunctionKind::kBlend) {
    c.blend_radius_mm = jn.fillets[i].R_mm;
    c.t_blend_begin_s = S[at - 1].t_start_s;
    c.t_blend_end_s = S[at].t_end_s;
  } else if (dwell_between) {
    c.t_s = S[at - 1].t_end_s;  // before the dwell
    c.t_blend_begin_s = c.t_blend_end_s = c.t_s;
  }
  const ReferenceSample r = traj.at_time(c.t_s);
  c.v_ref_mm_per_s = dwell_between ? 0.0 : r.path_speed_mm_per_s;
  c.deviation_mm =
      J.kind == JunctionKind::kBlend && !dwell_between ? jn.fillets[i].deviation_mm : norm3(r.x_mm - c.p_mm);
  return c;
}

/// 6. The corners of the program, in order.
std::vector<Corner> find_corners(const Trajectory& traj, const ProgrammedMoves& pm, const Junctions& jn,
                                 const std::vector<std::size_t>& corner_seg) {
  std::vector<Corner> out;
  const std::size_t nm = pm.moves.size();
  for (std::size_t i = 0; i + 1 < nm; ++i) {
    if (pm.moves[i].kind == SegmentKind::kDwell) continue;
    std::size_t k = i + 1;
    while (k < nm && pm.moves[k].kind == SegmentKind::kDwell) ++k;
    if (k >= nm) break;
    if (auto c = corner_after(traj, pm, jn, corner_seg, i, k)) out.push_back(*c);
  }
  return out;
}

}  // namespace

Trajectory plan_trajectory(const Program& program, const MotionLimits& limits, double Ts_s) {
  limits.validate();
  if (!(Ts_s > 0.0) || !std::isfinite(Ts_s))
    throw ConfigError(fmt::format("{}: sample period Ts = {} s must be > 0", program.source_name, Ts_s));
  Trajectory traj;
  traj.Ts_s_ = Ts_s;
  const auto& blocks = program.blocks;
  if (!blocks.empty()) {
    traj.start_mm_ = blocks.front().start_mm;
    traj.end_mm_ = blocks.back().end_mm;
    traj.spindle_rpm_at_start_ = blocks.front().spindle_rpm;
  }
  traj.spindle_rpm_at_end_ = program.spindle_rpm_at_end;

  const ProgrammedMoves pm = programmed_moves(program, limits);
  const Junctions jn = plan_junctions(program, pm, limits, Ts_s);
  PlannedPath path = assemble_path(pm, jn);
  limit_path(path, limits);
  look_ahead(path);
  traj.duration_s_ = time_laws(program, path, Ts_s, traj.pieces_);
  traj.segments_ = std::move(path.segs);
  traj.block_timings_ = block_timings(program, traj.segments_);
  traj.corners_ = find_corners(traj, pm, jn, path.corner_seg);
  return traj;
}

}  // namespace twin::controller
