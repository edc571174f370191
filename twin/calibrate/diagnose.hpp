#pragma once
/// Residual diagnosis: for every effect of the catalogue
/// (spec/measured-data.md), a statistic aimed at its signature in the
/// inverse-dynamics residual (or the measured current), its parameters fitted
/// on the fitting part and the reduction of the residual it gives on the
/// held-out part where the effect acts.
#include <string>
#include <utility>
#include <vector>

#include "twin/calibrate/effect_registry.hpp"
#include "twin/calibrate/identify.hpp"
#include "twin/sim/machine.hpp"

namespace twin::analysis {

struct EffectCandidate {
  EffectKind kind{EffectKind::kStribeck};
  std::string effect;  ///< catalogue name of `kind`, as reports give it
  Axis axis{Axis::kX};
  /// The effect's parameters; one of another effect is carried with it (a
  /// gap in the coupling carries the coupling's stiffness).
  ParamSet params;
  double signal_gain{0.0};  ///< 1 - rms(residual with effect) / rms(residual without), held out, where it acts
  double t_stat{0.0};       ///< fitted size over its standard error (for a spectral peak: its prominence)
  double min_t{3.0};        ///< what t_stat must reach for the candidate to be replayed
  std::string evidence;     ///< one line with the figure that decides
  /// The replay hardly sees it (a reparametrisation of the moving model that
  /// differs only at standstill): where the replayed errors tie, its signature decides.
  bool replay_blind{false};
  /// A limit cycle (hunting) the replay reproduces only out of phase: the
  /// candidate is judged by the hunting statistic (AxisErrors::hunt), which
  /// compares the spread of the tracking error window by window.
  bool judged_by_hunting{false};
  /// Alternative parameter sets the torque residual cannot tell apart (a
  /// Stribeck speed below what the low-pass resolves): calibrate replays
  /// each and keeps the one with the lowest error on the fitting part.
  std::vector<ParamSet> param_grid;
  /// Parameters calibrate refines on the fitting part after the grid, by a
  /// coordinate search: parameter and multiplicative step.
  std::vector<std::pair<EffectParam, double>> refine;
  /// J, B, Tc refitted with each grid set (empty: `base` serves every set).
  std::vector<DriveIdentification> grid_base;
  DriveIdentification base; ///< J, B, Tc fitted together with the effect
  std::vector<double> T_after_Nm;  ///< torque with the effect's part taken out (for a second effect)

  void set_kind(EffectKind k) {
    kind = k;
    effect = std::string(feeddrive::effect_name(k));
  }
};

/// Candidates for one axis, best signal gain first; effects already on the
/// axis (`present`) are skipped. `T_Nm` is the torque the base model explains.
/// `e_residual_mm` (measured minus replayed tracking error, may be empty) is
/// used for the resonance of compliance.
std::vector<EffectCandidate> diagnose_axis(const AxisSignals& s, const std::vector<double>& T_Nm,
                                           const feeddrive::DriveParams& drive,
                                           const std::vector<EffectKind>& present,
                                           const std::vector<double>& e_residual_mm);

/// Spread (standard deviation about the window mean) of `e` in consecutive
/// windows of `window` rows over [from, to); a last partial window is dropped.
std::vector<double> window_spread(const std::vector<double>& e, std::size_t from, std::size_t to, std::size_t window);

/// After a parameter set was chosen from the grid: the torque with the
/// effect's part taken out (EffectCandidate::T_after_Nm), recomputed for the
/// chosen set where the registry knows the effect's torque in closed form.
void update_torque_after(const AxisSignals& s, const std::vector<double>& T_Nm, EffectCandidate& c);

/// Switches the candidate's effect on in `axis` with its parameters and sets
/// J, B, Tc to the ones fitted with it.
void apply_candidate(sim::AxisDefinition& axis, const EffectCandidate& c);

}  // namespace twin::analysis
