#include "controller/interpolator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "twin/core/check.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::controller {
namespace {

/// Junctions that involve an arc and turn by at most this much are passed
/// without stopping; the velocity step v*theta is kept below 0.5 a_max Ts.
constexpr double kTangentAngle_rad = 0.5 * kRadPerDeg;
/// Straight-on line junctions below this turn need no blend at all.
constexpr double kCollinearAngle_rad = 1e-9;
/// Corners reported by Trajectory::corners().
constexpr double kCornerReportAngle_deg = 1.0;
/// On arcs the centripetal part may use this share of the acceleration
/// limit, the tangential part the rest; the jerk is split in three
/// (tangential, centripetal rotation v^3 k^2, coupling 3 v a_t k).
constexpr double kArcAccelShare = 0.5;
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

/// The tail of a stop from speed v (or, mirrored, the head of a start): the
/// time before rest over which its shape does not depend on v,
/// v/a (trapezoidal acceleration) or sqrt(v/j) (triangular).
double symmetric_tail_s(double v, double a, double j) {
  return v * j >= a * a ? v / a : std::sqrt(v / j);
}

/// Speed and distance to go at time tau before rest, inside the tail:
/// v = j tau^2/2, d = j tau^3/6 in the jerk phase (tau <= a/j), then the
/// constant-deceleration phase.
void tail_at(double tau, double a, double j, double& v, double& d) {
  const double Tj = a / j;
  if (tau <= Tj) {
    v = 0.5 * j * tau * tau;
    d = j * tau * tau * tau / 6.0;
    return;
  }
  const double u = tau - Tj;
  v = 0.5 * a * Tj + a * u;
  d = a * Tj * Tj / 6.0 + 0.5 * a * Tj * u + 0.5 * a * u * u;
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
  double a_blend{0.0}, j_blend{0.0};  // limits of the overlapping stop/start ramps
  double tolerance_mm{0.0};
  double overlap_s{0.0};              // time the two moves run together
};

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

AxisArray<double> entry_tangent(const Segment& s) { return s.kind == SegmentKind::kLine ? s.u : arc_tangent(s, 0.0); }
AxisArray<double> exit_tangent(const Segment& s) { return s.kind == SegmentKind::kLine ? s.u : arc_tangent(s, 1.0); }

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
  if (t_s <= seg.t_start_s || seg.num_pieces == 0) {
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
  const Segment* current = &*it;
  eval_segment(*current, t_s, out.x_mm, out.v_mm_per_s);
  const Segment* reported = current;
  if (it != segments_.begin()) {
    const Segment& prev = *(it - 1);
    if (prev.kind == SegmentKind::kLine && t_s < prev.t_end_s) {
      AxisArray<double> xp{}, vp{};
      eval_segment(prev, t_s, xp, vp);
      for (std::size_t a = 0; a < kNumAxes; ++a) {
        out.x_mm[a] += xp[a] - prev.end_mm[a];
        out.v_mm_per_s[a] += vp[a];
      }
      if (t_s < current->t_switch_s) reported = &prev;
    }
  }
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
  const double a_min = min_of(limits.a_max_mm_per_s2);
  const double j_min = min_of(limits.j_max_mm_per_s3);

  // 1. Geometry and path limits of every move (zero-length moves are dropped).
  std::vector<Segment> segs;
  std::vector<PathLimits> lims;
  for (std::size_t bi = 0; bi < blocks.size(); ++bi) {
    const Block& b = blocks[bi];
    auto where = [&](const std::string& what, const std::string& value) {
      return ConfigError(fmt::format("{}:{}: {} ({})", program.source_name, b.line, what, value));
    };
    for (std::size_t a = 0; a < kNumAxes; ++a)
      if (!std::isfinite(b.start_mm[a]) || !std::isfinite(b.end_mm[a]) || !std::isfinite(b.center_mm[a]))
        throw where("non-finite coordinate", std::string(axis_name(a)));
    Segment s;
    s.block = static_cast<int>(bi);
    s.start_mm = b.start_mm;
    s.end_mm = b.end_mm;
    s.spindle_rpm = b.spindle_rpm;
    s.feed_mm_per_s = b.feed_mm_per_min / kSPerMin;
    PathLimits pl;
    if (b.kind == MotionKind::kDwell) {
      if (!(b.dwell_s >= 0.0) || !std::isfinite(b.dwell_s)) throw where("dwell must be >= 0 s", fmt::format("{}", b.dwell_s));
      if (b.dwell_s == 0.0) continue;
      s.kind = SegmentKind::kDwell;
      s.feed_mm_per_s = 0.0;
      s.end_mm = s.start_mm;
      segs.push_back(s);
      lims.push_back(pl);
      continue;
    }
    if (!(b.feed_mm_per_min > 0.0) || !std::isfinite(b.feed_mm_per_min))
      throw where("feed must be > 0", fmt::format("F{}", b.feed_mm_per_min));
    s.cutting = b.kind != MotionKind::kRapid;
    if (b.kind == MotionKind::kRapid || b.kind == MotionKind::kLinear) {
      AxisArray<double> d{};
      for (std::size_t a = 0; a < kNumAxes; ++a) d[a] = b.end_mm[a] - b.start_mm[a];
      s.length_mm = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      if (!std::isfinite(s.length_mm)) throw where("move length is not finite", fmt::format("{:g} mm", s.length_mm));
      if (s.length_mm < kMinLength_mm) continue;
      s.kind = SegmentKind::kLine;
      s.u = normalized(d);
      pl.v_cap = std::min(s.feed_mm_per_s, min_over_axes(limits.v_max_mm_per_s, s.u));
      pl.a = min_over_axes(limits.a_max_mm_per_s2, s.u);
      pl.j = min_over_axes(limits.j_max_mm_per_s3, s.u);
    } else {
      s.kind = SegmentKind::kArc;
      s.cx_mm = b.center_mm[0];
      s.cy_mm = b.center_mm[1];
      s.r0_mm = std::hypot(b.start_mm[0] - s.cx_mm, b.start_mm[1] - s.cy_mm);
      s.r1_mm = std::hypot(b.end_mm[0] - s.cx_mm, b.end_mm[1] - s.cy_mm);
      const std::string radii = fmt::format("r_start {:.6g} mm, r_end {:.6g} mm", s.r0_mm, s.r1_mm);
      if (!(s.r0_mm > 1e-9)) throw where("arc radius must be > 0", radii);
      if (std::abs(s.r1_mm - s.r0_mm) > std::max(kArcRadiusTolerance_mm, kArcRadiusTolerance_rel * s.r0_mm))
        throw where("arc end not on its circle", radii);
      s.phi0_rad = std::atan2(b.start_mm[1] - s.cy_mm, b.start_mm[0] - s.cx_mm);
      const double phi1 = std::atan2(b.end_mm[1] - s.cy_mm, b.end_mm[0] - s.cx_mm);
      double d = phi1 - s.phi0_rad;
      if (b.kind == MotionKind::kArcCcw) {
        while (d <= 1e-9) d += 2.0 * kPi;
        while (d > 2.0 * kPi + 1e-9) d -= 2.0 * kPi;
      } else {
        while (d >= -1e-9) d -= 2.0 * kPi;
        while (d < -2.0 * kPi - 1e-9) d += 2.0 * kPi;
      }
      s.dphi_rad = d;
      const double R = 0.5 * (s.r0_mm + s.r1_mm);
      const double dz = b.end_mm[2] - b.start_mm[2];
      s.length_mm = std::hypot(R * std::abs(d), dz);
      if (!std::isfinite(s.length_mm)) throw where("arc length is not finite", radii);
      // Helix: pitch per radian h, curvature k = R/(R^2+h^2), torsion tau = h/(R^2+h^2).
      const double h = dz / std::abs(d);
      const double ell2 = R * R + h * h;
      const double kappa = R / ell2;
      const double torsion = std::abs(h) / ell2;
      const double c_xy = R / std::sqrt(ell2);
      const double c_z = std::abs(h) / std::sqrt(ell2);
      double v_cap = std::min({s.feed_mm_per_s, limits.v_max_mm_per_s[0] / c_xy, limits.v_max_mm_per_s[1] / c_xy});
      if (c_z > 1e-15) v_cap = std::min(v_cap, limits.v_max_mm_per_s[2] / c_z);
      v_cap = std::min(v_cap, std::sqrt(kArcAccelShare * a_min / kappa));
      v_cap = std::min(v_cap, std::cbrt(kArcJerkShare * j_min / (kappa * (kappa + torsion))));
      pl.v_cap = v_cap;
      pl.a = std::min((1.0 - kArcAccelShare) * a_min, kArcJerkShare * j_min / (3.0 * v_cap * kappa));
      pl.j = kArcJerkShare * j_min;
    }
    segs.push_back(s);
    lims.push_back(pl);
  }
  const std::size_t n = segs.size();

  // 2. Junctions: stop, tangent pass-through, or blended corner (G64, lines).
  std::vector<Junction> junc(n > 0 ? n - 1 : 0);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    Junction& J = junc[i];
    const Segment& s0 = segs[i];
    const Segment& s1 = segs[i + 1];
    const Block& b0 = blocks[static_cast<std::size_t>(s0.block)];
    const Block& b1 = blocks[static_cast<std::size_t>(s1.block)];
    if (s0.kind == SegmentKind::kDwell || s1.kind == SegmentKind::kDwell) continue;
    J.turn_rad = angle_between(exit_tangent(s0), entry_tangent(s1));
    if (b0.kind == MotionKind::kRapid || b1.kind == MotionKind::kRapid || b0.exact_stop) continue;
    const double v_both = std::min(lims[i].v_cap, lims[i + 1].v_cap);
    if (J.turn_rad <= kCollinearAngle_rad) {
      J.kind = JunctionKind::kTangent;
      J.v_mm_per_s = v_both;
    } else if (s0.kind == SegmentKind::kLine && s1.kind == SegmentKind::kLine) {
      // Both moves stop/start here; their ramps overlap in time. While both
      // run, axis a sees at most a_r (|u0_a| + |u1_a|).
      J.kind = JunctionKind::kBlend;
      AxisArray<double> sum{};
      for (std::size_t a = 0; a < kNumAxes; ++a) sum[a] = std::abs(s1.u[a]) + std::abs(s0.u[a]);
      J.a_blend = min_over_axes(limits.a_max_mm_per_s2, sum);
      J.j_blend = min_over_axes(limits.j_max_mm_per_s3, sum);
      J.tolerance_mm = b0.blend_tolerance_mm > 0.0 ? b0.blend_tolerance_mm : limits.default_blend_tolerance_mm;
    } else if (J.turn_rad <= kTangentAngle_rad) {
      J.kind = JunctionKind::kTangent;
      J.v_mm_per_s = std::min(v_both, 0.5 * a_min * Ts_s / J.turn_rad);
    }
  }

  // 3. Look-ahead: backward and forward passes over the junction speeds.
  // A move's end next to a blend uses the blend limits; the passes use the
  // smaller of those and the move's own, which keeps every law feasible.
  auto end_limits = [&](std::size_t i, const Junction* J) {
    if (J && J->kind == JunctionKind::kBlend) return PathLimits{lims[i].v_cap, J->a_blend, J->j_blend};
    return lims[i];
  };
  std::vector<PathLimits> pass_lims(lims);
  for (std::size_t i = 0; i < n; ++i) {
    for (const Junction* J : {i > 0 ? &junc[i - 1] : nullptr, i + 1 < n ? &junc[i] : nullptr}) {
      if (!J || J->kind != JunctionKind::kBlend) continue;
      pass_lims[i].a = std::min(pass_lims[i].a, J->a_blend);
      pass_lims[i].j = std::min(pass_lims[i].j, J->j_blend);
    }
  }
  auto v_in = [&](std::size_t i) { return i == 0 ? 0.0 : junc[i - 1].v_mm_per_s; };
  auto v_out = [&](std::size_t i) { return i + 1 == n ? 0.0 : junc[i].v_mm_per_s; };
  for (std::size_t i = n - 1; n > 1 && i-- > 0;) {
    if (junc[i].kind != JunctionKind::kTangent) continue;
    const PathLimits& pl = pass_lims[i + 1];
    junc[i].v_mm_per_s =
        std::min(junc[i].v_mm_per_s, reachable_speed(v_out(i + 1), segs[i + 1].length_mm, pl.a, pl.j, pl.v_cap));
  }
  for (std::size_t i = 0; i + 1 < n; ++i) {
    if (junc[i].kind != JunctionKind::kTangent) continue;
    const PathLimits& pl = pass_lims[i];
    junc[i].v_mm_per_s = std::min(junc[i].v_mm_per_s, reachable_speed(v_in(i), segs[i].length_mm, pl.a, pl.j, pl.v_cap));
  }

  // 4. Time laws, first each on its own clock starting at 0.
  std::vector<double> peak(n, 0.0), own_duration(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    Segment& s = segs[i];
    s.first_piece = traj.pieces_.size();
    if (s.kind == SegmentKind::kDwell) {
      own_duration[i] = blocks[static_cast<std::size_t>(s.block)].dwell_s;
      continue;
    }
    const PathLimits first = end_limits(i, i > 0 ? &junc[i - 1] : nullptr);
    const PathLimits last = end_limits(i, i + 1 < n ? &junc[i] : nullptr);
    const double L = s.length_mm;
    const double v0 = v_in(i), v1 = v_out(i);
    const double v_top = std::max({v0, v1, lims[i].v_cap});
    auto needed = [&](double v) {
      return transition_distance(v0, v, first.a, first.j) + transition_distance(v, v1, last.a, last.j);
    };
    TWIN_DEMAND(needed(std::max(v0, v1)) <= L + 1e-9 * std::max(1.0, L));
    peak[i] = bisect_max(std::max(v0, v1), v_top, [&](double v) { return needed(v) <= L; });
    LawBuilder law(traj.pieces_, 0.0, v0);
    law.transition_to(peak[i], first.a, first.j);
    law.cruise(L - needed(peak[i]));
    law.transition_to(v1, last.a, last.j);
    own_duration[i] = law.t_s();
  }
  // Overlap of blended corners: the largest T_b within the tolerance,
  // 2 sin(theta/2) d(T_b/2) <= T, and within the symmetric tails of both.
  for (std::size_t i = 0; i + 1 < n; ++i) {
    Junction& J = junc[i];
    if (J.kind != JunctionKind::kBlend) continue;
    const double T_max = std::min(symmetric_tail_s(peak[i], J.a_blend, J.j_blend),
                                  symmetric_tail_s(peak[i + 1], J.a_blend, J.j_blend));
    const double dev_per_d = 2.0 * std::sin(0.5 * J.turn_rad);
    J.overlap_s = bisect_max(0.0, T_max, [&](double T_b) {
      double v = 0.0, d = 0.0;
      tail_at(0.5 * T_b, J.a_blend, J.j_blend, v, d);
      return dev_per_d * d <= J.tolerance_mm;
    });
  }
  // Absolute times.
  double t_s = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    Segment& s = segs[i];
    const double T_in = (i > 0 && junc[i - 1].kind == JunctionKind::kBlend) ? junc[i - 1].overlap_s : 0.0;
    s.t_start_s = std::max(0.0, t_s - T_in);
    s.t_switch_s = s.t_start_s + 0.5 * T_in;
    s.t_end_s = s.t_start_s + own_duration[i];
    const int line = blocks[static_cast<std::size_t>(s.block)].line;
    if (!std::isfinite(own_duration[i]))
      throw ConfigError(fmt::format("{}:{}: the planned duration of this move is not finite ({} s)",
                                    program.source_name, line, own_duration[i]));
    if (!(s.t_end_s / Ts_s < kMaxTicks))
      throw ConfigError(fmt::format("{}:{}: the program's planned duration reaches {:.6g} s here, {:.3g} ticks of "
                                    "{} s: more than a run can count",
                                    program.source_name, line, s.t_end_s, s.t_end_s / Ts_s, Ts_s));
    s.num_pieces = traj.pieces_.size() - s.first_piece;
    if (i + 1 < n) s.num_pieces = segs[i + 1].first_piece - s.first_piece;
    for (std::size_t p = s.first_piece; p < s.first_piece + s.num_pieces; ++p) traj.pieces_[p].t0_s += s.t_start_s;
    t_s = s.t_end_s;
  }
  traj.duration_s_ = t_s;
  traj.segments_ = std::move(segs);

  // 5. Block timings and corners.
  traj.block_timings_.resize(blocks.size());
  double cursor_s = 0.0;
  std::size_t next_seg = 0;
  for (std::size_t bi = 0; bi < blocks.size(); ++bi) {
    BlockTiming& bt = traj.block_timings_[bi];
    bt.feed_programmed_mm_per_s = blocks[bi].kind == MotionKind::kDwell ? 0.0 : blocks[bi].feed_mm_per_min / kSPerMin;
    if (next_seg < n && traj.segments_[next_seg].block == static_cast<int>(bi)) {
      const Segment& s = traj.segments_[next_seg++];
      bt.t_start_s = s.t_start_s;
      bt.t_end_s = s.t_end_s;
      bt.length_mm = s.length_mm;
      cursor_s = s.t_end_s;
    } else {
      bt.t_start_s = bt.t_end_s = cursor_s;
    }
  }
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const Segment& s0 = traj.segments_[i];
    if (s0.kind == SegmentKind::kDwell) continue;
    std::size_t k = i + 1;
    bool dwell_between = false;
    while (k < n && traj.segments_[k].kind == SegmentKind::kDwell) {
      dwell_between = true;
      ++k;
    }
    if (k >= n) break;
    const Segment& s1 = traj.segments_[k];
    const double turn = angle_between(exit_tangent(s0), entry_tangent(s1));
    if (turn * kDegPerRad <= kCornerReportAngle_deg) continue;
    Corner c;
    c.block_before = s0.block;
    c.block_after = s1.block;
    c.turn_angle_deg = turn * kDegPerRad;
    c.p_mm = s0.end_mm;
    const Junction& J = junc[i];
    c.exact_stop = dwell_between || J.kind == JunctionKind::kStop;
    if (!dwell_between && J.kind == JunctionKind::kBlend) {
      c.t_s = s1.t_switch_s;
      c.v_ref_mm_per_s = traj.at_time(c.t_s).path_speed_mm_per_s;
      c.exact_stop = J.overlap_s == 0.0;
    } else {
      c.t_s = s0.t_end_s;
      c.v_ref_mm_per_s = dwell_between ? 0.0 : J.v_mm_per_s;
    }
    traj.corners_.push_back(c);
  }
  return traj;
}

}  // namespace twin::controller
