#pragma once
/// Gain tuning of the position loops (`twin tune`): the gains each axis's law
/// searches (controller/law.hpp, controller::Law: FADAL Kp, Ki, Kd, K1, K2; cascade
/// Kv, Kvp, Tn with the machine's feedforward kff, Jff kept) are searched to minimise
/// the tracking and contour error through the corners of a scenario in the coupled
/// nonlinear simulation (friction, saturation, encoder, cutting load in), subject to
/// constraints read from the linear analysis and from the simulation:
///   phase margin >= PM_min, gain margin >= GM_min, sensitivity peak <= Ms_max,
///   feedback step overshoot <= overshoot_max (linear model),
///   |command| <= u_fraction_max * its limit at every tick of the scenario, never at the
///   limit (FADAL: u and u_max; cascade: the torque and T_max).
///
/// Two stages, both NLopt (derivative-free):
///  A. per axis, COBYLA on the linear model only: the feedback gains
///     nearest (in log ratio) to the starting gains that meet the linear constraints;
///  B. all tuned axes together, BOBYQA on the simulated corners, starting from the
///     stage-A gains and the model-based feedforward (FADAL K1 = J/(Ka Kt rg),
///     K2 = B/(Ka Kt rg)); a broken constraint is a penalty, and the result is the
///     best point that met every constraint (never an infeasible one).
/// The search simulates a window around the corners (the run starts on the path
/// in steady motion, see docs/tuning.md); the result is judged on the full scenario.
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "controller/gcode.hpp"
#include "controller/interpolator.hpp"
#include "twin/tune/linear_analysis.hpp"
#include "twin/report/run_report.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::analysis {

struct TuneConstraints {
  double phase_margin_min_deg{40.0};
  double gain_margin_min_dB{6.0};
  double sensitivity_peak_max{2.0};    ///< |S| peak, absolute (2 = 6 dB)
  double step_overshoot_max{0.35};     ///< feedback-only position step overshoot, fraction of the step
  double u_fraction_max{0.95};         ///< peak |command| over the scenario / its limit (u_max, T_max)
};

struct TuneOptions {
  std::vector<Axis> axes;              ///< axes to tune (present axes of the machine)
  TuneConstraints constraints;
  int max_evaluations{160};            ///< simulations in stage B
  double window_before_s{0.1};         ///< simulated before the first tuning corner
  double window_after_s{0.1};          ///< simulated after the last tuning corner
  double max_window_span_s{2.0};       ///< corners searched on: those ending within this of the first one's start
  double gain_range{4.0};              ///< Kp, Ki, Kd stay within [start / range, start * range]
  double feedforward_range{2.0};       ///< K1, K2 stay within [0, range * model value]
  double rms_weight{0.5};              ///< weight of the RMS tracking error against the max contour error
  double max_tracking_weight{0.25};    ///< weight of the max tracking error
};

/// The values every constraint is judged on, for one axis and one set of gains.
struct ConstraintValues {
  double phase_margin_deg{0.0};
  double gain_margin_dB{0.0};
  double sensitivity_peak{0.0};
  double step_overshoot{0.0};
  /// The law's command to the drive (u in V for the FADAL law, the torque for the
  /// cascade): its peak from the simulation (0 before one ran; a tick at the limit
  /// counts as the limit) and u_fraction_max times its limit (u_max, T_max).
  std::string_view command_name;
  std::string_view command_unit;
  double command_peak{0.0};
  double command_limit{0.0};
  bool stable{false};
  bool linear_ok{false};
  bool simulation_ok{false};
  std::string violation;               ///< empty when all hold; otherwise the first broken one, with values
};
/// Linear constraint values for an axis (command_peak is left at 0).
ConstraintValues linear_constraints(const LinearPlant& plant, const controller::PositionLoopParams& gains,
                                    double Ts_s, const TuneConstraints& c, const std::string& where);

/// A tick range of the scenario and the corners judged inside it.
struct SimulationWindow {
  std::int64_t k_begin{0};
  std::int64_t k_end{0};               ///< exclusive
  std::vector<CornerWindow> corners;   ///< only ticks inside these count for the corner figures
};

/// Figures of one coupled run through the corners of a window.
struct ScenarioMetrics {
  bool completed{false};
  std::string failure;                 ///< why the run stopped (runaway), when !completed
  AxisArray<double> max_tracking_error_mm{};   ///< through the corners
  AxisArray<double> rms_tracking_error_mm{};   ///< through the corners
  AxisArray<double> u_peak_V{};                ///< over the whole window
  AxisArray<double> u_peak_t_s{};              ///< when the peak |u| was reached
  AxisArray<int> u_peak_block{};               ///< program block running then (-1: none, settling)
  AxisArray<std::int64_t> saturated_ticks{};
  double max_contour_error_mm{0.0};            ///< through the corners
  double rms_contour_error_mm{0.0};            ///< through the corners
  double max_contour_error_run_mm{0.0};        ///< over the whole window
  AxisArray<double> max_error_after_stop_mm{}; ///< |e| after the reference ends (overshoot / settling)
  std::int64_t ticks{0};
};

/// Per-tick tracking and contour error around one corner (plots).
struct CornerTrace {
  std::vector<double> t_s;
  AxisArray<std::vector<double>> e_mm;
  std::vector<double> contour_mm;
};

/// A planned scenario: program, trajectory and its corners.
struct PlannedScenario {
  controller::Program program;
  controller::Trajectory trajectory;
  std::vector<CornerWindow> corners;         ///< all corners
  std::vector<CornerWindow> tuning_corners;  ///< corners between two feed moves (all corners if none)
  std::int64_t total_ticks{0};               ///< reference plus settling
};
PlannedScenario plan_scenario(const io::Scenario& scenario);

/// The whole scenario, or a window from window_before_s ahead of the first tuning
/// corner to window_after_s past the last one.
SimulationWindow full_window(const PlannedScenario& planned);
/// With many corners, only the first tuning corner and those ending within max_span_s of
/// its start are in the window (a search step then costs a bounded simulation).
SimulationWindow corner_window(const PlannedScenario& planned, double before_s, double after_s,
                               double max_span_s = std::numeric_limits<double>::infinity());

/// Runs the coupled simulation over the window with the machine `machine`. A window
/// that starts after tick 0 starts in steady motion on the reference (drives at the
/// reference speed, integrators holding the force of the viscous and Coulomb friction).
/// A run that the co-simulation stops (runaway) returns completed = false with the reason.
/// With `trace`, records ticks [trace_begin, trace_end).
ScenarioMetrics simulate_window(const io::Scenario& scenario, const PlannedScenario& planned,
                                const sim::MachineDefinition& machine, const SimulationWindow& window,
                                CornerTrace* trace = nullptr, std::int64_t trace_begin = 0,
                                std::int64_t trace_end = 0);

struct AxisTuneResult {
  Axis axis{Axis::kX};
  bool tuned{true};                          ///< false: the machine's gains were kept (see note)
  std::string note;                          ///< why the gains were kept, or what limited the tuning
  controller::PositionLoopParams before, after;
  /// `before` with every feedforward gain at its model value (FADAL K1 = J/(Ka Kt rg),
  /// K2 = B/(Ka Kt rg); cascade kff = 1, Jff = J).
  controller::PositionLoopParams model_feedforward;
  LoopAnalysis analysis_before, analysis_after;
  ConstraintValues constraints_before, constraints_after;  ///< u_peak from the full scenario
};

struct TuneResult {
  bool feasible{false};
  std::string message;                       ///< one line: what was found, or why no gains qualify
  sim::MachineDefinition machine_before, machine_after;
  std::vector<AxisTuneResult> axes;
  ScenarioMetrics window_before, window_after;   ///< on the tuning window
  ScenarioMetrics full_before, full_after;       ///< on the full scenario
  int evaluations{0};                            ///< coupled simulations run in stage B
  double objective_before{0.0}, objective_after{0.0};
};

/// Tunes the given axes of the scenario's machine. Does not throw for gains that
/// cannot meet the constraints: the result says so (feasible = false, message).
/// Throws ConfigError for an axis that is absent or options out of range.
TuneResult tune_gains(const io::Scenario& scenario, const TuneOptions& options);

/// report.json content: per axis gains, margins, bandwidth and constraint values
/// before and after, errors through the corners before and after, and, when given,
/// the same figures on a second scenario not used for tuning.
nlohmann::json tune_report(const io::Scenario& scenario, const TuneOptions& options, const TuneResult& result,
                           const std::optional<io::Scenario>& check_scenario,
                           const std::optional<std::pair<ScenarioMetrics, ScenarioMetrics>>& check_metrics);

/// Writes the Bode plot (bode.png: |L|, arg L, |S|, |T| before and after per axis) and
/// the tracking error through the first tuning corner before and after
/// (corner_error.png), with their data bode.dat and corner_error.dat, in the result
/// set. Returns the plots written (staged paths).
std::vector<std::filesystem::path> plot_tune(io::ResultSet& results, const io::Scenario& scenario,
                                             const TuneResult& result);

}  // namespace twin::analysis
