#pragma once
/// `twin calibrate`: identification of J, B, Tc per axis, residual diagnosis
/// against the effect catalogue, and the choice of effects judged by replay
/// on the held-out part of the run (spec/interfaces.md, report.json).
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "twin/calibrate/diagnose.hpp"
#include "twin/report/replay.hpp"

namespace twin::analysis {

struct CalibrateOptions {
  double fit_fraction{0.6};       ///< first part fitted, the rest judges
  double min_signal_gain{0.03};   ///< a candidate must cut its held-out torque residual by this much to be replayed
  /// The replayed held-out errors must improve by this much (mean of their
  /// ratios) for a first effect on an axis to be added: two replays of
  /// equivalent models differ by under 1 % in these errors.
  double min_improvement{0.03};
  /// A second effect on an axis, whose signature may be what is left of the
  /// first one's misfit (a cogging ripple's harmonics read as a lead error),
  /// must improve them by this much.
  double min_improvement_second{0.08};
  /// Every added effect must leave each held-out error (tracking, u) at or
  /// below its value before. For a candidate the replay is blind to
  /// (EffectCandidate::replay_blind), whose replayed errors do not improve by
  /// min_improvement, a signature this strong decides: signal gain and t above these.
  double strong_signal_gain{0.3};
  double strong_t{2.0};
  /// A tie is evidence only where the model follows the run at all: the
  /// held-out tracking NRMS before must be below this (a run in a limit
  /// cycle, near 1, leaves friction levels the identification distorts).
  double tie_max_err_nrms{0.9};
  /// A candidate judged by the hunting statistic (EffectCandidate::judged_by_hunting)
  /// must cut AxisErrors::hunt to this fraction (and, as every candidate,
  /// leave the point-by-point errors not above before).
  double max_hunt_ratio{0.5};
  int max_effects_per_axis{2};
  int replays_per_round{4};
};

/// Held-out errors of one axis (spec/interfaces.md): NRMS of the tracking
/// error and of the 200 Hz low-passed u (or current when u is absent).
struct AxisErrors {
  double err_mm{0.0};
  double u{0.0};
  /// Why an error could not be computed (empty: it was): too few held-out
  /// rows, no measured position, a measured signal that is zero throughout.
  std::string err_not_computed, u_not_computed;
  /// Hunting statistic, blind to phase: NRMS of the spread of the tracking
  /// error in consecutive 20 ms windows (model against run).
  double hunt{0.0};
  bool has_u{false};
  bool has_current{false};
  double score() const { return (has_u || has_current) ? 0.5 * (err_mm + u) : err_mm; }
  /// Mean over the metrics of other / this: below 1 when `other` is better.
  double relative(const AxisErrors& other) const {
    const double re = err_mm > 0.0 ? other.err_mm / err_mm : 1.0;
    if (!(has_u || has_current)) return re;
    const double ru = u > 0.0 ? other.u / u : 1.0;
    return 0.5 * (re + ru);
  }
};

struct AddedEffect {
  EffectCandidate candidate;
  AxisErrors before, after;   ///< held-out errors of the axis without and with it
};

struct CalibrationResult {
  sim::MachineDefinition identified;  ///< identified J, B, Tc, no effects added
  sim::MachineDefinition final_machine;
  std::vector<Axis> axes;
  AxisArray<DriveIdentification> identification;
  AxisArray<bool> identified_axis{};
  AxisArray<LoopIdentification> loop;  ///< the loop law checked on u, where logged at the loop's rate
  AxisArray<AmplifierCheck> amplifier; ///< the current against Ka u, where both are logged
  std::vector<AddedEffect> added;
  std::vector<EffectCandidate> rejected;  ///< replayed and not good enough (with their figures)
  std::vector<EffectCandidate> considered;///< every candidate of every round with its signal figures
  AxisArray<AxisErrors> error_before, error_after;
  ReplayResult replay_before, replay_after;
  std::size_t n_fit{0}, n{0};
  double t_split_s{0.0}, t_end_s{0.0};
  int replays{0};
  std::vector<std::string> notes;
};

/// Errors of `model` against the run on rows [from, to) (to clipped to the
/// run), to 4 significant digits: the numbers the held-out rule compares and
/// report.json carries.
AxisErrors axis_errors(const MeasuredRun& run, const ReplayResult& model, Axis a, std::size_t from,
                       std::size_t to = static_cast<std::size_t>(-1));

CalibrationResult calibrate(const MeasuredRun& run, const sim::MachineDefinition& start,
                            const CalibrateOptions& options = {});

/// report.json exactly as spec/interfaces.md.
nlohmann::json calibration_report_json(const CalibrationResult& r);
/// report.md, a person's reading of the same.
std::string calibration_report_markdown(const CalibrationResult& r, const std::string& run_dir);

}  // namespace twin::analysis
