#pragma once
/// The drive effects of the catalogue of spec/measured-data.md that the drive
/// models: their names and their parameters with units, one line each. The
/// parameter structs are in drive_params.hpp, the equations in
/// effect_torques.hpp. The machine file's parameter table (twin/sim/machine.cpp)
/// and calibrate's registry (twin/calibrate/effect_registry.hpp) are built from
/// these lines.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "feeddrive/drive_params.hpp"

/// E(member of DriveEffects, EffectKind enumerator), in catalogue order. The
/// member's name is the effect's catalogue name.
#define TWIN_DRIVE_EFFECTS(E)                                                                                     \
  E(stribeck, kStribeck)                                                                                          \
  E(cogging, kCogging)                                                                                            \
  E(screw_pitch_error, kScrewPitchError)                                                                          \
  E(backlash, kBacklash)                                                                                          \
  E(constant_load, kConstantLoad)                                                                                 \
  E(position_dependent_friction, kPositionDependentFriction)                                                      \
  E(delay, kDelay)                                                                                                \
  E(compliance, kCompliance)                                                                                      \
  E(current_saturation, kCurrentSaturation)                                                                       \
  E(smooth_friction, kSmoothFriction)                                                                              \
  E(rising_friction, kRisingFriction)                                                                             \
  E(load_dependent_friction, kLoadDependentFriction)

/// P(effect, parameter name, field of the effect's struct, unit, description),
/// in the order of the machine file's table.
#define TWIN_DRIVE_EFFECT_PARAMS(P)                                                                               \
  P(stribeck, Ts_static, Ts_static_Nm, "N m", "static friction level")                                            \
  P(stribeck, ws, ws_rad_per_s, "rad/s", "Stribeck speed")                                                        \
  P(cogging, amplitude_Nm, amplitude_Nm, "N m", "cogging torque amplitude")                                       \
  P(cogging, cycles_per_rev, cycles_per_rev, "1", "cogging periods per motor revolution")                         \
  P(cogging, phase_rad, phase_rad, "rad", "cogging phase")                                                        \
  P(screw_pitch_error, amplitude_mm, amplitude_mm, "mm", "lead error amplitude")                                  \
  P(screw_pitch_error, period_mm, period_mm, "mm", "lead error period")                                           \
  P(screw_pitch_error, phase_rad, phase_rad, "rad", "lead error phase")                                           \
  P(backlash, gap_mm, gap_mm, "mm", "lost motion at reversal")                                                    \
  P(constant_load, torque_Nm, torque_Nm, "N m", "constant load torque")                                           \
  P(position_dependent_friction, dTc_Nm, dTc_Nm, "N m", "extra Coulomb friction in the band")                     \
  P(position_dependent_friction, x_start_mm, x_start_mm, "mm", "band start")                                      \
  P(position_dependent_friction, x_end_mm, x_end_mm, "mm", "band end")                                            \
  P(delay, delay_s, delay_s, "s", "command delay")                                                                \
  P(compliance, K_Nm_per_rad, K_Nm_per_rad, "N m/rad", "torsional stiffness motor-load")                          \
  P(compliance, C_Nm_s_per_rad, C_Nm_s_per_rad, "N m s/rad", "torsional damping motor-load")                      \
  P(compliance, load_fraction, load_fraction, "1", "share of J on the load side")                                 \
  P(current_saturation, i_max_A, i_max_A, "A", "current limit")                                                   \
  P(smooth_friction, ws, ws_rad_per_s, "rad/s", "speed below which Coulomb friction is smoothed (no stiction)")   \
  P(rising_friction, share, share, "1", "breakaway friction as a share of the Coulomb level")                      \
  P(rising_friction, ws, ws_rad_per_s, "rad/s", "speed over which friction rises to the Coulomb level")           \
  P(load_dependent_friction, fraction, fraction, "1",                                                              \
    "friction added per unit of the motor's torque (the screw's loss under load)")

namespace twin::feeddrive {

enum class EffectKind : std::uint8_t {
#define TWIN_EFFECT_ENUM(member, kind) kind,
  TWIN_DRIVE_EFFECTS(TWIN_EFFECT_ENUM)
#undef TWIN_EFFECT_ENUM
};

#define TWIN_EFFECT_COUNT(member, kind) +1
inline constexpr std::size_t kDriveEffectCount = 0 TWIN_DRIVE_EFFECTS(TWIN_EFFECT_COUNT);
#undef TWIN_EFFECT_COUNT

/// One parameter of one effect: `EffectParam::stribeck_ws` is stribeck's ws.
enum class EffectParam : std::uint8_t {
#define TWIN_EFFECT_PARAM_ENUM(effect, name, field, unit, doc) effect##_##name,
  TWIN_DRIVE_EFFECT_PARAMS(TWIN_EFFECT_PARAM_ENUM)
#undef TWIN_EFFECT_PARAM_ENUM
};

struct EffectDef {
  EffectKind kind;
  std::string_view name;  ///< catalogue name (spec/measured-data.md)
  bool& (*enabled)(DriveEffects&);
};

struct EffectParamDef {
  EffectParam id;
  EffectKind effect;
  std::string_view name;       ///< "ws"
  std::string_view qualified;  ///< "stribeck.ws", as the machine file and --set name it
  std::string_view unit;
  std::string_view doc;
  double& (*ref)(DriveEffects&);
};

const EffectDef& effect_def(EffectKind kind);
const EffectParamDef& effect_param_def(EffectParam p);
/// Every parameter of every effect, in the machine file's order.
std::span<const EffectParamDef> effect_params();
std::string_view effect_name(EffectKind kind);

/// A parameter equals a name when the name is its own ("ws") or its
/// qualified one ("stribeck.ws").
inline bool operator==(EffectParam p, std::string_view name) {
  const EffectParamDef& d = effect_param_def(p);
  return d.name == name || d.qualified == name;
}

}  // namespace twin::feeddrive
