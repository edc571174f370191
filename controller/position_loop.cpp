#include "controller/position_loop.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <fmt/format.h>

#include "twin/core/check.hpp"
#include "twin/core/error.hpp"

namespace twin::controller {

void PositionLoopParams::validate(std::string_view where) const {
  auto finite = [&](const char* name, double v) {
    if (!std::isfinite(v))
      throw ConfigError(fmt::format("{}: {} = {} must be finite", where, name, v));
  };
  finite("Kp", Kp_V_per_mm);
  finite("Ki", Ki_V_per_s_mm);
  finite("Kd", Kd_V_s_per_mm);
  finite("K1", K1_V_s2_per_mm);
  finite("K2", K2_V_s_per_mm);
  finite("u_max", u_max_V);
  finite("Ts", Ts_s);
  if (!(u_max_V > 0.0))
    throw ConfigError(fmt::format("{}: u_max = {} V must be > 0", where, u_max_V));
  if (!(Ts_s > 0.0 && Ts_s <= 0.1))
    throw ConfigError(fmt::format("{}: Ts = {} s must be in (0, 0.1]", where, Ts_s));
  if (Kp_V_per_mm < 0.0 || Ki_V_per_s_mm < 0.0 || Kd_V_s_per_mm < 0.0)
    throw ConfigError(fmt::format("{}: Kp, Ki, Kd = {}, {}, {} must be >= 0", where, Kp_V_per_mm,
                                  Ki_V_per_s_mm, Kd_V_s_per_mm));
}

PositionLoop::PositionLoop(const PositionLoopParams& params) : params_(params) {
  params_.validate("position loop");
}

void PositionLoop::reset(double x_ref0_mm, double x_meas0_mm) noexcept {
  state_ = PositionLoopState{};
  state_.x_ref_prev_mm = x_ref0_mm;
  state_.e_prev_mm = x_ref0_mm - x_meas0_mm;
  primed_ = true;
}

PositionLoopOutput PositionLoop::step(std::int64_t k, double x_ref_mm, double x_meas_mm) {
  if (!primed_) reset(x_ref_mm, x_meas_mm);
  if (state_.last_k >= 0 && k != state_.last_k + 1)
    throw InternalError(fmt::format("position loop stepped at tick {} after tick {}", k, state_.last_k));
  const double Ts = params_.Ts_s;
  PositionLoopOutput out;
  out.e_mm = x_ref_mm - x_meas_mm;
  out.v_ref_mm_per_s = (x_ref_mm - state_.x_ref_prev_mm) / Ts;
  out.a_ref_mm_per_s2 = (out.v_ref_mm_per_s - state_.v_ref_prev_mm_per_s) / Ts;
  const double I = state_.I_mm_s + Ts * out.e_mm;
  out.u_unclamped_V = params_.Kp_V_per_mm * out.e_mm + params_.Ki_V_per_s_mm * I +
                      params_.Kd_V_s_per_mm * (out.e_mm - state_.e_prev_mm) / Ts +
                      params_.K1_V_s2_per_mm * out.a_ref_mm_per_s2 +
                      params_.K2_V_s_per_mm * out.v_ref_mm_per_s;
  out.u_V = std::clamp(out.u_unclamped_V, -params_.u_max_V, params_.u_max_V);
  out.saturated = out.u_V != out.u_unclamped_V;
  state_.I_mm_s = I;
  state_.e_prev_mm = out.e_mm;
  state_.x_ref_prev_mm = x_ref_mm;
  state_.v_ref_prev_mm_per_s = out.v_ref_mm_per_s;
  state_.last_k = k;
  return out;
}

}  // namespace twin::controller
