#include "controller/laws/fadal.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "controller/laws/realisation_builder.hpp"
#include "twin/core/error.hpp"

namespace twin::controller::laws {

FeedforwardGains model_feedforward(const LinearPlant& p) {
  const double g = p.Ka_A_per_V * p.Kt_Nm_per_A * p.rg_mm_per_rad;
  return FeedforwardGains{p.J_kg_m2 / g, p.B_kg_m2_per_s / g};
}

void FadalLaw::validate(const PositionLoopParams& g, std::string_view where) const {
  require_finite(where, {{"Kp", g.Kp_V_per_mm},
                         {"Ki", g.Ki_V_per_s_mm},
                         {"Kd", g.Kd_V_s_per_mm},
                         {"K1", g.K1_V_s2_per_mm},
                         {"K2", g.K2_V_s_per_mm},
                         {"u_max", g.u_max_V}});
  if (!(g.u_max_V > 0.0)) throw ConfigError(fmt::format("{}: u_max = {} V must be > 0", where, g.u_max_V));
  if (g.Kp_V_per_mm < 0.0 || g.Ki_V_per_s_mm < 0.0 || g.Kd_V_s_per_mm < 0.0)
    throw ConfigError(fmt::format("{}: Kp, Ki, Kd = {}, {}, {} must be >= 0", where, g.Kp_V_per_mm,
                                  g.Ki_V_per_s_mm, g.Kd_V_s_per_mm));
}

void FadalLaw::step(const PositionLoopParams& g, const LawSetup& setup, double, double, PositionLoopState& s,
                    PositionLoopOutput& out) const {
  const double Ts = setup.Ts_s;
  const double I = s.I_mm_s + Ts * out.e_mm;
  out.u_unclamped_V = g.Kp_V_per_mm * out.e_mm + g.Ki_V_per_s_mm * I +
                      g.Kd_V_s_per_mm * (out.e_mm - s.e_prev_mm) / Ts + g.K1_V_s2_per_mm * out.a_ref_mm_per_s2 +
                      g.K2_V_s_per_mm * out.v_ref_mm_per_s;
  out.u_V = std::clamp(out.u_unclamped_V, -g.u_max_V, g.u_max_V);
  out.saturated = out.u_V != out.u_unclamped_V;
  out.torque_demand = out.u_V * setup.drive.Ka_A_per_V * setup.drive.Kt_Nm_per_A;
  s.I_mm_s = I;
}

/// With no error, the integrator gives the voltage the velocity feedforward does not.
double FadalLaw::steady_state(const PositionLoopParams& g, const SteadyMotion& m, double, PositionLoopState& s) const {
  const double u_needed = m.torque_needed / (m.drive.Ka_A_per_V * m.drive.Kt_Nm_per_A);
  s.I_mm_s = g.Ki_V_per_s_mm > 0.0 ? (u_needed - g.K2_V_s_per_mm * m.v_ref_mm_per_s) / g.Ki_V_per_s_mm : 0.0;
  s.e_prev_mm = 0.0;
  return 0.0;
}

ControllerRealisation FadalLaw::realise(const PositionLoopParams& g, double Ts, const LinearPlant&) const {
  const bool integral = g.Ki_V_per_s_mm != 0.0;
  const int iI = integral ? 0 : -1, ie = integral ? 1 : 0, ir = ie + 1, iv = ie + 2, n = ie + 3;
  RealisationBuilder b(n);
  const Row e = b.r() - b.x();
  const Row v = (b.r() - b.state(ir)) / Ts;
  const Row a = (v - b.state(iv)) / Ts;
  Row command = g.Kp_V_per_mm * e + g.Kd_V_s_per_mm * (e - b.state(ie)) / Ts + g.K1_V_s2_per_mm * a +
                g.K2_V_s_per_mm * v;
  if (integral) {
    const Row I = b.state(iI) + Ts * e;
    command += g.Ki_V_per_s_mm * I;
    b.set_next(iI, I);
  }
  b.set_next(ie, e);
  b.set_next(ir, b.r());
  b.set_next(iv, v);
  Eigen::VectorXd start = Eigen::VectorXd::Zero(n);
  start(ie) = 1.0;  // e[-1] = e[0] = r0 - 0
  start(ir) = 1.0;  // x_ref[-1] = r0
  return b.finish(command, start, 2);
}

namespace {
double& Kp(PositionLoopParams& g) { return g.Kp_V_per_mm; }
double& Ki(PositionLoopParams& g) { return g.Ki_V_per_s_mm; }
double& Kd(PositionLoopParams& g) { return g.Kd_V_s_per_mm; }
double& K1(PositionLoopParams& g) { return g.K1_V_s2_per_mm; }
double& K2(PositionLoopParams& g) { return g.K2_V_s_per_mm; }

constexpr LawGain kGains[] = {
    {"Kp", "Kp_V_per_mm", "V/mm", false, true, &Kp, nullptr, [](const PositionLoopParams&) { return 100.0; }},
    {"Ki", "Ki_V_per_s_mm", "V/(s mm)", false, true, &Ki, nullptr, nullptr},
    {"Kd", "Kd_V_s_per_mm", "V s/mm", false, true, &Kd, nullptr,
     [](const PositionLoopParams& g) { return 1e-3 * (g.Kp_V_per_mm > 0.0 ? g.Kp_V_per_mm : 100.0); }},
    {"K1", "K1_V_s2_per_mm", "V s^2/mm", true, true, &K1,
     [](const LinearPlant& p) { return model_feedforward(p).K1_V_s2_per_mm; }, nullptr},
    {"K2", "K2_V_s_per_mm", "V s/mm", true, true, &K2,
     [](const LinearPlant& p) { return model_feedforward(p).K2_V_s_per_mm; }, nullptr},
};
}  // namespace

std::span<const LawGain> FadalLaw::gains() const noexcept { return kGains; }

}  // namespace twin::controller::laws
