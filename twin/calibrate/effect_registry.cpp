#include "twin/calibrate/effect_registry.hpp"

#include <algorithm>
#include <array>

#include <fmt/format.h>

#include "twin/calibrate/effect_detectors.hpp"
#include "twin/core/check.hpp"
#include "twin/core/error.hpp"

namespace twin::analysis {
namespace {

constexpr std::uint8_t kTorque = kJudgeTorque;
constexpr std::uint8_t kTracking = kJudgeTracking;
constexpr std::uint8_t kBoth = kJudgeTorque | kJudgeTracking;

// One line per effect, in catalogue order:
// kind, diagnose, torque_after, from_data, from_data_rank, judged_on, replaces, plot.
constexpr std::array<EffectEntry, feeddrive::kDriveEffectCount> kRegistry{{
    {EffectKind::kStribeck, detect_stribeck, stribeck_torque_after, detect_stribeck_in_data, 2, kBoth,
     effect_bit(EffectKind::kSmoothFriction) | effect_bit(EffectKind::kRisingFriction), PlotAlong::kTime},
    {EffectKind::kCogging, detect_cogging, nullptr, detect_cogging_in_data, 4, kTorque, 0,
     PlotAlong::kPosition},
    {EffectKind::kScrewPitchError, detect_screw_pitch_error, nullptr, detect_screw_pitch_error_in_data, 5, kTracking,
     0, PlotAlong::kPosition},
    {EffectKind::kBacklash, detect_backlash, nullptr, detect_backlash_in_data, 6, kTracking, 0,
     PlotAlong::kTime},
    {EffectKind::kConstantLoad, detect_constant_load, nullptr, nullptr, 0, kTorque, 0, PlotAlong::kTime},
    {EffectKind::kPositionDependentFriction, detect_position_dependent_friction, nullptr,
     detect_position_dependent_friction_in_data, 3, kTorque, 0, PlotAlong::kPosition},
    {EffectKind::kDelay, detect_delay, nullptr, detect_delay_in_data, 0, kBoth, 0, PlotAlong::kTime},
    {EffectKind::kCompliance, detect_compliance, nullptr, nullptr, 0, kTracking, 0, PlotAlong::kTime},
    {EffectKind::kCurrentSaturation, detect_current_saturation, nullptr, detect_current_saturation_in_data, 1, kBoth,
     0, PlotAlong::kTime},
    // Found while the drive is identified from data (calibrate_from_data), not by a detector.
    {EffectKind::kSmoothFriction, nullptr, nullptr, nullptr, 0, kTorque, 0, PlotAlong::kTime},
    {EffectKind::kRisingFriction, nullptr, nullptr, nullptr, 0, kTorque, effect_bit(EffectKind::kSmoothFriction),
     PlotAlong::kTime},
    {EffectKind::kLoadDependentFriction, detect_load_dependent_friction, nullptr,
     detect_load_dependent_friction_in_data, 2, kBoth, 0, PlotAlong::kTime},
}};

constexpr bool registry_in_catalogue_order() {
  for (std::size_t i = 0; i < kRegistry.size(); ++i)
    if (static_cast<std::size_t>(kRegistry[i].kind) != i) return false;
  return true;
}
static_assert(registry_in_catalogue_order(), "one registry entry per catalogue effect, in catalogue order");

}  // namespace

double param_value(const ParamSet& set, EffectParam p) {
  for (const auto& [k, v] : set)
    if (k == p) return v;
  throw InternalError(
      fmt::format("calibrate: a parameter set without {}", feeddrive::effect_param_def(p).qualified));
}

std::string param_key(EffectKind owner, EffectParam p) {
  const feeddrive::EffectParamDef& d = feeddrive::effect_param_def(p);
  return std::string(d.effect == owner ? d.name : d.qualified);
}

std::span<const EffectEntry> effect_registry() { return kRegistry; }

const EffectEntry& registry_entry(EffectKind kind) {
  const auto i = static_cast<std::size_t>(kind);
  TWIN_DEMAND(i < kRegistry.size());
  return kRegistry[i];
}

std::vector<EffectKind> replaced_by(EffectKind kind) {
  std::vector<EffectKind> r;
  for (const EffectEntry& e : kRegistry)
    if ((registry_entry(kind).replaces & effect_bit(e.kind)) != 0) r.push_back(e.kind);
  return r;
}

std::vector<const EffectEntry*> from_data_search_order() {
  std::vector<const EffectEntry*> r;
  for (const EffectEntry& e : kRegistry)
    if (e.from_data != nullptr) r.push_back(&e);
  std::stable_sort(r.begin(), r.end(),
                   [](const EffectEntry* a, const EffectEntry* b) { return a->from_data_rank < b->from_data_rank; });
  return r;
}

}  // namespace twin::analysis
