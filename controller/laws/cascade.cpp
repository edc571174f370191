#include "controller/laws/cascade.hpp"

#include <algorithm>
#include <cmath>
#include <string_view>

#include <fmt/format.h>

#include "controller/laws/realisation_builder.hpp"
#include "twin/core/error.hpp"

namespace twin::controller::laws {

void CascadeLaw::validate(const PositionLoopParams& g, std::string_view where) const {
  const CascadeGains& c = g.cascade;
  require_finite(where, {{"Kv", c.Kv_per_s},
                         {"kff", c.kff},
                         {"Kvp", c.Kvp_torque_s_per_rad},
                         {"Tn", c.Tn_s},
                         {"tau_i", c.tau_i_s},
                         {"T_max", c.T_max},
                         {"Jff", c.Jff_torque_s2_per_rad},
                         {"Tv", c.Tv_s},
                         {"command_average", c.command_average_s},
                         {"command_lag", c.command_lag_s},
                         {"command_delay", c.command_delay_s},
                         {"feedforward_unsmoothed", c.feedforward_unsmoothed}});
  if (!(c.Kv_per_s > 0.0)) throw ConfigError(fmt::format("{}: Kv = {} 1/s must be > 0", where, c.Kv_per_s));
  if (c.kff < 0.0 || c.kff > 1.5) throw ConfigError(fmt::format("{}: kff = {} must be in [0, 1.5]", where, c.kff));
  if (!(c.Kvp_torque_s_per_rad > 0.0))
    throw ConfigError(fmt::format("{}: Kvp = {} must be > 0", where, c.Kvp_torque_s_per_rad));
  if (c.Tn_s < 0.0 || c.tau_i_s < 0.0 || c.Jff_torque_s2_per_rad < 0.0)
    throw ConfigError(fmt::format("{}: Tn, tau_i, Jff = {}, {}, {} must be >= 0", where, c.Tn_s, c.tau_i_s,
                                  c.Jff_torque_s2_per_rad));
  if (!(c.T_max > 0.0)) throw ConfigError(fmt::format("{}: T_max = {} must be > 0", where, c.T_max));
  if (c.command_average_s < 0.0 || c.command_lag_s < 0.0 || c.command_delay_s < 0.0)
    throw ConfigError(fmt::format("{}: command_average, command_lag, command_delay = {}, {}, {} s must be >= 0", where,
                                  c.command_average_s, c.command_lag_s, c.command_delay_s));
  if (c.feedforward_unsmoothed != 0.0 && c.feedforward_unsmoothed != 1.0)
    throw ConfigError(fmt::format("{}: feedforward_unsmoothed = {} must be 0 or 1", where, c.feedforward_unsmoothed));
  if (c.Tv_s < 0.0) throw ConfigError(fmt::format("{}: Tv = {} s must be >= 0 (0: the position loop's Ts)", where, c.Tv_s));
}

int CascadeLaw::inner_ticks(const CascadeGains& g, double Ts_s) {
  if (g.Tv_s <= 0.0) return 1;
  const double n = Ts_s / g.Tv_s;
  if (!(n >= 1.0 - 1e-9 && n <= kMaxInnerTicks + 1e-9 && std::abs(n - std::round(n)) <= 1e-6 * n))
    throw ConfigError(fmt::format("position loop: the velocity loop's period Tv = {} s must divide Ts = {} s into 1 "
                                  "to {} ticks",
                                  g.Tv_s, Ts_s, kMaxInnerTicks));
  return static_cast<int>(std::lround(n));
}

namespace {

/// `value_s` in periods of Ts: 0 for 0, else 1 to `max_ticks` whole periods
/// (a ConfigError naming `what` otherwise).
int whole_periods(double value_s, double Ts_s, int max_ticks, std::string_view what) {
  const double n = value_s / Ts_s;
  if (!(n > 0.0)) return 0;
  if (!(n <= max_ticks + 1e-9 && std::abs(n - std::round(n)) <= 1e-6 * n && n >= 1.0 - 1e-9))
    throw ConfigError(fmt::format("position loop: {} = {} s must be 1 to {} whole periods of Ts = {} s", what, value_s,
                                  max_ticks, Ts_s));
  return static_cast<int>(std::lround(n));
}

}  // namespace

LawSetup CascadeLaw::setup(const PositionLoopParams& g, double Ts_s, const DriveScale& drive) const {
  if (!(drive.rg_mm_per_rad > 0.0) || !(drive.Ka_A_per_V > 0.0) || !(drive.Kt_Nm_per_A > 0.0))
    throw ConfigError(fmt::format("position loop: the cascade needs rg, Ka, Kt > 0 (got {}, {}, {})",
                                  drive.rg_mm_per_rad, drive.Ka_A_per_V, drive.Kt_Nm_per_A));
  const int n = inner_ticks(g.cascade, Ts_s);
  LawSetup s{Ts_s, drive, 0.0, n, Ts_s / n};
  s.lag_a = g.cascade.tau_i_s > 0.0 ? std::exp(-s.Tv_s / g.cascade.tau_i_s) : 0.0;
  s.command_average_ticks =
      std::max(1, whole_periods(g.cascade.command_average_s, Ts_s, kMaxCommandAverageTicks,
                                "the reference's moving average command_average"));
  s.command_lag_a = g.cascade.command_lag_s > 0.0 ? std::exp(-Ts_s / g.cascade.command_lag_s) : 0.0;
  s.command_delay_ticks =
      whole_periods(g.cascade.command_delay_s, Ts_s, kMaxCommandDelayTicks, "the reference's dead time command_delay");
  s.feedforward_unsmoothed = g.cascade.feedforward_unsmoothed == 1.0;
  return s;
}

void CascadeLaw::step(const PositionLoopParams& p, const LawSetup& setup, double x_meas_mm, double v_meas_mm_per_s,
                      PositionLoopState& s, PositionLoopOutput& out) const {
  const CascadeGains& g = p.cascade;
  const double Ts = setup.Ts_s;
  const double v_meas = std::isfinite(v_meas_mm_per_s) ? v_meas_mm_per_s : (x_meas_mm - s.x_meas_prev_mm) / Ts;
  out.vcmd_mm_per_s = g.Kv_per_s * out.e_mm + g.kff * out.v_ref_mm_per_s;
  velocity_tick(p, setup, v_meas, s, out);
  s.x_meas_prev_mm = x_meas_mm;
}

void CascadeLaw::inner_step(const PositionLoopParams& p, const LawSetup& setup, double v_meas_mm_per_s,
                            PositionLoopState& s, PositionLoopOutput& out) const {
  if (!std::isfinite(v_meas_mm_per_s))
    throw InternalError("cascade: an inner tick of the velocity loop needs the drive's speed");
  velocity_tick(p, setup, v_meas_mm_per_s, s, out);
}

void CascadeLaw::velocity_tick(const PositionLoopParams& p, const LawSetup& setup, double v_meas_mm_per_s,
                               PositionLoopState& s, PositionLoopOutput& out) {
  const CascadeGains& g = p.cascade;
  const double rg = setup.drive.rg_mm_per_rad;
  const double ev = (out.vcmd_mm_per_s - v_meas_mm_per_s) / rg;
  const double Iv = s.Iv_rad + setup.Tv_s * ev;
  const double integral = g.Tn_s > 0.0 ? Iv / g.Tn_s : 0.0;
  const double T_unclamped = g.Kvp_torque_s_per_rad * (ev + integral) + g.Jff_torque_s2_per_rad * out.a_ref_mm_per_s2 / rg;
  const double T = std::clamp(T_unclamped, -g.T_max, g.T_max);
  out.saturated = T != T_unclamped;
  out.torque_demand = T;
  // Anti-windup: the integral is frozen while the limit holds the command.
  if (!out.saturated) s.Iv_rad = Iv;
  s.T_filtered = setup.lag_a * s.T_filtered + (1.0 - setup.lag_a) * T;
  out.torque_cmd = s.T_filtered;
  const double per_V = setup.drive.Ka_A_per_V * setup.drive.Kt_Nm_per_A;
  out.u_V = s.T_filtered / per_V;
  out.u_unclamped_V = T_unclamped / per_V;
}

/// The P position loop lags by the error whose Kv e gives the speed the velocity
/// feedforward does not: e = (rg w + rg ev - kff v) / Kv, the velocity error ev = 0
/// with an integral, T / Kvp without one.
double CascadeLaw::steady_state(const PositionLoopParams& p, const SteadyMotion& m, double x_ref_mm,
                                PositionLoopState& s) const {
  const CascadeGains& c = p.cascade;
  const double rg = m.drive.rg_mm_per_rad, w = m.w_rad_per_s, T_needed = m.torque_needed;
  const double ev = c.Tn_s > 0.0 ? 0.0 : T_needed / c.Kvp_torque_s_per_rad;
  const double e = (rg * (w + ev) - c.kff * m.v_ref_mm_per_s) / c.Kv_per_s;
  s.Iv_rad = c.Tn_s > 0.0 ? c.Tn_s * T_needed / c.Kvp_torque_s_per_rad : 0.0;
  s.T_filtered = T_needed;
  s.x_meas_prev_mm = (x_ref_mm - e) - rg * w * m.Ts_s;
  s.e_prev_mm = e;
  return e;
}

namespace {

/// The cascade whose velocity loop runs `ticks` > 1 times a period: at the
/// first tick the position loop sets the velocity command, held with the
/// reference's acceleration for the ticks after it; every tick the PI
/// velocity loop and the current-loop filter act at Tv = Ts / ticks.
ControllerRealisation realise_multirate(const CascadeGains& c, double Ts, int ticks, const LinearPlant& p) {
  const double rg = p.rg_mm_per_rad, Tv = Ts / ticks;
  const bool integral = c.Tn_s > 0.0, lag = c.tau_i_s > 0.0;
  const double alpha = lag ? std::exp(-Tv / c.tau_i_s) : 0.0;
  int n = 0;
  const int iI = integral ? n++ : -1;
  const int iT = lag ? n++ : -1;
  const int ih = n++;                      // the velocity command held over the period (mm/s)
  const int ir = n++, iv = n++, ia = n++;  // x_ref[k-1], v_ref[k-1], a_ref held (reference only)
  auto velocity_tick = [&](RealisationBuilder& b, const Row& vcmd, const Row& a) {
    const Row ev = vcmd / rg - b.w();
    Row Tc = c.Kvp_torque_s_per_rad * ev + c.Jff_torque_s2_per_rad * a / rg;
    if (integral) {
      const Row Iv = b.state(iI) + Tv * ev;
      Tc += c.Kvp_torque_s_per_rad / c.Tn_s * Iv;
      b.set_next(iI, Iv);
    }
    if (!lag) return Tc;
    const Row command = alpha * b.state(iT) + (1.0 - alpha) * Tc;
    b.set_next(iT, command);
    return command;
  };
  Eigen::VectorXd start = Eigen::VectorXd::Zero(n);
  start(ir) = 1.0;

  RealisationBuilder first(n);
  const Row e = first.r() - first.x();
  const Row v = (first.r() - first.state(ir)) / Ts;
  const Row a = (v - first.state(iv)) / Ts;
  const Row vcmd = c.Kv_per_s * e + c.kff * v;
  const Row command = velocity_tick(first, vcmd, a);
  first.set_next(ih, vcmd);
  first.set_next(ir, first.r());
  first.set_next(iv, v);
  first.set_next(ia, a);
  ControllerRealisation K = first.finish(command, start, 3);

  RealisationBuilder later(n);
  const Row command_later = velocity_tick(later, later.state(ih), later.state(ia));
  for (int i : {ih, ir, iv, ia}) later.set_next(i, later.state(i));
  const ControllerRealisation inner = later.finish(command_later, start, 3);
  K.inner_ticks = ticks;
  K.inner = {inner.Ac, inner.By, inner.Cc, inner.Dy};
  return K;
}

}  // namespace

ControllerRealisation CascadeLaw::realise(const PositionLoopParams& g, double Ts, const LinearPlant& p) const {
  const CascadeGains& c = g.cascade;
  if (const int ticks = inner_ticks(c, Ts); ticks > 1) return realise_multirate(c, Ts, ticks, p);
  const double rg = p.rg_mm_per_rad;
  const bool integral = c.Tn_s > 0.0, lag = c.tau_i_s > 0.0;
  int n = 0;
  const int iI = integral ? n++ : -1;
  const int iT = lag ? n++ : -1;
  const int ir = n++, iv = n++;
  RealisationBuilder b(n);
  const Row e = b.r() - b.x();
  const Row v = (b.r() - b.state(ir)) / Ts;
  const Row a = (v - b.state(iv)) / Ts;
  const Row ev = (c.Kv_per_s * e + c.kff * v) / rg - b.w();
  Row Tc = c.Kvp_torque_s_per_rad * ev + c.Jff_torque_s2_per_rad * a / rg;
  if (integral) {
    const Row Iv = b.state(iI) + Ts * ev;
    Tc += c.Kvp_torque_s_per_rad / c.Tn_s * Iv;
    b.set_next(iI, Iv);
  }
  Row command = Tc;
  if (lag) {
    const double alpha = std::exp(-Ts / c.tau_i_s);
    command = alpha * b.state(iT) + (1.0 - alpha) * Tc;
    b.set_next(iT, command);
  }
  b.set_next(ir, b.r());
  b.set_next(iv, v);
  Eigen::VectorXd start = Eigen::VectorXd::Zero(n);
  start(ir) = 1.0;
  return b.finish(command, start, 2);
}

namespace {
double& Kv(PositionLoopParams& g) { return g.cascade.Kv_per_s; }
double& Kvp(PositionLoopParams& g) { return g.cascade.Kvp_torque_s_per_rad; }
double& Tn(PositionLoopParams& g) { return g.cascade.Tn_s; }
double& kff(PositionLoopParams& g) { return g.cascade.kff; }
double& Jff(PositionLoopParams& g) { return g.cascade.Jff_torque_s2_per_rad; }

constexpr LawGain kGains[] = {
    {"Kv", "Kv_per_s", "1/s", false, true, &Kv, nullptr, nullptr},
    {"Kvp", "Kvp_torque_s_per_rad", "torque unit s/rad", false, true, &Kvp, nullptr, nullptr},
    {"Tn", "Tn_s", "s", false, true, &Tn, nullptr, nullptr},
    {"kff", "kff", "1", true, false, &kff, [](const LinearPlant&) { return 1.0; }, nullptr},
    {"Jff", "Jff_torque_s2_per_rad", "torque unit s^2/rad", true, false, &Jff,
     [](const LinearPlant& p) { return p.J_kg_m2; }, nullptr},
};
}  // namespace

std::span<const LawGain> CascadeLaw::gains() const noexcept { return kGains; }

}  // namespace twin::controller::laws
