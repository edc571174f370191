#include "controller/law.hpp"

#include <cmath>

#include <fmt/format.h>

#include "controller/laws/cascade.hpp"
#include "controller/laws/fadal.hpp"
#include "twin/core/error.hpp"

namespace twin::controller {

namespace {
/// The registered laws, one line each, in the order of LoopLaw.
const laws::FadalLaw kFadal{};
const laws::CascadeLaw kCascade{};
constexpr const Law* kLaws[] = {&kFadal, &kCascade};
}  // namespace

const Law& law_of(LoopLaw law) noexcept {
  for (const Law* l : kLaws)
    if (l->id() == law) return *l;
  return kFadal;
}

std::string_view loop_law_name(LoopLaw law) noexcept { return law_of(law).name(); }

std::optional<LoopLaw> parse_loop_law(std::string_view name) noexcept {
  for (const Law* l : kLaws)
    if (l->name() == name) return l->id();
  return std::nullopt;
}

void require_finite(std::string_view where, std::initializer_list<std::pair<const char*, double>> values) {
  for (const auto& [name, v] : values)
    if (!std::isfinite(v)) throw ConfigError(fmt::format("{}: {} = {} must be finite", where, name, v));
}

void LinearPlant::validate(const std::string& where) const {
  auto positive = [&](const char* name, double v) {
    if (!std::isfinite(v) || !(v > 0.0))
      throw ConfigError(fmt::format("{}: {} = {} must be finite and > 0 for the linear analysis", where, name, v));
  };
  positive("Ka", Ka_A_per_V);
  positive("Kt", Kt_Nm_per_A);
  positive("J", J_kg_m2);
  positive("rg", rg_mm_per_rad);
  if (!std::isfinite(B_kg_m2_per_s) || B_kg_m2_per_s < 0.0)
    throw ConfigError(fmt::format("{}: B = {} must be finite and >= 0 for the linear analysis", where, B_kg_m2_per_s));
  if (load_fraction != 0.0) {
    if (!(load_fraction > 0.0 && load_fraction < 1.0) || !std::isfinite(K_Nm_per_rad) || !(K_Nm_per_rad > 0.0) ||
        !std::isfinite(C_Nm_s_per_rad) || C_Nm_s_per_rad < 0.0)
      throw ConfigError(fmt::format("{}: a compliant coupling needs a load fraction in (0, 1), K > 0 and C >= 0 for the "
                                    "linear analysis (got {}, {}, {})",
                                    where, load_fraction, K_Nm_per_rad, C_Nm_s_per_rad));
  }
  if (!std::isfinite(command_delay_s) || command_delay_s < 0.0)
    throw ConfigError(fmt::format("{}: the command's delay = {} s must be finite and >= 0 for the linear analysis",
                                  where, command_delay_s));
}

LawSetup Law::setup(const PositionLoopParams&, double Ts_s, const DriveScale& drive) const {
  return LawSetup{Ts_s, drive, 0.0, 1, Ts_s};
}

void Law::inner_step(const PositionLoopParams&, const LawSetup&, double, PositionLoopState&,
                     PositionLoopOutput&) const {
  throw InternalError(fmt::format("the {} law has no inner ticks", name()));
}

PositionLoopParams Law::feedback_only(const PositionLoopParams& g) const {
  PositionLoopParams out = g;
  for (const LawGain& lg : gains())
    if (lg.feedforward) lg.ref(out) = 0.0;
  return out;
}

std::string Law::gains_text(const PositionLoopParams& g, bool units) const {
  std::string s;
  for (const LawGain& lg : gains())
    s += fmt::format("{}{} {:.6g}{}{}", s.empty() ? "" : ", ", lg.name, lg.get(g), units ? " " : "",
                     units ? lg.unit : "");
  return s;
}

}  // namespace twin::controller
