#pragma once
/// The CNC's digital position loop per axis, at the machine's period Ts, e[k] = x_ref[k] - x_meas[k]:
///   v_ref[k] = (x_ref[k] - x_ref[k-1]) / Ts,  a_ref[k] = (v_ref[k] - v_ref[k-1]) / Ts
/// and the command u[k] from the axis' law (controller/law.hpp; the laws in
/// controller/laws/: FADAL fadal.hpp, cascade cascade.hpp, spec/measured-data.md).
/// v_meas is the motor speed the drive's own sensor gives (rg w); where the
/// caller has none, the encoder's backward difference.
///
/// u[k] is held by the drive until the next sample.
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <string_view>

namespace twin::controller {

/// The registered laws (controller/law.cpp registers each).
enum class LoopLaw { kFadal, kCascade };
class Law;
std::string_view loop_law_name(LoopLaw law) noexcept;
/// A registered law's name ("fadal", "cascade"); nullopt for anything else.
std::optional<LoopLaw> parse_loop_law(std::string_view name) noexcept;

/// Gains of the cascade law. The torque unit is N m, or the log's own unit
/// for a drive identified in it (then Kt = 1).
struct CascadeGains {
  double Kv_per_s{0.0};          ///< position-loop gain
  double kff{0.0};               ///< velocity feedforward fraction
  double Kvp_torque_s_per_rad{0.0};  ///< velocity-loop proportional gain
  double Tn_s{0.0};              ///< velocity-loop integral time (0: no integral)
  double tau_i_s{0.0};           ///< current-loop lag (0: ideal)
  double T_max{1e9};             ///< torque limit
  double Jff_torque_s2_per_rad{0.0};  ///< acceleration (torque) feedforward
  /// The velocity and current loops' period where they run faster than the
  /// position loop (most drives: 125 to 250 us under a 1 ms position loop),
  /// Ts a whole multiple of it; 0: the position loop's Ts.
  double Tv_s{0.0};
  /// The CNC's smoothing of the reference after its interpolator, before the
  /// position loop (a log's reference is then ahead of what the loop
  /// follows): a moving average over this window, a whole multiple of Ts
  /// (0: none), then a first-order lag of command_lag_s (0: none). It lies
  /// outside the feedback loop.
  double command_average_s{0.0};
  double command_lag_s{0.0};
  /// A dead time of whole periods after the smoothing, before the position
  /// loop (a CNC that holds an axis's setpoint back to match a slower axis's
  /// response, or hands it to the drive some cycles after the interpolator);
  /// 0: none.
  double command_delay_s{0.0};
  /// 1: the feedforward (kff, Jff) takes the reference as given and only the
  /// position loop's error the smoothed one (a CNC that delays the position
  /// setpoint to match its velocity loop while feeding the speed forward);
  /// 0: both the smoothed one.
  double feedforward_unsmoothed{0.0};
};

/// The longest moving average of the reference, in periods.
inline constexpr int kMaxCommandAverageTicks = 128;
/// The longest dead time of the reference, in periods.
inline constexpr int kMaxCommandDelayTicks = 128;

/// What the cascade needs of the drive it commands.
struct DriveScale {
  double rg_mm_per_rad{1.0};
  double Ka_A_per_V{1.0};
  double Kt_Nm_per_A{1.0};
};

/// The most inner (velocity-loop) ticks a law may run in one period.
inline constexpr int kMaxInnerTicks = 64;

/// What a loop computes once at construction for its law's step.
struct LawSetup {
  double Ts_s{1e-4};
  DriveScale drive;
  double lag_a{0.0};  ///< cascade: exp(-Tv / tau_i) of the current loop (0: ideal)
  /// The law's inner (velocity-loop) ticks per period, 1 to kMaxInnerTicks, and
  /// their period Ts / inner_ticks.
  int inner_ticks{1};
  double Tv_s{1e-4};
  /// The reference's smoothing (CascadeGains::command_average_s, command_lag_s):
  /// the moving average's periods (1: none) and exp(-Ts / command_lag) (0: none).
  int command_average_ticks{1};
  double command_lag_a{0.0};
  int command_delay_ticks{0};  ///< CascadeGains::command_delay_s in periods
  bool feedforward_unsmoothed{false};
};

/// The gains of every law; an axis uses those of its `law`.
struct PositionLoopParams {
  LoopLaw law{LoopLaw::kFadal};
  double Kp_V_per_mm{0.0};
  double Ki_V_per_s_mm{0.0};
  double Kd_V_s_per_mm{0.0};
  double K1_V_s2_per_mm{0.0};
  double K2_V_s_per_mm{0.0};
  double u_max_V{10.0};
  CascadeGains cascade;
  /// Its law's validation of the gains.
  void validate(std::string_view where) const;
};

/// Throws ConfigError "<where>: Ts = ... s must be in (0, 0.1]" (or "must be finite").
void validate_sample_period(std::string_view where, double Ts_s);

struct PositionLoopState {
  double I_mm_s{0.0};
  double e_prev_mm{0.0};
  double x_ref_prev_mm{0.0};  ///< the reference the feedforward takes (smoothed or as given)
  double v_ref_prev_mm_per_s{0.0};
  // Cascade only.
  double Iv_rad{0.0};
  double T_filtered{0.0};
  double x_meas_prev_mm{0.0};
  // The reference's smoothing (LawSetup::command_average_ticks, command_lag_a):
  // the last references, newest at ref_window_head, and the lag's output.
  std::array<double, kMaxCommandAverageTicks> ref_window{};
  int ref_window_head{0};
  double ref_lagged_mm{0.0};
  // The dead time (LawSetup::command_delay_ticks = d): the last d + 1
  // smoothed references, newest at ref_delay_head.
  std::array<double, kMaxCommandDelayTicks + 1> ref_delay_line{};
  int ref_delay_head{0};
  std::int64_t last_k{-1};
};

/// The reference the loop follows once the law's smoothing (CascadeGains::
/// command_average_s, command_lag_s, command_delay_s) has been primed for steady motion at
/// v_ref_mm_per_s through x_ref_mm at the tick: sets `s`'s smoothing state
/// and returns the smoothed reference at the tick (x_ref_mm where there is
/// no smoothing).
double prime_reference_smoothing(const LawSetup& setup, double x_ref_mm, double v_ref_mm_per_s,
                                 PositionLoopState& s) noexcept;

/// One output of the law at a tick, with its terms (for traces and analysis).
struct PositionLoopOutput {
  double u_V{0.0};            ///< clamped command to the drive
  double u_unclamped_V{0.0};  ///< before the clamp (FADAL) or the torque limit (cascade), in V
  double e_mm{0.0};
  double v_ref_mm_per_s{0.0};
  double a_ref_mm_per_s2{0.0};
  double vcmd_mm_per_s{0.0};  ///< cascade: the position loop's velocity command
  double torque_cmd{0.0};     ///< cascade: the torque command after the current loop
  /// The torque the law asks of the drive, before the current loop and any
  /// delay (cascade: the velocity loop's output after the torque limit;
  /// FADAL: Ka Kt u).
  double torque_demand{0.0};
  bool saturated{false};
};

class PositionLoop {
 public:
  /// `Ts_s` is the machine's sample period.
  PositionLoop(const PositionLoopParams& params, double Ts_s, const DriveScale& drive = {});
  /// Starts from rest at x_ref0: v_ref and a_ref are 0 at the first tick and
  /// the derivative term sees e[-1] = e[0] (no kick at the first sample).
  void reset(double x_ref0_mm, double x_meas0_mm) noexcept;
  /// Must be called once per tick with k = last k + 1 (the first call after
  /// reset may take any k). Throws InternalError when out of order.
  /// `v_meas_mm_per_s` is the drive's speed sensor (cascade only; NaN: the
  /// encoder's backward difference).
  PositionLoopOutput step(std::int64_t k, double x_ref_mm, double x_meas_mm,
                          double v_meas_mm_per_s = std::numeric_limits<double>::quiet_NaN());
  /// The law's inner ticks per period: 1, or Ts / Tv for a cascade whose
  /// velocity loop runs faster than the position loop.
  int inner_ticks() const noexcept { return setup_.inner_ticks; }
  /// Inner tick q (1 to inner_ticks() - 1) of the period `step` began: the
  /// velocity and current loops again on the speed of that instant, the
  /// position loop's output in `out` held; updates the command in `out`.
  void inner_step(int q, double v_meas_mm_per_s, PositionLoopOutput& out);
  const PositionLoopParams& params() const noexcept { return params_; }
  const LawSetup& setup() const noexcept { return setup_; }
  double Ts_s() const noexcept { return setup_.Ts_s; }
  const PositionLoopState& state() const noexcept { return state_; }
  void set_state(const PositionLoopState& s) noexcept {
    state_ = s;
    primed_ = true;
  }

 private:
  PositionLoopParams params_;
  const Law* law_;
  LawSetup setup_;
  PositionLoopState state_;
  bool primed_{false};
};

}  // namespace twin::controller
