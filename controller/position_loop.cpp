#include "controller/position_loop.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <fmt/format.h>

#include "twin/core/check.hpp"
#include "twin/core/error.hpp"

namespace twin::controller {

std::string_view loop_law_name(LoopLaw law) noexcept { return law == LoopLaw::kCascade ? "cascade" : "fadal"; }

std::optional<LoopLaw> parse_loop_law(std::string_view name) noexcept {
  if (name == "fadal") return LoopLaw::kFadal;
  if (name == "cascade") return LoopLaw::kCascade;
  return std::nullopt;
}

void validate_sample_period(std::string_view where, double Ts_s) {
  if (!std::isfinite(Ts_s)) throw ConfigError(fmt::format("{}: Ts = {} must be finite", where, Ts_s));
  if (!(Ts_s > 0.0 && Ts_s <= 0.1))
    throw ConfigError(fmt::format("{}: Ts = {} s must be in (0, 0.1]", where, Ts_s));
}

void PositionLoopParams::validate(std::string_view where) const {
  auto finite = [&](const char* name, double v) {
    if (!std::isfinite(v))
      throw ConfigError(fmt::format("{}: {} = {} must be finite", where, name, v));
  };
  if (law == LoopLaw::kCascade) {
    const CascadeGains& c = cascade;
    finite("Kv", c.Kv_per_s);
    finite("kff", c.kff);
    finite("Kvp", c.Kvp_torque_s_per_rad);
    finite("Tn", c.Tn_s);
    finite("tau_i", c.tau_i_s);
    finite("T_max", c.T_max);
    finite("Jff", c.Jff_torque_s2_per_rad);
    if (!(c.Kv_per_s > 0.0)) throw ConfigError(fmt::format("{}: Kv = {} 1/s must be > 0", where, c.Kv_per_s));
    if (c.kff < 0.0 || c.kff > 1.5)
      throw ConfigError(fmt::format("{}: kff = {} must be in [0, 1.5]", where, c.kff));
    if (!(c.Kvp_torque_s_per_rad > 0.0))
      throw ConfigError(fmt::format("{}: Kvp = {} must be > 0", where, c.Kvp_torque_s_per_rad));
    if (c.Tn_s < 0.0 || c.tau_i_s < 0.0 || c.Jff_torque_s2_per_rad < 0.0)
      throw ConfigError(fmt::format("{}: Tn, tau_i, Jff = {}, {}, {} must be >= 0", where, c.Tn_s, c.tau_i_s,
                                    c.Jff_torque_s2_per_rad));
    if (!(c.T_max > 0.0)) throw ConfigError(fmt::format("{}: T_max = {} must be > 0", where, c.T_max));
    return;
  }
  finite("Kp", Kp_V_per_mm);
  finite("Ki", Ki_V_per_s_mm);
  finite("Kd", Kd_V_s_per_mm);
  finite("K1", K1_V_s2_per_mm);
  finite("K2", K2_V_s_per_mm);
  finite("u_max", u_max_V);
  if (!(u_max_V > 0.0))
    throw ConfigError(fmt::format("{}: u_max = {} V must be > 0", where, u_max_V));
  if (Kp_V_per_mm < 0.0 || Ki_V_per_s_mm < 0.0 || Kd_V_s_per_mm < 0.0)
    throw ConfigError(fmt::format("{}: Kp, Ki, Kd = {}, {}, {} must be >= 0", where, Kp_V_per_mm,
                                  Ki_V_per_s_mm, Kd_V_s_per_mm));
}

PositionLoop::PositionLoop(const PositionLoopParams& params, double Ts_s, const DriveScale& drive)
    : params_(params), Ts_s_(Ts_s), drive_(drive) {
  validate_sample_period("position loop", Ts_s_);
  params_.validate("position loop");
  if (params_.law == LoopLaw::kCascade) {
    if (!(drive_.rg_mm_per_rad > 0.0) || !(drive_.Ka_A_per_V > 0.0) || !(drive_.Kt_Nm_per_A > 0.0))
      throw ConfigError(fmt::format("position loop: the cascade needs rg, Ka, Kt > 0 (got {}, {}, {})",
                                    drive_.rg_mm_per_rad, drive_.Ka_A_per_V, drive_.Kt_Nm_per_A));
    lag_a_ = params_.cascade.tau_i_s > 0.0 ? std::exp(-Ts_s_ / params_.cascade.tau_i_s) : 0.0;
  }
}

void PositionLoop::reset(double x_ref0_mm, double x_meas0_mm) noexcept {
  state_ = PositionLoopState{};
  state_.x_ref_prev_mm = x_ref0_mm;
  state_.e_prev_mm = x_ref0_mm - x_meas0_mm;
  state_.x_meas_prev_mm = x_meas0_mm;
  primed_ = true;
}

void PositionLoop::cascade_step(PositionLoopOutput& out, double x_meas_mm, double v_meas_mm_per_s) {
  const CascadeGains& g = params_.cascade;
  const double Ts = Ts_s_;
  const double rg = drive_.rg_mm_per_rad;
  const double v_meas = std::isfinite(v_meas_mm_per_s) ? v_meas_mm_per_s : (x_meas_mm - state_.x_meas_prev_mm) / Ts;
  out.vcmd_mm_per_s = g.Kv_per_s * out.e_mm + g.kff * out.v_ref_mm_per_s;
  const double ev = (out.vcmd_mm_per_s - v_meas) / rg;
  const double Iv = state_.Iv_rad + Ts * ev;
  const double integral = g.Tn_s > 0.0 ? Iv / g.Tn_s : 0.0;
  const double T_unclamped = g.Kvp_torque_s_per_rad * (ev + integral) + g.Jff_torque_s2_per_rad * out.a_ref_mm_per_s2 / rg;
  const double T = std::clamp(T_unclamped, -g.T_max, g.T_max);
  out.saturated = T != T_unclamped;
  // Anti-windup: the integral is frozen while the limit holds the command.
  if (!out.saturated) state_.Iv_rad = Iv;
  state_.T_filtered = lag_a_ * state_.T_filtered + (1.0 - lag_a_) * T;
  out.torque_cmd = state_.T_filtered;
  const double per_V = drive_.Ka_A_per_V * drive_.Kt_Nm_per_A;
  out.u_V = state_.T_filtered / per_V;
  out.u_unclamped_V = T_unclamped / per_V;
  state_.x_meas_prev_mm = x_meas_mm;
}

PositionLoopOutput PositionLoop::step(std::int64_t k, double x_ref_mm, double x_meas_mm, double v_meas_mm_per_s) {
  if (!primed_) reset(x_ref_mm, x_meas_mm);
  if (state_.last_k >= 0 && k != state_.last_k + 1)
    throw InternalError(fmt::format("position loop stepped at tick {} after tick {}", k, state_.last_k));
  const double Ts = Ts_s_;
  PositionLoopOutput out;
  out.e_mm = x_ref_mm - x_meas_mm;
  out.v_ref_mm_per_s = (x_ref_mm - state_.x_ref_prev_mm) / Ts;
  out.a_ref_mm_per_s2 = (out.v_ref_mm_per_s - state_.v_ref_prev_mm_per_s) / Ts;
  if (params_.law == LoopLaw::kCascade) {
    cascade_step(out, x_meas_mm, v_meas_mm_per_s);
  } else {
    const double I = state_.I_mm_s + Ts * out.e_mm;
    out.u_unclamped_V = params_.Kp_V_per_mm * out.e_mm + params_.Ki_V_per_s_mm * I +
                        params_.Kd_V_s_per_mm * (out.e_mm - state_.e_prev_mm) / Ts +
                        params_.K1_V_s2_per_mm * out.a_ref_mm_per_s2 + params_.K2_V_s_per_mm * out.v_ref_mm_per_s;
    out.u_V = std::clamp(out.u_unclamped_V, -params_.u_max_V, params_.u_max_V);
    out.saturated = out.u_V != out.u_unclamped_V;
    state_.I_mm_s = I;
  }
  state_.e_prev_mm = out.e_mm;
  state_.x_ref_prev_mm = x_ref_mm;
  state_.v_ref_prev_mm_per_s = out.v_ref_mm_per_s;
  state_.last_k = k;
  return out;
}

}  // namespace twin::controller
