#include "controller/position_loop.hpp"

#include <cmath>

#include <fmt/format.h>

#include "controller/law.hpp"
#include "twin/core/error.hpp"

namespace twin::controller {

void validate_sample_period(std::string_view where, double Ts_s) {
  if (!std::isfinite(Ts_s)) throw ConfigError(fmt::format("{}: Ts = {} must be finite", where, Ts_s));
  if (!(Ts_s > 0.0 && Ts_s <= 0.1))
    throw ConfigError(fmt::format("{}: Ts = {} s must be in (0, 0.1]", where, Ts_s));
}

void PositionLoopParams::validate(std::string_view where) const { law_of(law).validate(*this, where); }

PositionLoop::PositionLoop(const PositionLoopParams& params, double Ts_s, const DriveScale& drive)
    : params_(params), law_(&law_of(params.law)) {
  validate_sample_period("position loop", Ts_s);
  params_.validate("position loop");
  setup_ = law_->setup(params_, Ts_s, drive);
}

void PositionLoop::reset(double x_ref0_mm, double x_meas0_mm) noexcept {
  state_ = PositionLoopState{};
  state_.x_ref_prev_mm = x_ref0_mm;
  state_.e_prev_mm = x_ref0_mm - x_meas0_mm;
  state_.x_meas_prev_mm = x_meas0_mm;
  primed_ = true;
}

PositionLoopOutput PositionLoop::step(std::int64_t k, double x_ref_mm, double x_meas_mm, double v_meas_mm_per_s) {
  if (!primed_) reset(x_ref_mm, x_meas_mm);
  if (state_.last_k >= 0 && k != state_.last_k + 1)
    throw InternalError(fmt::format("position loop stepped at tick {} after tick {}", k, state_.last_k));
  const double Ts = setup_.Ts_s;
  PositionLoopOutput out;
  out.e_mm = x_ref_mm - x_meas_mm;
  out.v_ref_mm_per_s = (x_ref_mm - state_.x_ref_prev_mm) / Ts;
  out.a_ref_mm_per_s2 = (out.v_ref_mm_per_s - state_.v_ref_prev_mm_per_s) / Ts;
  law_->step(params_, setup_, x_meas_mm, v_meas_mm_per_s, state_, out);
  state_.e_prev_mm = out.e_mm;
  state_.x_ref_prev_mm = x_ref_mm;
  state_.v_ref_prev_mm_per_s = out.v_ref_mm_per_s;
  state_.last_k = k;
  return out;
}

void PositionLoop::inner_step(int q, double v_meas_mm_per_s, PositionLoopOutput& out) {
  if (q < 1 || q >= setup_.inner_ticks)
    throw InternalError(fmt::format("position loop: inner tick {} of {}", q, setup_.inner_ticks));
  law_->inner_step(params_, setup_, v_meas_mm_per_s, state_, out);
}

}  // namespace twin::controller
