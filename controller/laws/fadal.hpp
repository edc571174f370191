#pragma once
/// The FADAL law (spec/measured-data.md; the shipped fadal2216), e[k] = x_ref[k] - x_meas[k]:
///   I[k] = I[k-1] + Ts e[k]
///   u[k] = Kp e + Ki I + Kd (e[k] - e[k-1]) / Ts + K1 a_ref + K2 v_ref, clamped to +-u_max
/// Its linear controller has the state [I[k-1] (when Ki > 0), e[k-1], x_ref[k-1], v_ref[k-1]].
#include "controller/law.hpp"

namespace twin::controller::laws {

/// The model-based feedforward gains that cancel the linear plant:
/// K1 = J / (Ka Kt rg) [V s^2/mm], K2 = B / (Ka Kt rg) [V s/mm].
struct FeedforwardGains {
  double K1_V_s2_per_mm{0.0};
  double K2_V_s_per_mm{0.0};
};
FeedforwardGains model_feedforward(const LinearPlant& plant);

class FadalLaw final : public Law {
 public:
  LoopLaw id() const noexcept override { return LoopLaw::kFadal; }
  std::string_view name() const noexcept override { return "fadal"; }
  void validate(const PositionLoopParams& g, std::string_view where) const override;
  void step(const PositionLoopParams& g, const LawSetup& setup, double x_meas_mm, double v_meas_mm_per_s,
            PositionLoopState& s, PositionLoopOutput& out) const override;
  double steady_state(const PositionLoopParams& g, const SteadyMotion& m, double x_ref_mm,
                      PositionLoopState& s) const override;
  std::span<const LawGain> gains() const noexcept override;
  std::string_view command_name() const noexcept override { return "u"; }
  std::string_view command_unit() const noexcept override { return "V"; }
  std::string_view command_limit_name() const noexcept override { return "u_max"; }
  double torque_per_command(const LinearPlant& p) const override { return p.Ka_A_per_V * p.Kt_Nm_per_A; }
  double command_limit(const PositionLoopParams& g) const override { return g.u_max_V; }
  ControllerRealisation realise(const PositionLoopParams& g, double Ts_s, const LinearPlant& plant) const override;
};

}  // namespace twin::controller::laws
