#include "feeddrive/drive_params.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::feeddrive {
namespace {

// Each check throws one line: "<where>: <field> = <value> must be <limit>".
class Checker {
 public:
  explicit Checker(std::string_view where) : where_(where) {}

  void finite(std::string_view field, double value) const {
    if (!std::isfinite(value)) fail(field, value, "finite");
  }
  void positive(std::string_view field, double value) const {
    finite(field, value);
    if (!(value > 0.0)) fail(field, value, "> 0");
  }
  void non_negative(std::string_view field, double value) const {
    finite(field, value);
    if (!(value >= 0.0)) fail(field, value, ">= 0");
  }
  void fail(std::string_view field, double value, std::string_view limit) const {
    throw ConfigError(fmt::format("{}: {} = {} must be {}", where_, field, value, limit));
  }

 private:
  std::string_view where_;
};

}  // namespace

void DriveParams::validate(std::string_view where) const {
  const Checker c(where);
  c.positive("Ka_A_per_V", Ka_A_per_V);
  c.positive("Kt_Nm_per_A", Kt_Nm_per_A);
  c.positive("J_kg_m2", J_kg_m2);
  c.non_negative("B_kg_m2_per_s", B_kg_m2_per_s);
  c.positive("rg_mm_per_rad", rg_mm_per_rad);
  c.non_negative("Tc_pos_Nm", Tc_pos_Nm);
  c.non_negative("Tc_neg_Nm", Tc_neg_Nm);

  const DriveEffects& e = effects;
  if (e.stribeck.enabled) {
    c.finite("effects.stribeck.Ts_static_Nm", e.stribeck.Ts_static_Nm);
    const double Tc_max_Nm = std::max(Tc_pos_Nm, Tc_neg_Nm);
    if (!(e.stribeck.Ts_static_Nm >= Tc_max_Nm))
      c.fail("effects.stribeck.Ts_static_Nm", e.stribeck.Ts_static_Nm,
             fmt::format(">= max(Tc_pos_Nm, Tc_neg_Nm) = {}", Tc_max_Nm));
    c.positive("effects.stribeck.ws_rad_per_s", e.stribeck.ws_rad_per_s);
  }
  if (e.smooth_friction.enabled) {
    c.positive("effects.smooth_friction.ws_rad_per_s", e.smooth_friction.ws_rad_per_s);
    if (e.stribeck.enabled)
      c.fail("effects.smooth_friction.enabled", 1.0,
             "off with stribeck (both describe the friction at low speed: choose one)");
    if (e.compliance.enabled)
      c.fail("effects.smooth_friction.enabled", 1.0, "off with compliance (rigid drives only)");
  }
  if (e.rising_friction.enabled) {
    c.finite("effects.rising_friction.share", e.rising_friction.share);
    if (!(e.rising_friction.share >= 0.0 && e.rising_friction.share < 1.0))
      c.fail("effects.rising_friction.share", e.rising_friction.share, "in [0, 1)");
    c.positive("effects.rising_friction.ws_rad_per_s", e.rising_friction.ws_rad_per_s);
    if (e.stribeck.enabled || e.smooth_friction.enabled)
      c.fail("effects.rising_friction.enabled", 1.0,
             "off with stribeck and smooth_friction (each describes the friction at low speed: choose one)");
  }
  if (e.load_dependent_friction.enabled) {
    c.finite("effects.load_dependent_friction.fraction", e.load_dependent_friction.fraction);
    if (!(e.load_dependent_friction.fraction >= 0.0 && e.load_dependent_friction.fraction <= 0.5))
      c.fail("effects.load_dependent_friction.fraction", e.load_dependent_friction.fraction, "in [0, 0.5]");
  }
  if (e.cogging.enabled) {
    c.non_negative("effects.cogging.amplitude_Nm", e.cogging.amplitude_Nm);
    c.positive("effects.cogging.cycles_per_rev", e.cogging.cycles_per_rev);
    c.finite("effects.cogging.phase_rad", e.cogging.phase_rad);
  }
  if (e.screw_pitch_error.enabled) {
    c.non_negative("effects.screw_pitch_error.amplitude_mm", e.screw_pitch_error.amplitude_mm);
    c.positive("effects.screw_pitch_error.period_mm", e.screw_pitch_error.period_mm);
    c.finite("effects.screw_pitch_error.phase_rad", e.screw_pitch_error.phase_rad);
  }
  if (e.backlash.enabled) c.non_negative("effects.backlash.gap_mm", e.backlash.gap_mm);
  if (e.constant_load.enabled) c.finite("effects.constant_load.torque_Nm", e.constant_load.torque_Nm);
  if (e.position_dependent_friction.enabled) {
    const auto& p = e.position_dependent_friction;
    c.non_negative("effects.position_dependent_friction.dTc_Nm", p.dTc_Nm);
    c.finite("effects.position_dependent_friction.x_start_mm", p.x_start_mm);
    c.finite("effects.position_dependent_friction.x_end_mm", p.x_end_mm);
    if (!(p.x_end_mm >= p.x_start_mm))
      c.fail("effects.position_dependent_friction.x_end_mm", p.x_end_mm,
             fmt::format(">= x_start_mm = {}", p.x_start_mm));
  }
  if (e.delay.enabled) c.non_negative("effects.delay.delay_s", e.delay.delay_s);
  if (e.compliance.enabled) {
    c.positive("effects.compliance.K_Nm_per_rad", e.compliance.K_Nm_per_rad);
    c.non_negative("effects.compliance.C_Nm_s_per_rad", e.compliance.C_Nm_s_per_rad);
    c.finite("effects.compliance.load_fraction", e.compliance.load_fraction);
    if (!(e.compliance.load_fraction > 0.0 && e.compliance.load_fraction < 1.0))
      c.fail("effects.compliance.load_fraction", e.compliance.load_fraction, "in (0, 1)");
  }
  if (e.current_saturation.enabled)
    c.positive("effects.current_saturation.i_max_A", e.current_saturation.i_max_A);
}

}  // namespace twin::feeddrive
