#pragma once
/// calibrate's effect registry: one entry per drive effect of the catalogue
/// (feeddrive/effect_catalogue.hpp) saying how calibrate looks for it on the
/// residual, how a candidate is judged and how its evidence is plotted. A
/// new effect is one line of effect_registry.cpp beside its detector
/// functions (declared in effect_detectors.hpp). No code outside the
/// registry and the catalogue tells an effect by its name.
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "feeddrive/effect_catalogue.hpp"

namespace twin::analysis {

using feeddrive::EffectKind;
using feeddrive::EffectParam;

/// A parameter of a candidate, typed by the effect and the parameter it sets
/// (a gap in the coupling carries the coupling's stiffness:
/// EffectParam::compliance_K_Nm_per_rad in a backlash candidate).
using ParamValue = std::pair<EffectParam, double>;
using ParamSet = std::vector<ParamValue>;

/// The value of `p` in `set`; InternalError when the set has none.
double param_value(const ParamSet& set, EffectParam p);
/// The name a report gives `p` in a candidate of effect `owner`: its own
/// name ("gap_mm") for the owner's parameters, the qualified one
/// ("compliance.K_Nm_per_rad") for another effect's.
std::string param_key(EffectKind owner, EffectParam p);

struct AxisSignals;
struct EffectCandidate;
struct DiagnoseContext;  ///< a detector's view of one axis of a shipped machine (diagnose.cpp)
struct DataSearch;       ///< a detector's view of one axis identified from data (machine_from_data.cpp)

/// The channels a candidate of a machine identified from data must lower on
/// the held-out rows (spec/measured-data.md, "where it shows").
enum JudgedOn : std::uint8_t { kJudgeTorque = 1, kJudgeTracking = 2 };

/// What the evidence plot of an added effect runs along.
enum class PlotAlong { kTime, kPosition };

constexpr std::uint32_t effect_bit(EffectKind k) { return 1u << static_cast<unsigned>(k); }

struct EffectEntry {
  EffectKind kind;
  /// Candidates from the inverse-dynamics residual of a machine the twin
  /// ships (nullptr: not looked for there).
  void (*diagnose)(const DiagnoseContext&, std::vector<EffectCandidate>&);
  /// The torque with the effect's part taken out, recomputed for the set the
  /// replay chose (nullptr: the detector's own stands).
  void (*torque_after)(const AxisSignals&, const std::vector<double>& T_Nm, EffectCandidate&);
  /// Candidates on a machine identified from data (nullptr: not looked for there).
  void (*from_data)(DataSearch&);
  /// The order of the from-data search: the effects on the loop's command
  /// first, then friction, then the periodic ones, then the gap.
  int from_data_rank;
  std::uint8_t judged_on;  ///< JudgedOn bits (from data)
  /// The effects this one replaces where it is kept (bits of effect_bit):
  /// the drive holds one of them (each describes the friction at low speed).
  std::uint32_t replaces;
  PlotAlong plot;
};

/// Every entry, in catalogue order.
std::span<const EffectEntry> effect_registry();
const EffectEntry& registry_entry(EffectKind kind);
/// The effects `kind` replaces where it is kept, in catalogue order.
std::vector<EffectKind> replaced_by(EffectKind kind);
/// The entries with a from-data detector, in the order of the search.
std::vector<const EffectEntry*> from_data_search_order();

}  // namespace twin::analysis
