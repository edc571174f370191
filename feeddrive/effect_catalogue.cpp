#include "feeddrive/effect_catalogue.hpp"

#include <array>

#include "twin/core/check.hpp"

namespace twin::feeddrive {
namespace {

constexpr std::array kEffects{
#define TWIN_EFFECT_DEF(member, kind) \
  EffectDef{EffectKind::kind, #member, [](DriveEffects& e) -> bool& { return e.member.enabled; }},
    TWIN_DRIVE_EFFECTS(TWIN_EFFECT_DEF)
#undef TWIN_EFFECT_DEF
};

constexpr EffectKind kind_of(std::string_view member) {
  for (const EffectDef& d : kEffects)
    if (d.name == member) return d.kind;
  return EffectKind::kStribeck;
}

constexpr std::array kParams{
#define TWIN_EFFECT_PARAM_DEF(effect, pname, field, unit, doc)                                                \
  EffectParamDef{EffectParam::effect##_##pname, kind_of(#effect), #pname, #effect "." #pname, unit, doc, \
                 [](DriveEffects& e) -> double& { return e.effect.field; }},
    TWIN_DRIVE_EFFECT_PARAMS(TWIN_EFFECT_PARAM_DEF)
#undef TWIN_EFFECT_PARAM_DEF
};

}  // namespace

std::span<const EffectDef> drive_effects() { return kEffects; }
std::span<const EffectParamDef> drive_effect_params() { return kParams; }

const EffectDef& effect_def(EffectKind kind) {
  const auto i = static_cast<std::size_t>(kind);
  TWIN_DEMAND(i < kEffects.size());
  return kEffects[i];
}

const EffectParamDef& effect_param_def(EffectParam p) {
  const auto i = static_cast<std::size_t>(p);
  TWIN_DEMAND(i < kParams.size());
  return kParams[i];
}

std::string_view effect_name(EffectKind kind) { return effect_def(kind).name; }

std::optional<EffectKind> find_effect(std::string_view name) {
  for (const EffectDef& d : kEffects)
    if (d.name == name) return d.kind;
  return std::nullopt;
}

}  // namespace twin::feeddrive
