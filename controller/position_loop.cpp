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

namespace {

bool smooths(const LawSetup& setup) {
  return setup.command_average_ticks > 1 || setup.command_lag_a > 0.0 || setup.command_delay_ticks > 0;
}

/// The reference through the moving average, the lag and the dead time, one tick.
double smooth_reference(const LawSetup& setup, double x_ref_mm, PositionLoopState& s) {
  const int n = setup.command_average_ticks;
  double x = x_ref_mm;
  if (n > 1) {
    s.ref_window_head = (s.ref_window_head + 1) % n;
    s.ref_window[static_cast<std::size_t>(s.ref_window_head)] = x_ref_mm;
    double sum = 0.0;
    for (int j = 0; j < n; ++j) sum += s.ref_window[static_cast<std::size_t>(j)];
    x = sum / n;
  }
  if (setup.command_lag_a > 0.0) {
    s.ref_lagged_mm = setup.command_lag_a * s.ref_lagged_mm + (1.0 - setup.command_lag_a) * x;
    x = s.ref_lagged_mm;
  }
  if (const int d = setup.command_delay_ticks; d > 0) {
    s.ref_delay_head = (s.ref_delay_head + 1) % (d + 1);
    s.ref_delay_line[static_cast<std::size_t>(s.ref_delay_head)] = x;
    x = s.ref_delay_line[static_cast<std::size_t>((s.ref_delay_head + 1) % (d + 1))];  // written d ticks ago
  }
  return x;
}

}  // namespace

double prime_reference_smoothing(const LawSetup& setup, double x_ref_mm, double v_ref_mm_per_s,
                                 PositionLoopState& s) noexcept {
  const int n = setup.command_average_ticks;
  const double step = v_ref_mm_per_s * setup.Ts_s;
  // The window holds the ramp's last n references, the newest at the head.
  s.ref_window_head = 0;
  for (int j = 0; j < n; ++j) s.ref_window[static_cast<std::size_t>((n - j) % n)] = x_ref_mm - j * step;
  const double averaged = x_ref_mm - 0.5 * (n - 1) * step;
  // y = a y + (1 - a) u on a ramp of `step` a tick lags it by step a / (1 - a).
  const double a = setup.command_lag_a;
  s.ref_lagged_mm = a > 0.0 ? averaged - step * a / (1.0 - a) : averaged;
  // The dead time's line holds the lag's last d + 1 outputs, newest at the head.
  const int d = setup.command_delay_ticks;
  s.ref_delay_head = 0;
  for (int j = 0; j <= d; ++j) s.ref_delay_line[static_cast<std::size_t>((d + 1 - j) % (d + 1))] = s.ref_lagged_mm - j * step;
  return s.ref_lagged_mm - d * step;
}

void PositionLoop::reset(double x_ref0_mm, double x_meas0_mm) noexcept {
  state_ = PositionLoopState{};
  state_.ref_window.fill(x_ref0_mm);
  state_.ref_lagged_mm = x_ref0_mm;
  state_.ref_delay_line.fill(x_ref0_mm);
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
  // The error from the reference the loop follows; the feedforward's speed
  // from it too, or from the one given (LawSetup::feedforward_unsmoothed).
  const double x_given_mm = x_ref_mm;
  if (smooths(setup_)) x_ref_mm = smooth_reference(setup_, x_ref_mm, state_);
  const double x_ff_mm = setup_.feedforward_unsmoothed ? x_given_mm : x_ref_mm;
  out.e_mm = x_ref_mm - x_meas_mm;
  out.v_ref_mm_per_s = (x_ff_mm - state_.x_ref_prev_mm) / Ts;
  out.a_ref_mm_per_s2 = (out.v_ref_mm_per_s - state_.v_ref_prev_mm_per_s) / Ts;
  law_->step(params_, setup_, x_meas_mm, v_meas_mm_per_s, state_, out);
  state_.e_prev_mm = out.e_mm;
  state_.x_ref_prev_mm = x_ff_mm;
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
