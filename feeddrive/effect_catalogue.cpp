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

// The tables are indexed by their enums: both are built from the same lines.
constexpr bool tables_in_enum_order() {
  for (std::size_t i = 0; i < kEffects.size(); ++i)
    if (static_cast<std::size_t>(kEffects[i].kind) != i) return false;
  for (std::size_t i = 0; i < kParams.size(); ++i)
    if (static_cast<std::size_t>(kParams[i].id) != i) return false;
  return kEffects.size() == kDriveEffectCount;
}
static_assert(tables_in_enum_order(), "effect tables out of their enums' order");

}  // namespace

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

std::span<const EffectParamDef> effect_params() { return kParams; }

std::string_view effect_name(EffectKind kind) { return effect_def(kind).name; }

}  // namespace twin::feeddrive
