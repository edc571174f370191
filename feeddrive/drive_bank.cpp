#include "feeddrive/drive_bank.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>

#include <fmt/format.h>

#include "feeddrive/effect_torques.hpp"
#include "feeddrive/ode_solver.hpp"
#include "twin/core/axis.hpp"
#include "twin/core/check.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"

namespace twin::feeddrive {
namespace {

// State layout of one axis inside an integrator vector. Positions are
// deviations from the axis's base position at the last restart, so the
// absolute tolerance applies to microns of motion, not hundreds of mm.
//   rigid:     [dx_mm, w, q_damping_J, q_friction_J]
//   compliant: [dx_motor_mm, w_motor, dx_load_mm, w_load, q_damping_J, q_friction_J]
constexpr std::size_t kRigidSize = 4;
constexpr std::size_t kCompliantSize = 6;
// Root functions per axis: 0 stop (s w = 0) or breakaway (+), 1 breakaway (-),
// 2 and 3 the ends of the position-dependent friction band.
constexpr std::size_t kRootsPerAxis = 4;
constexpr int kMaxEventsPerTick = 1000;

// Exact zero-order-hold advance of the linear sliding drive
//   dtheta/dt = w,  dw/dt = -a w + c,  a = B/J, c = F/J held over h,
// i.e. the matrix exponential of [[0, 1, 0], [0, -a, 1], [0, 0, 0]] h:
//   w(h)     = e w0 + f1 c,          e = exp(-a h), f1 = int_0^h exp(-a s) ds
//   theta(h) = f1 w0 + g1 c,         g1 = int_0^h f1(s) ds
//   int w^2  = Iee w0^2 + 2 Ief w0 c + Iff c^2
// with Iee = int e(s)^2, Ief = int e(s) f1(s), Iff = int f1(s)^2 ds. With
// z = a h each is h^n times a power series in z, summed directly for z < 1
// (no cancellation as a -> 0, B = 0 included) and in closed form above.
struct LinearTick {
  double e{1.0};
  double f1_s{0.0};
  double g1_s2{0.0};
  double Iee_s{0.0};
  double Ief_s2{0.0};
  double Iff_s3{0.0};
};

LinearTick linear_tick(double a_per_s, double h_s) {
  const double z = a_per_s * h_s;
  double phi1 = 0.0, phi2 = 0.0, phi1_2z = 0.0, psi_ef = 0.0, psi_ff = 0.0;
  if (z < 1.0) {
    // Terms (-z)^k/(k+1)!, (-z)^k/(k+2)!, (-2z)^k/(k+1)!, and the two
    // combinations below; 40 terms leave < 1e-30 for z < 1.
    double zk = 1.0;    // z^k
    double two_k = 1.0; // 2^k
    double fact = 1.0;  // (k+1)!
    for (int k = 0; k < 40; ++k) {
      fact *= (k + 1);
      const double sign = (k % 2 == 0) ? 1.0 : -1.0;
      phi1 += sign * zk / fact;
      phi2 += sign * zk / (fact * (k + 2));
      phi1_2z += sign * two_k * zk / fact;
      // psi_ef = sum_{k>=1} (-1)^(k+1) (2^k - 1) z^(k-1)/(k+1)!  (term k+1 uses z^k)
      const double f_next = fact * (k + 2);
      psi_ef += sign * (2.0 * two_k - 1.0) * zk / f_next;
      // psi_ff = sum_{k>=2} (-1)^k (2^k - 2) z^(k-2)/(k+1)!  (term k+2 uses z^k)
      psi_ff += sign * (4.0 * two_k - 2.0) * zk / (f_next * (k + 3));
      zk *= z;
      two_k *= 2.0;
    }
  } else {
    phi1 = -std::expm1(-z) / z;
    phi2 = (z + std::expm1(-z)) / (z * z);
    phi1_2z = -std::expm1(-2.0 * z) / (2.0 * z);
    psi_ef = (phi1 - phi1_2z) / z;
    psi_ff = (1.0 - 2.0 * phi1 + phi1_2z) / (z * z);
  }
  LinearTick t;
  t.e = std::exp(-z);
  t.f1_s = h_s * phi1;
  t.g1_s2 = h_s * h_s * phi2;
  t.Iee_s = h_s * phi1_2z;
  t.Ief_s2 = h_s * h_s * psi_ef;
  t.Iff_s3 = h_s * h_s * h_s * psi_ff;
  return t;
}

// Everything about one axis that is fixed for its life in the bank.
struct AxisConst {
  DriveParams p;
  bool compliant{false};
  double Jm_kg_m2{0.0};  // motor side inertia (all of J when rigid)
  double Jl_kg_m2{0.0};  // load side inertia (compliance only)
  std::size_t delay_ticks{0};
  // Closed-form tick (rigid, no nonlinear effect): coefficients of the exact
  // solution of J dw/dt = F - B w, dtheta/dt = w over h = Ts with F held.
  bool linear{false};
  LinearTick tick;
  // Smooth friction: the speed above which the group's coarse step is short
  // enough for this axis (0: any speed, or no smooth friction).
  double sf_guard_rad_per_s{0.0};
};

// Per-tick and per-segment values of one axis, set by the bank.
struct AxisRun {
  double u_applied_V{0.0};
  double i_A{0.0};
  double Tm_Nm{0.0};
  double Tload_Nm{0.0};  // Td + constant load, opposing + motion
  double x0_mm{0.0};     // base position (motor) of the current segment
  double xl0_mm{0.0};    // base position (load) of the current segment
  double damping_base_J{0.0};
  double friction_base_J{0.0};
  int mode{0};           // friction-side sliding direction: +1, -1, 0 = held
  bool frozen{true};     // rigid axis held for the rest of the tick: not integrated
  bool exact{false};     // advanced in closed form this tick: not integrated
  bool clamped{false};   // the current limit clamps this tick's command
  int prev_mode{2};      // mode at the previous tick start (2 = unknown)
  bool prev_frozen{false};
  bool prev_exact{false};
};

double position_friction_Nm(const DriveParams& p, double x_mm) {
  const auto& e = p.effects.position_dependent_friction;
  if (!e.enabled) return 0.0;
  return band_friction_Nm(e.dTc_Nm, e.x_start_mm, e.x_end_mm, x_mm);
}

// The friction the motor's torque Tm adds (load_dependent_friction).
double load_friction_Nm(const DriveParams& p, double Tm_Nm) {
  const auto& e = p.effects.load_dependent_friction;
  return e.enabled ? feeddrive::load_friction_Nm(e.fraction, Tm_Nm) : 0.0;
}

// Coulomb level moving in direction s under the motor's torque Tm.
double coulomb_Nm(const DriveParams& p, int s, double x_mm, double Tm_Nm) {
  return (s > 0 ? p.Tc_pos_Nm : p.Tc_neg_Nm) + position_friction_Nm(p, x_mm) + load_friction_Nm(p, Tm_Nm);
}

// Static friction that must be exceeded to start moving in direction s.
double breakaway_Nm(const DriveParams& p, int s, double x_mm, double Tm_Nm) {
  if (p.effects.stribeck.enabled)
    return p.effects.stribeck.Ts_static_Nm + position_friction_Nm(p, x_mm) + load_friction_Nm(p, Tm_Nm);
  if (p.effects.rising_friction.enabled) return p.effects.rising_friction.share * coulomb_Nm(p, s, x_mm, Tm_Nm);
  return coulomb_Nm(p, s, x_mm, Tm_Nm);
}

// Friction magnitude while sliding in direction s at speed w.
double sliding_friction_Nm(const DriveParams& p, int s, double w, double x_mm, double Tm_Nm) {
  double T = coulomb_Nm(p, s, x_mm, Tm_Nm);
  const auto& st = p.effects.stribeck;
  if (st.enabled) T += stribeck_excess_Nm(st.Ts_static_Nm, s > 0 ? p.Tc_pos_Nm : p.Tc_neg_Nm, w, st.ws_rad_per_s);
  const auto& rf = p.effects.rising_friction;
  if (rf.enabled) T -= rising_friction_deficit_Nm(T, rf.share, w, rf.ws_rad_per_s);
  return T;
}

double cogging_Nm(const DriveParams& p, double x_motor_mm) {
  const auto& c = p.effects.cogging;
  if (!c.enabled) return 0.0;
  return cogging_torque_Nm(c.amplitude_Nm, c.cycles_per_rev, c.phase_rad, x_motor_mm, p.rg_mm_per_rad);
}

double cogging_work_J(const DriveParams& p, double xa_mm, double xb_mm) {
  const auto& c = p.effects.cogging;
  if (!c.enabled) return 0.0;
  return feeddrive::cogging_work_J(c.amplitude_Nm, c.cycles_per_rev, c.phase_rad, xa_mm, xb_mm, p.rg_mm_per_rad);
}

// Deflection of the coupling spring, rad: the twist between motor and load,
// less the gap of a backlash in the coupling.
double spring_deflection_rad(const DriveParams& p, double xm_mm, double xl_mm) {
  const double twist_rad = (xm_mm - xl_mm) / p.rg_mm_per_rad;
  if (!p.effects.backlash.enabled) return twist_rad;
  const double half_rad = 0.5 * p.effects.backlash.gap_mm / p.rg_mm_per_rad;
  if (twist_rad > half_rad) return twist_rad - half_rad;
  if (twist_rad < -half_rad) return twist_rad + half_rad;
  return 0.0;
}

double spring_torque_Nm(const DriveParams& p, double xm_mm, double xl_mm, double wm, double wl) {
  const auto& c = p.effects.compliance;
  const double d_rad = spring_deflection_rad(p, xm_mm, xl_mm);
  // Inside a gap the coupling carries nothing, its damper included.
  if (d_rad == 0.0 && p.effects.backlash.enabled) return 0.0;
  return c.K_Nm_per_rad * d_rad + c.C_Nm_s_per_rad * (wm - wl);
}

// Net torque on the friction side of an axis at rest (w of that side = 0),
// with the values of the state s.
double rest_torque_Nm(const AxisConst& a, const AxisRun& r, const DriveState& s) {
  if (a.compliant) return spring_torque_Nm(a.p, s.x_mm, s.x_load_mm, s.w_rad_per_s, 0.0) - r.Tload_Nm;
  return r.Tm_Nm - r.Tload_Nm - cogging_Nm(a.p, s.x_mm);
}

// Karnopp decision at rest: +1 / -1 to slip in the direction of the net
// torque, 0 to stick while |net| <= breakaway of that direction.
int rest_decision(const AxisConst& a, const AxisRun& r, double net_Nm, double x_friction_mm) {
  if (net_Nm > 0.0 && net_Nm > breakaway_Nm(a.p, +1, x_friction_mm, r.Tm_Nm)) return +1;
  if (net_Nm < 0.0 && -net_Nm > breakaway_Nm(a.p, -1, x_friction_mm, r.Tm_Nm)) return -1;
  return 0;
}

void axis_rhs(const AxisConst& a, const AxisRun& r, const double* y, double* yd) {
  const DriveParams& p = a.p;
  if (!a.compliant) {
    if (r.frozen || r.exact) {
      std::fill(yd, yd + kRigidSize, 0.0);
      return;
    }
    const double w = y[1];
    const double x_mm = r.x0_mm + y[0];
    const double Tf = p.effects.smooth_friction.enabled
                          ? smooth_friction_Nm(coulomb_Nm(p, w >= 0.0 ? +1 : -1, x_mm, r.Tm_Nm), w,
                                               p.effects.smooth_friction.ws_rad_per_s)
                          : r.mode * sliding_friction_Nm(p, r.mode, w, x_mm, r.Tm_Nm);
    yd[0] = p.rg_mm_per_rad * w;
    yd[1] = (r.Tm_Nm - p.B_kg_m2_per_s * w - Tf - r.Tload_Nm - cogging_Nm(p, x_mm)) / a.Jm_kg_m2;
    yd[2] = p.B_kg_m2_per_s * w * w;
    yd[3] = Tf * w;
    return;
  }
  const double wm = y[1];
  const double wl = y[3];
  const double xm_mm = r.x0_mm + y[0];
  const double xl_mm = r.xl0_mm + y[2];
  const double Tk = spring_torque_Nm(p, xm_mm, xl_mm, wm, wl);
  yd[0] = p.rg_mm_per_rad * wm;
  yd[1] = (r.Tm_Nm - p.B_kg_m2_per_s * wm - Tk - cogging_Nm(p, xm_mm)) / a.Jm_kg_m2;
  double Tf = 0.0;
  if (r.mode == 0) {
    yd[2] = 0.0;
    yd[3] = 0.0;
  } else {
    Tf = r.mode * sliding_friction_Nm(p, r.mode, wl, xl_mm, r.Tm_Nm);
    yd[2] = p.rg_mm_per_rad * wl;
    yd[3] = (Tk - Tf - r.Tload_Nm) / a.Jl_kg_m2;
  }
  const double dw = wm - wl;
  yd[4] = p.B_kg_m2_per_s * wm * wm + p.effects.compliance.C_Nm_s_per_rad * dw * dw;
  yd[5] = Tf * wl;
}

void axis_roots(const AxisConst& a, const AxisRun& r, const double* y, double* g) {
  g[0] = g[1] = g[2] = g[3] = 1.0;
  if (r.frozen || r.exact) return;
  const auto& pf = a.p.effects.position_dependent_friction;
  double x_friction_mm = 0.0;
  if (!a.compliant) {
    x_friction_mm = r.x0_mm + y[0];
    // Smooth friction has no stick/slip: no event at w = 0.
    if (!a.p.effects.smooth_friction.enabled) g[0] = r.mode * y[1];
  } else {
    x_friction_mm = r.xl0_mm + y[2];
    if (r.mode != 0) {
      g[0] = r.mode * y[3];
    } else {
      const double net = spring_torque_Nm(a.p, r.x0_mm + y[0], x_friction_mm, y[1], 0.0) - r.Tload_Nm;
      g[0] = breakaway_Nm(a.p, +1, x_friction_mm, r.Tm_Nm) - net;
      g[1] = net + breakaway_Nm(a.p, -1, x_friction_mm, r.Tm_Nm);
    }
  }
  if (pf.enabled && pf.dTc_Nm > 0.0) {
    g[2] = x_friction_mm - pf.x_start_mm;
    g[3] = x_friction_mm - pf.x_end_mm;
  }
}

// The largest rate smooth friction adds [1/s]: max |d/dw Tc tanh(w/ws)| / J
// = Tc / (ws J), at w = 0 (0 without it).
double smooth_friction_rate_per_s(const AxisConst& a) {
  const DriveParams& p = a.p;
  if (!p.effects.smooth_friction.enabled) return 0.0;
  return std::max(p.Tc_pos_Nm, p.Tc_neg_Nm) / p.effects.smooth_friction.ws_rad_per_s / a.Jm_kg_m2;
}

// Fastest linearised rate of an axis [1/s], to bound a fixed explicit step,
// smooth friction's left out (smooth_friction_rate_per_s).
double rate_but_smooth_friction_per_s(const AxisConst& a) {
  const DriveParams& p = a.p;
  double rate = p.B_kg_m2_per_s / a.Jm_kg_m2;
  if (p.effects.stribeck.enabled) {
    const double slope = stribeck_max_slope(p.effects.stribeck.Ts_static_Nm, std::min(p.Tc_pos_Nm, p.Tc_neg_Nm),
                                            p.effects.stribeck.ws_rad_per_s);
    rate += slope / (a.compliant ? a.Jl_kg_m2 : a.Jm_kg_m2);
  }
  if (p.effects.rising_friction.enabled) {  // the same shape as stribeck's, deficit (1 - share) Tc
    const auto& rf = p.effects.rising_friction;
    const double Tc_max = std::max(p.Tc_pos_Nm, p.Tc_neg_Nm);
    const double slope = stribeck_max_slope(Tc_max, rf.share * Tc_max, rf.ws_rad_per_s);
    rate += slope / (a.compliant ? a.Jl_kg_m2 : a.Jm_kg_m2);
  }
  if (a.compliant) {
    const auto& c = p.effects.compliance;
    const double inv = 1.0 / a.Jm_kg_m2 + 1.0 / a.Jl_kg_m2;
    rate += std::sqrt(c.K_Nm_per_rad * inv) + c.C_Nm_s_per_rad * inv;
  }
  return rate;
}

// Whether the options integrate with fixed ERK steps.
bool fixed_erk_steps(const IntegratorOptions& o) {
  return o.method == IntegratorOptions::Method::kArkodeErk && o.erk_fixed_steps_per_tick > 0;
}

// The explicit fixed step for the rate [1/s]: Ts / n, with n at least the
// options' steps per tick and enough that step x rate <= 0.25.
double fixed_step_for_s(double Ts_s, double rate_per_s, int steps_per_tick) {
  const double n_rate = std::ceil(Ts_s * rate_per_s / 0.25);
  return Ts_s / std::max(static_cast<double>(steps_per_tick), n_rate);
}

// The speed above which `step` integrates smooth friction as well as the
// fine step does near rest: 0 where step x (rate_but_smooth_friction + Tc /
// (ws J)) <= 0.25 already holds at w = 0. Else 10 ws, where tanh(w / ws) is
// 1 to 4e-9, so the friction is the Coulomb level and the drive linear (the
// slope condition alone is not enough: at 3.8 ws, where it held, one step
// that took w through one ws erred by 4e-6 of that change, against the 1e-9
// of steps at the fine length), or further out if the slope needs it.
double smooth_friction_guard_rad_per_s(const AxisConst& a, double step_s) {
  const double top = smooth_friction_rate_per_s(a);
  if (top <= 0.0) return 0.0;
  const double q = (0.25 / step_s - rate_but_smooth_friction_per_s(a)) / top;  // the sech^2 allowed
  if (q >= 1.0) return 0.0;
  if (q <= 0.0) return std::numeric_limits<double>::infinity();
  return a.p.effects.smooth_friction.ws_rad_per_s * std::max(10.0, std::acosh(1.0 / std::sqrt(q)));
}

// A bound on how much a rigid axis's speed can change over a tick of h
// seconds, starting at |w| = w0 with the tick's inputs held: every torque on
// it at its largest (the motor's, the load, the Coulomb level with a band of
// position-dependent friction and load-dependent friction on top, cogging,
// and damping at the speed reached), J dw = T0 + B (w0 + dw) over h.
// Infinity where damping alone could outrun the inertia within the tick.
double largest_speed_change_rad_per_s(const AxisConst& a, const AxisRun& r, double w0, double h_s) {
  const DriveParams& p = a.p;
  const auto& fx = p.effects;
  double friction_Nm = std::max(p.Tc_pos_Nm, p.Tc_neg_Nm);
  if (fx.position_dependent_friction.enabled) friction_Nm += std::abs(fx.position_dependent_friction.dTc_Nm);
  if (fx.load_dependent_friction.enabled)
    friction_Nm += feeddrive::load_friction_Nm(fx.load_dependent_friction.fraction, r.Tm_Nm);
  const double cogging_Nm = fx.cogging.enabled ? std::abs(fx.cogging.amplitude_Nm) : 0.0;
  const double T0_Nm = std::abs(r.Tm_Nm) + std::abs(r.Tload_Nm) + friction_Nm + cogging_Nm + p.B_kg_m2_per_s * w0;
  const double room = a.Jm_kg_m2 - h_s * p.B_kg_m2_per_s;
  return room > 0.0 ? h_s * T0_Nm / room : std::numeric_limits<double>::infinity();
}

}  // namespace

struct DriveBank::Impl {
  // A set of axes integrated by one SUNDIALS instance.
  struct Group : OdeSystem {
    Impl* bank{nullptr};
    std::vector<std::size_t> axes;
    std::vector<std::size_t> offset;
    std::size_t size{0};
    std::vector<double> y;
    std::unique_ptr<OdeSolver> solver;
    // Smooth friction's slope is steep only near zero speed: where every
    // axis with it moves faster than its guard, the group steps at the
    // coarse step, else at the fine one (equal where nothing is guarded).
    double fine_step_s{0.0}, coarse_step_s{0.0};
    bool coarse{false};
    bool dirty{true};        // solver state does not match the bank: restart
    double t_solver_s{0.0};  // time the solver state belongs to

    void rhs(double, const double* yv, double* yd) override {
      for (std::size_t k = 0; k < axes.size(); ++k)
        axis_rhs(bank->consts[axes[k]], bank->runs[axes[k]], yv + offset[k], yd + offset[k]);
    }
    void roots(double, const double* yv, double* g) override {
      for (std::size_t k = 0; k < axes.size(); ++k)
        axis_roots(bank->consts[axes[k]], bank->runs[axes[k]], yv + offset[k], g + kRootsPerAxis * k);
    }
  };

  double Ts_s{0.0};
  IntegratorOptions options;
  std::vector<AxisConst> consts;
  std::vector<AxisRun> runs;
  std::vector<DriveState> states;
  std::vector<std::unique_ptr<Group>> groups;
  std::vector<std::array<double, 2>> tick_start;  // x motor, x load at the tick start
  long closed_form_ticks{0};
  long sundials_ticks{0};

  void build_groups();
  void finish_axis(std::size_t i, double t_s);
  bool try_closed_form(std::size_t i);
  void pack(Group& g);
  void unpack(Group& g, double t_s);
  void start_tick_mode(std::size_t i);
  void handle_roots(Group& g, double t_s);
  void advance_group(Group& g, double t_from_s, double t_to_s);
};

void DriveBank::Impl::build_groups() {
  groups.clear();
  std::vector<std::vector<std::size_t>> sets;
  if (options.one_instance_for_all_axes) {
    // An axis whose smooth friction asks a finer fixed step near rest gets
    // an instance of its own, so that the others do not take that step with
    // it while it rests.
    const bool fixed = fixed_erk_steps(options);
    std::vector<std::size_t> rest;
    for (std::size_t i = 0; i < consts.size(); ++i) {
      const double r = rate_but_smooth_friction_per_s(consts[i]);
      const int n = options.erk_fixed_steps_per_tick;
      if (fixed && fixed_step_for_s(Ts_s, r + smooth_friction_rate_per_s(consts[i]), n) < fixed_step_for_s(Ts_s, r, n))
        sets.push_back({i});
      else
        rest.push_back(i);
    }
    if (!rest.empty()) sets.push_back(rest);
  } else {
    for (std::size_t i = 0; i < consts.size(); ++i) sets.push_back({i});
  }
  for (const auto& set : sets) {
    auto g = std::make_unique<Group>();
    g->bank = this;
    g->axes = set;
    std::vector<double> atol;
    double rate = 0.0, rate_coarse = 0.0;
    for (std::size_t i : set) {
      g->offset.push_back(g->size);
      const bool c = consts[i].compliant;
      const std::size_t n = c ? kCompliantSize : kRigidSize;
      g->size += n;
      atol.push_back(options.atol_mm);
      atol.push_back(options.atol_rad_per_s);
      if (c) {
        atol.push_back(options.atol_mm);
        atol.push_back(options.atol_rad_per_s);
      }
      // Energy quadratures ride along without steering the step size.
      atol.push_back(1e6);
      atol.push_back(1e6);
      const double r = rate_but_smooth_friction_per_s(consts[i]);
      rate = std::max(rate, r + smooth_friction_rate_per_s(consts[i]));
      rate_coarse = std::max(rate_coarse, r);
    }
    double fixed_step_s = 0.0;
    if (fixed_erk_steps(options)) {
      fixed_step_s = fixed_step_for_s(Ts_s, rate, options.erk_fixed_steps_per_tick);
      g->fine_step_s = g->coarse_step_s = fixed_step_s;
      const double coarse_s = fixed_step_for_s(Ts_s, rate_coarse, options.erk_fixed_steps_per_tick);
      if (coarse_s > fixed_step_s) {
        g->coarse_step_s = coarse_s;
        for (std::size_t i : set) consts[i].sf_guard_rad_per_s = smooth_friction_guard_rad_per_s(consts[i], coarse_s);
      }
    }
    g->y.assign(g->size, 0.0);
    g->solver = std::make_unique<OdeSolver>(*g, g->size, kRootsPerAxis * set.size(), options, atol,
                                            fixed_step_s);
    groups.push_back(std::move(g));
  }
}

void DriveBank::Impl::pack(Group& g) {
  for (std::size_t k = 0; k < g.axes.size(); ++k) {
    const std::size_t i = g.axes[k];
    const DriveState& s = states[i];
    AxisRun& r = runs[i];
    double* y = g.y.data() + g.offset[k];
    r.x0_mm = s.x_mm;
    r.xl0_mm = s.x_load_mm;
    r.damping_base_J = s.work_damping_J;
    r.friction_base_J = s.work_friction_J;
    y[0] = 0.0;
    y[1] = s.w_rad_per_s;
    if (consts[i].compliant) {
      y[2] = 0.0;
      y[3] = s.w_load_rad_per_s;
      y[4] = y[5] = 0.0;
    } else {
      y[2] = y[3] = 0.0;
    }
  }
}

void DriveBank::Impl::unpack(Group& g, double t_s) {
  for (std::size_t k = 0; k < g.axes.size(); ++k) {
    const std::size_t i = g.axes[k];
    const AxisConst& a = consts[i];
    const AxisRun& r = runs[i];
    DriveState& s = states[i];
    const double* y = g.y.data() + g.offset[k];
    s.x_mm = r.x0_mm + y[0];
    s.w_rad_per_s = y[1];
    if (a.compliant) {
      s.x_load_mm = r.xl0_mm + y[2];
      s.w_load_rad_per_s = y[3];
      s.work_damping_J = r.damping_base_J + y[4];
      s.work_friction_J = r.friction_base_J + y[5];
    } else {
      s.x_load_mm = s.x_mm;
      s.w_load_rad_per_s = s.w_rad_per_s;
      s.work_damping_J = r.damping_base_J + y[2];
      s.work_friction_J = r.friction_base_J + y[3];
    }
    finish_axis(i, t_s);
  }
}

// Table position after the play of a backlash, and the finiteness check.
void DriveBank::Impl::finish_axis(std::size_t i, double t_s) {
  const AxisConst& a = consts[i];
  DriveState& s = states[i];
  const double x_drive_mm = a.compliant ? s.x_load_mm : s.x_mm;
  if (a.p.effects.backlash.enabled && !a.compliant) {
    const double half_mm = 0.5 * a.p.effects.backlash.gap_mm;
    if (x_drive_mm - s.x_table_mm > half_mm) s.x_table_mm = x_drive_mm - half_mm;
    if (s.x_table_mm - x_drive_mm > half_mm) s.x_table_mm = x_drive_mm + half_mm;
  } else {
    s.x_table_mm = x_drive_mm;
  }
  if (!all_finite(s.x_mm, s.w_rad_per_s, s.x_load_mm, s.w_load_rad_per_s, s.work_damping_J, s.work_friction_J))
    throw ModelError(fmt::format("feeddrive: axis {} state became non-finite at t = {} s (x = {} mm, w = {} rad/s)",
                                 i < kNumAxes ? axis_name(i) : std::string_view("?"), t_s, s.x_mm, s.w_rad_per_s));
}

// Closed-form advance of rigid axis i over the whole tick, if the tick is an
// ordinary one: the axis slides (w != 0 at the start, so its friction side s
// is known and held), has no nonlinear effect, its current is not clamped,
// and w keeps its sign to the end of the tick by a clear margin. The solution
// of J dw/dt = F - B w is monotone in t, so w(h) of the sign of w(0) means no
// zero of w, hence no stop, reversal or stick inside the tick. The margin
// (1e-6 of the speed scale of the tick) leaves every tick whose end speed
// comes anywhere near zero to SUNDIALS and its root finding; returns false
// then, with the state untouched.
bool DriveBank::Impl::try_closed_form(std::size_t i) {
  const AxisConst& a = consts[i];
  AxisRun& r = runs[i];
  DriveState& s = states[i];
  if (!a.linear || r.frozen || r.clamped || s.w_rad_per_s == 0.0) return false;
  const DriveParams& p = a.p;
  const LinearTick& k = a.tick;
  const int dir = s.w_rad_per_s > 0.0 ? +1 : -1;
  const double Tf_Nm = dir * coulomb_Nm(p, dir, s.x_mm, r.Tm_Nm);
  const double w0 = s.w_rad_per_s;
  const double c = (r.Tm_Nm - Tf_Nm - r.Tload_Nm) / a.Jm_kg_m2;
  const double w1 = k.e * w0 + k.f1_s * c;
  const double margin = 1e-6 * (std::abs(w0) + std::abs(c) * k.f1_s);
  if (!(dir * w1 > margin)) return false;
  const double dtheta_rad = k.f1_s * w0 + k.g1_s2 * c;
  const double int_w2 = k.Iee_s * w0 * w0 + 2.0 * k.Ief_s2 * w0 * c + k.Iff_s3 * c * c;
  s.x_mm += p.rg_mm_per_rad * dtheta_rad;
  s.w_rad_per_s = w1;
  s.x_load_mm = s.x_mm;
  s.w_load_rad_per_s = w1;
  s.work_damping_J += p.B_kg_m2_per_s * int_w2;
  s.work_friction_J += Tf_Nm * dtheta_rad;
  r.mode = dir;
  r.exact = true;
  return true;
}

// Mode of axis i at the start of a tick, from its state and this tick's inputs.
void DriveBank::Impl::start_tick_mode(std::size_t i) {
  const AxisConst& a = consts[i];
  AxisRun& r = runs[i];
  DriveState& s = states[i];
  if (!a.compliant) {
    if (a.p.effects.smooth_friction.enabled) {
      // Never held: the smooth characteristic acts at every speed, 0 included.
      r.mode = +1;
      r.frozen = false;
    } else if (s.w_rad_per_s != 0.0) {
      r.mode = s.w_rad_per_s > 0.0 ? +1 : -1;
      r.frozen = false;
    } else {
      r.mode = rest_decision(a, r, rest_torque_Nm(a, r, s), s.x_mm);
      r.frozen = r.mode == 0;
    }
    s.stuck = r.frozen;
    return;
  }
  r.frozen = false;
  if (s.w_load_rad_per_s != 0.0) {
    r.mode = s.w_load_rad_per_s > 0.0 ? +1 : -1;
  } else {
    r.mode = rest_decision(a, r, rest_torque_Nm(a, r, s), s.x_load_mm);
  }
  s.load_stuck = r.mode == 0;
  s.stuck = s.load_stuck;
}

void DriveBank::Impl::handle_roots(Group& g, double t_s) {
  const std::vector<int>& found = g.solver->roots_found();
  for (std::size_t k = 0; k < g.axes.size(); ++k) {
    const std::size_t i = g.axes[k];
    const AxisConst& a = consts[i];
    AxisRun& r = runs[i];
    DriveState& s = states[i];
    const int* f = found.data() + kRootsPerAxis * k;
    if (f[0] == 0 && f[1] == 0) continue;  // band edges only need the restart
    if (!a.compliant) {
      // The axis came to rest: stick, or slip back if the net torque breaks away.
      s.w_rad_per_s = 0.0;
      r.mode = rest_decision(a, r, rest_torque_Nm(a, r, s), s.x_mm);
      r.frozen = r.mode == 0;
      s.stuck = r.frozen;
      continue;
    }
    if (r.mode != 0) {
      s.w_load_rad_per_s = 0.0;
      r.mode = rest_decision(a, r, rest_torque_Nm(a, r, s), s.x_load_mm);
    } else {
      r.mode = f[0] != 0 ? +1 : -1;
    }
    s.load_stuck = r.mode == 0;
    s.stuck = s.load_stuck;
  }
  (void)t_s;
}

void DriveBank::Impl::advance_group(Group& g, double t_from_s, double t_to_s) {
  bool restart = options.reinit_every_tick || g.dirty ||
                 std::abs(g.t_solver_s - t_from_s) > 1e-12 * std::max(1.0, std::abs(t_from_s));
  bool any_moving = false;
  for (std::size_t i : g.axes) {
    AxisRun& r = runs[i];
    r.exact = false;
    start_tick_mode(i);
    if (options.exact_linear_ticks && try_closed_form(i)) {
      ++closed_form_ticks;
      finish_axis(i, t_to_s);
      // The solver's copy of this axis is stale from here: re-pack if it runs.
      restart = true;
    }
    if (r.mode != r.prev_mode || r.frozen != r.prev_frozen || r.exact != r.prev_exact) restart = true;
    r.prev_mode = r.mode;
    r.prev_frozen = r.frozen;
    r.prev_exact = r.exact;
    if (!r.frozen && !r.exact) {
      any_moving = true;
      ++sundials_ticks;
    }
  }
  if (!any_moving) {
    g.dirty = true;
    return;
  }
  if (g.coarse_step_s > g.fine_step_s) {
    // The coarse step where no moving axis with smooth friction can fall to
    // its guard within the tick.
    bool coarse = true;
    for (std::size_t i : g.axes) {
      const AxisConst& a = consts[i];
      const AxisRun& r = runs[i];
      if (r.frozen || r.exact || a.sf_guard_rad_per_s <= 0.0) continue;
      const double w0 = std::abs(states[i].w_rad_per_s);
      if (!(w0 - largest_speed_change_rad_per_s(a, r, w0, t_to_s - t_from_s) > a.sf_guard_rad_per_s)) coarse = false;
    }
    if (coarse != g.coarse) {
      g.solver->set_fixed_step(coarse ? g.coarse_step_s : g.fine_step_s);
      g.coarse = coarse;
      restart = true;
    }
  }
  double t_s = t_from_s;
  if (restart) {
    pack(g);
    g.solver->restart(t_s, g.y);
  }
  for (int events = 0;; ++events) {
    if (events > kMaxEventsPerTick)
      throw ModelError(fmt::format("feeddrive: more than {} stick/slip events in the tick at t = {} s",
                                   kMaxEventsPerTick, t_from_s));
    const OdeSolver::Stop stop = g.solver->advance(t_to_s, g.y, t_s);
    unpack(g, t_s);
    if (stop == OdeSolver::Stop::kReachedEnd) break;
    handle_roots(g, t_s);
    bool moving = false;
    for (std::size_t i : g.axes) moving = moving || (!runs[i].frozen && !runs[i].exact);
    if (!moving) {
      g.dirty = true;
      return;
    }
    pack(g);
    g.solver->restart(t_s, g.y);
    // Later ticks compare against the mode the axis ends this tick in.
    for (std::size_t i : g.axes) {
      runs[i].prev_mode = runs[i].mode;
      runs[i].prev_frozen = runs[i].frozen;
      runs[i].prev_exact = runs[i].exact;
    }
  }
  g.dirty = false;
  g.t_solver_s = t_to_s;
}

DriveBank::DriveBank(std::vector<DriveParams> axes, double Ts_s, IntegratorOptions options)
    : impl_(std::make_unique<Impl>()) {
  if (!(std::isfinite(Ts_s) && Ts_s > 0.0))
    throw ConfigError(fmt::format("feeddrive: Ts_s = {} must be finite and > 0", Ts_s));
  if (axes.empty()) throw ConfigError("feeddrive: the drive bank needs at least one axis (got 0)");
  if (!(std::isfinite(options.rtol) && options.rtol > 0.0))
    throw ConfigError(fmt::format("feeddrive: IntegratorOptions rtol = {} must be > 0", options.rtol));
  if (!(std::isfinite(options.atol_mm) && options.atol_mm > 0.0))
    throw ConfigError(fmt::format("feeddrive: IntegratorOptions atol_mm = {} must be > 0", options.atol_mm));
  if (!(std::isfinite(options.atol_rad_per_s) && options.atol_rad_per_s > 0.0))
    throw ConfigError(
        fmt::format("feeddrive: IntegratorOptions atol_rad_per_s = {} must be > 0", options.atol_rad_per_s));
  if (options.erk_fixed_steps_per_tick < 0)
    throw ConfigError(fmt::format("feeddrive: IntegratorOptions erk_fixed_steps_per_tick = {} must be >= 0",
                                  options.erk_fixed_steps_per_tick));
  Impl& m = *impl_;
  m.Ts_s = Ts_s;
  m.options = options;
  for (std::size_t i = 0; i < axes.size(); ++i) {
    const std::string where = fmt::format("feeddrive axis {}", i < kNumAxes ? axis_name(i) : "?");
    axes[i].validate(where);
    AxisConst a;
    a.p = axes[i];
    a.compliant = a.p.effects.compliance.enabled;
    if (a.compliant) {
      a.Jl_kg_m2 = a.p.J_kg_m2 * a.p.effects.compliance.load_fraction;
      a.Jm_kg_m2 = a.p.J_kg_m2 - a.Jl_kg_m2;
    } else {
      a.Jm_kg_m2 = a.p.J_kg_m2;
    }
    const DriveEffects& fx = a.p.effects;
    a.linear = !a.compliant && !fx.stribeck.enabled && !fx.cogging.enabled && !fx.smooth_friction.enabled &&
               !fx.rising_friction.enabled &&
               !(fx.position_dependent_friction.enabled && fx.position_dependent_friction.dTc_Nm != 0.0);
    a.tick = linear_tick(a.p.B_kg_m2_per_s / a.Jm_kg_m2, Ts_s);
    if (a.p.effects.delay.enabled) a.delay_ticks = static_cast<std::size_t>(std::llround(a.p.effects.delay.delay_s / Ts_s));
    m.consts.push_back(a);
  }
  m.runs.resize(m.consts.size());
  m.states.resize(m.consts.size());
  m.tick_start.resize(m.consts.size());
  m.build_groups();
  reset(std::vector<double>(m.consts.size(), 0.0));
}

DriveBank::~DriveBank() = default;
DriveBank::DriveBank(DriveBank&& other) noexcept = default;
DriveBank& DriveBank::operator=(DriveBank&& other) noexcept = default;

std::size_t DriveBank::size() const noexcept { return impl_->consts.size(); }

void DriveBank::reset(const std::vector<double>& x0_mm) {
  Impl& m = *impl_;
  if (x0_mm.size() != m.consts.size())
    throw ConfigError(fmt::format("feeddrive: reset got {} positions for {} axes", x0_mm.size(), m.consts.size()));
  for (std::size_t i = 0; i < x0_mm.size(); ++i) {
    if (!std::isfinite(x0_mm[i]))
      throw ConfigError(fmt::format("feeddrive: reset position of axis {} = {} mm must be finite", i, x0_mm[i]));
    DriveState s;
    s.x_mm = s.x_load_mm = s.x_table_mm = x0_mm[i];
    s.u_delay_V.assign(m.consts[i].delay_ticks, 0.0);
    m.states[i] = s;
    m.runs[i] = AxisRun{};
  }
  for (auto& g : m.groups) g->dirty = true;
}

void DriveBank::advance(double t_from_s, double t_to_s, const std::vector<DriveInput>& inputs) {
  Impl& m = *impl_;
  if (inputs.size() != m.consts.size())
    throw ConfigError(fmt::format("feeddrive: advance got {} inputs for {} axes", inputs.size(), m.consts.size()));
  if (!(std::isfinite(t_from_s) && std::isfinite(t_to_s) && t_to_s > t_from_s))
    throw InternalError(fmt::format("feeddrive: advance from t = {} s to t = {} s is not a forward interval",
                                    t_from_s, t_to_s));
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    const AxisConst& a = m.consts[i];
    AxisRun& r = m.runs[i];
    DriveState& s = m.states[i];
    if (!all_finite(inputs[i].u_V, inputs[i].Td_Nm))
      throw ModelError(fmt::format("feeddrive: axis {} input at t = {} s is non-finite (u = {} V, Td = {} N m)",
                                   i < kNumAxes ? axis_name(i) : "?", t_from_s, inputs[i].u_V, inputs[i].Td_Nm));
    double u_V = inputs[i].u_V;
    if (a.delay_ticks > 0) {
      const double oldest_V = s.u_delay_V[s.u_delay_head];
      s.u_delay_V[s.u_delay_head] = u_V;
      s.u_delay_head = (s.u_delay_head + 1) % a.delay_ticks;
      u_V = oldest_V;
    }
    r.u_applied_V = u_V;
    r.i_A = a.p.Ka_A_per_V * u_V;
    r.clamped = false;
    if (a.p.effects.current_saturation.enabled) {
      const double lim = a.p.effects.current_saturation.i_max_A;
      r.clamped = std::abs(r.i_A) >= lim;
      r.i_A = saturated_current_A(r.i_A, lim);
    }
    r.Tm_Nm = a.p.Kt_Nm_per_A * r.i_A;
    r.Tload_Nm = inputs[i].Td_Nm + (a.p.effects.constant_load.enabled ? a.p.effects.constant_load.torque_Nm : 0.0);
  }
  // Tick-start positions for the exact electrical and load work.
  std::vector<std::array<double, 2>>& start = m.tick_start;
  for (std::size_t i = 0; i < m.consts.size(); ++i) start[i] = {m.states[i].x_mm, m.states[i].x_load_mm};

  for (auto& g : m.groups) m.advance_group(*g, t_from_s, t_to_s);

  for (std::size_t i = 0; i < m.consts.size(); ++i) {
    const AxisConst& a = m.consts[i];
    const AxisRun& r = m.runs[i];
    DriveState& s = m.states[i];
    const double rg = a.p.rg_mm_per_rad;
    s.work_electrical_J += r.Tm_Nm * (s.x_mm - start[i][0]) / rg;
    s.work_load_J += r.Tload_Nm * (s.x_load_mm - start[i][1]) / rg + cogging_work_J(a.p, start[i][0], s.x_mm);
  }
}

DriveOutput DriveBank::output(std::size_t i) const {
  const Impl& m = *impl_;
  TWIN_DEMAND(i < m.consts.size());
  const AxisConst& a = m.consts[i];
  const AxisRun& r = m.runs[i];
  const DriveState& s = m.states[i];
  const DriveParams& p = a.p;
  DriveOutput o;
  o.x_mm = p.effects.backlash.enabled ? s.x_table_mm : (a.compliant ? s.x_load_mm : s.x_mm);
  const double sensor_mm = a.compliant ? s.x_mm : o.x_mm;
  o.x_meas_mm = sensor_mm;
  if (p.effects.screw_pitch_error.enabled) {
    const auto& e = p.effects.screw_pitch_error;
    o.x_meas_mm += screw_pitch_error_mm(e.amplitude_mm, e.period_mm, e.phase_rad, o.x_mm);
  }
  o.w_rad_per_s = s.w_rad_per_s;
  o.v_mm_per_s = p.rg_mm_per_rad * (a.compliant ? s.w_load_rad_per_s : s.w_rad_per_s);
  o.i_A = r.i_A;
  o.Tm_Nm = r.Tm_Nm;
  return o;
}

const DriveState& DriveBank::state(std::size_t i) const {
  TWIN_DEMAND(i < impl_->states.size());
  return impl_->states[i];
}

const std::vector<DriveState>& DriveBank::states() const { return impl_->states; }

void DriveBank::set_states(const std::vector<DriveState>& states) {
  Impl& m = *impl_;
  if (states.size() != m.consts.size())
    throw ConfigError(fmt::format("feeddrive: set_states got {} states for {} axes", states.size(), m.consts.size()));
  for (std::size_t i = 0; i < states.size(); ++i) {
    const DriveState& s = states[i];
    if (s.u_delay_V.size() != m.consts[i].delay_ticks ||
        (m.consts[i].delay_ticks > 0 && s.u_delay_head >= m.consts[i].delay_ticks))
      throw ConfigError(fmt::format("feeddrive: set_states axis {}: delay buffer of {} (head {}) must hold {} commands",
                                    i, s.u_delay_V.size(), s.u_delay_head, m.consts[i].delay_ticks));
    if (!all_finite(s.x_mm, s.w_rad_per_s, s.x_load_mm, s.w_load_rad_per_s, s.x_table_mm))
      throw ConfigError(fmt::format("feeddrive: set_states axis {}: non-finite state (x = {} mm, w = {} rad/s)", i,
                                    s.x_mm, s.w_rad_per_s));
  }
  m.states = states;
  for (auto& r : m.runs) r.prev_mode = 2;
  for (auto& g : m.groups) g->dirty = true;
}

const DriveParams& DriveBank::params(std::size_t i) const {
  TWIN_DEMAND(i < impl_->consts.size());
  return impl_->consts[i].p;
}

long DriveBank::num_steps() const noexcept {
  long n = 0;
  for (const auto& g : impl_->groups) n += g->solver->num_steps();
  return n;
}

long DriveBank::num_closed_form_ticks() const noexcept { return impl_->closed_form_ticks; }
long DriveBank::num_sundials_ticks() const noexcept { return impl_->sundials_ticks; }

long DriveBank::num_rhs_evals() const noexcept {
  long n = 0;
  for (const auto& g : impl_->groups) n += g->solver->num_rhs_evals();
  return n;
}

double kinetic_energy_J(const DriveParams& p, const DriveState& s) {
  if (!p.effects.compliance.enabled) return 0.5 * p.J_kg_m2 * s.w_rad_per_s * s.w_rad_per_s;
  const double Jl = p.J_kg_m2 * p.effects.compliance.load_fraction;
  const double Jm = p.J_kg_m2 - Jl;
  return 0.5 * Jm * s.w_rad_per_s * s.w_rad_per_s + 0.5 * Jl * s.w_load_rad_per_s * s.w_load_rad_per_s;
}

double spring_energy_J(const DriveParams& p, const DriveState& s) {
  if (!p.effects.compliance.enabled) return 0.0;
  const double d_rad = spring_deflection_rad(p, s.x_mm, s.x_load_mm);
  return 0.5 * p.effects.compliance.K_Nm_per_rad * d_rad * d_rad;
}

}  // namespace twin::feeddrive
