#pragma once
/// The FADAL digital position loop of spec/measured-data.md, at period Ts:
///   e[k]     = x_ref[k] - x_meas[k]
///   v_ref[k] = (x_ref[k] - x_ref[k-1]) / Ts,  a_ref[k] = (v_ref[k] - v_ref[k-1]) / Ts
///   I[k]     = I[k-1] + Ts e[k]
///   u[k]     = Kp e + Ki I + Kd (e[k] - e[k-1]) / Ts + K1 a_ref + K2 v_ref, clamped to +-u_max
/// u[k] is held by the drive until the next sample.
#include <cstdint>
#include <string_view>

namespace twin::controller {

struct PositionLoopParams {
  double Kp_V_per_mm{0.0};
  double Ki_V_per_s_mm{0.0};
  double Kd_V_s_per_mm{0.0};
  double K1_V_s2_per_mm{0.0};
  double K2_V_s_per_mm{0.0};
  double u_max_V{10.0};
  double Ts_s{1e-4};
  void validate(std::string_view where) const;
};

struct PositionLoopState {
  double I_mm_s{0.0};
  double e_prev_mm{0.0};
  double x_ref_prev_mm{0.0};
  double v_ref_prev_mm_per_s{0.0};
  std::int64_t last_k{-1};
};

/// One output of the law at a tick, with its terms (for traces and analysis).
struct PositionLoopOutput {
  double u_V{0.0};            ///< clamped command
  double u_unclamped_V{0.0};  ///< before the clamp
  double e_mm{0.0};
  double v_ref_mm_per_s{0.0};
  double a_ref_mm_per_s2{0.0};
  bool saturated{false};
};

class PositionLoop {
 public:
  explicit PositionLoop(const PositionLoopParams& params);
  /// Starts from rest at x_ref0: v_ref and a_ref are 0 at the first tick and
  /// the derivative term sees e[-1] = e[0] (no kick at the first sample).
  void reset(double x_ref0_mm, double x_meas0_mm) noexcept;
  /// Must be called once per tick with k = last k + 1 (the first call after
  /// reset may take any k). Throws InternalError when out of order.
  PositionLoopOutput step(std::int64_t k, double x_ref_mm, double x_meas_mm);
  const PositionLoopParams& params() const noexcept { return params_; }
  const PositionLoopState& state() const noexcept { return state_; }
  void set_state(const PositionLoopState& s) noexcept {
    state_ = s;
    primed_ = true;
  }

 private:
  PositionLoopParams params_;
  PositionLoopState state_;
  bool primed_{false};
};

}  // namespace twin::controller
