#pragma once
/// The cascade (spec/measured-data.md; most industrial CNCs): a P position loop, a PI
/// velocity loop on the motor speed, a current loop as a first-order lag, a torque limit:
///   vcmd[k]  = Kv e[k] + kff v_ref[k]                               (mm/s)
///   ev[k]    = (vcmd[k] - v_meas[k]) / rg                           (rad/s at the motor)
///   Iv[k]    = Iv[k-1] + Ts ev[k]   (frozen while the torque command is limited: anti-windup)
/// (with Tv > 0 the velocity and current loops run Ts / Tv times a period, on the speed
/// of each instant, with Tv in place of Ts in Iv and in a; vcmd and a_ref held)
///   Tc[k]    = Kvp (ev[k] + Iv[k] / Tn) + Jff a_ref[k] / rg, clamped to +-T_max
///   Tf[k]    = a Tf[k-1] + (1 - a) Tc[k],  a = exp(-Ts / tau_i)     (current loop sampled at Ts)
///   u[k]     = Tf[k] / (Ka Kt)   so that the drive's i = Ka u = Tf / Kt and Tm = Tf.
/// Tn = 0 switches the integral off; tau_i = 0 makes the current loop ideal.
/// x_ref may first pass the CNC's smoothing (command_average_s, command_lag_s:
/// PositionLoop applies it), outside the feedback loop; realise() is the loop
/// from the smoothed reference on.
/// Its linear controller has the state [Iv[k-1] (when Tn > 0), Tf[k-1] (when tau_i > 0),
/// x_ref[k-1], v_ref[k-1]], its speed feedback the drive's own speed (rg w at the tick, as
/// the co-simulation gives it). `twin tune` searches the feedback gains Kv, Kvp, Tn and
/// keeps the machine's feedforward kff, Jff (docs/tuning.md, "The cascade law").
#include "controller/law.hpp"

namespace twin::controller::laws {

class CascadeLaw final : public Law {
 public:
  LoopLaw id() const noexcept override { return LoopLaw::kCascade; }
  std::string_view name() const noexcept override { return "cascade"; }
  void validate(const PositionLoopParams& g, std::string_view where) const override;
  LawSetup setup(const PositionLoopParams& g, double Ts_s, const DriveScale& drive) const override;
  void step(const PositionLoopParams& g, const LawSetup& setup, double x_meas_mm, double v_meas_mm_per_s,
            PositionLoopState& s, PositionLoopOutput& out) const override;
  void inner_step(const PositionLoopParams& g, const LawSetup& setup, double v_meas_mm_per_s, PositionLoopState& s,
                  PositionLoopOutput& out) const override;
  /// The most velocity-loop ticks a position-loop period may hold.
  /// Ts / Tv (1 where Tv is 0); ConfigError where Tv does not divide Ts into 1 to kMaxInnerTicks.
  static int inner_ticks(const CascadeGains& g, double Ts_s);
  double steady_state(const PositionLoopParams& g, const SteadyMotion& m, double x_ref_mm,
                      PositionLoopState& s) const override;
  std::span<const LawGain> gains() const noexcept override;
  std::string_view command_name() const noexcept override { return "torque"; }
  std::string_view command_unit() const noexcept override { return "torque unit"; }
  std::string_view command_limit_name() const noexcept override { return "T_max"; }
  double torque_per_command(const LinearPlant&) const override { return 1.0; }
  double command_limit(const PositionLoopParams& g) const override { return g.cascade.T_max; }
  ControllerRealisation realise(const PositionLoopParams& g, double Ts_s, const LinearPlant& plant) const override;

 private:
  /// The velocity loop, the limit and the current loop at one inner tick, out.vcmd given.
  static void velocity_tick(const PositionLoopParams& g, const LawSetup& setup, double v_meas_mm_per_s,
                            PositionLoopState& s, PositionLoopOutput& out);
};

}  // namespace twin::controller::laws
