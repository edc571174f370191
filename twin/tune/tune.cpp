#include "twin/tune/tune.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>

#include <fmt/format.h>
#include <nlopt.hpp>

#include "twin/report/plots.hpp"
#include "twin/core/error.hpp"
#include "twin/core/units.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/sim/scenario.hpp"

namespace twin::analysis {

namespace {

bool is_feed_move(const controller::Program& program, int block) {
  if (block < 0 || block >= static_cast<int>(program.blocks.size())) return false;
  const auto kind = program.blocks[static_cast<std::size_t>(block)].kind;
  return kind == controller::MotionKind::kLinear || kind == controller::MotionKind::kArcCw ||
         kind == controller::MotionKind::kArcCcw;
}

std::string gains_text(const controller::PositionLoopParams& g) { return controller::law_of(g.law).gains_text(g); }

/// How far the linear constraints are broken (0 when all hold), in normalised units.
double linear_violation(const ConstraintValues& v, const TuneConstraints& c) {
  if (!v.stable) return 10.0;
  double s = 0.0;
  s += std::max(0.0, (c.phase_margin_min_deg - v.phase_margin_deg) / 10.0);
  s += std::max(0.0, (c.gain_margin_min_dB - v.gain_margin_dB) / 3.0);
  s += std::max(0.0, (v.sensitivity_peak - c.sensitivity_peak_max) / 0.2);
  s += std::max(0.0, (v.step_overshoot - c.step_overshoot_max) / 0.05);
  return s;
}

}  // namespace

ConstraintValues linear_constraints(const LinearPlant& plant, const controller::PositionLoopParams& gains,
                                    double Ts_s, const TuneConstraints& c, const std::string& where) {
  ConstraintValues v;
  const DiscreteLoopModel model(plant, gains, Ts_s, where);
  const LoopAnalysis a = analyse_loop(model, 0.01, 1500);
  v.stable = a.stable;
  // A velocity loop faster than the position loop has margins of its own: the
  // constraints hold for the smaller of the two loops'.
  const bool velocity_pm = a.velocity_loop && a.velocity_loop_phase_margin_deg < a.phase_margin_deg;
  const bool velocity_gm = a.velocity_loop && a.velocity_loop_gain_margin_dB < a.gain_margin_dB;
  v.phase_margin_deg = velocity_pm ? a.velocity_loop_phase_margin_deg : a.phase_margin_deg;
  v.gain_margin_dB = velocity_gm ? a.velocity_loop_gain_margin_dB : a.gain_margin_dB;
  v.sensitivity_peak = a.sensitivity_peak;
  v.step_overshoot = a.step_overshoot;
  v.command_name = model.law().command_name();
  v.command_unit = model.law().command_unit();
  v.command_limit = c.u_fraction_max * model.law().command_limit(gains);
  if (!a.stable) {
    v.violation = fmt::format("{}: closed loop unstable (largest pole |z| = {:.6f})", where, a.max_pole_magnitude);
  } else if (v.phase_margin_deg < c.phase_margin_min_deg) {
    v.violation = fmt::format("{}: {}phase margin {:.2f} deg < {:.2f} deg", where, velocity_pm ? "velocity loop " : "",
                              v.phase_margin_deg, c.phase_margin_min_deg);
  } else if (v.gain_margin_dB < c.gain_margin_min_dB) {
    v.violation = fmt::format("{}: {}gain margin {:.2f} dB < {:.2f} dB", where, velocity_gm ? "velocity loop " : "",
                              v.gain_margin_dB, c.gain_margin_min_dB);
  } else if (a.sensitivity_peak > c.sensitivity_peak_max) {
    v.violation = fmt::format("{}: sensitivity peak {:.3f} > {:.3f}", where, a.sensitivity_peak, c.sensitivity_peak_max);
  } else if (a.step_overshoot > c.step_overshoot_max) {
    v.violation = fmt::format("{}: step overshoot {:.1f} % > {:.1f} %", where, 100.0 * a.step_overshoot,
                              100.0 * c.step_overshoot_max);
  }
  v.linear_ok = v.violation.empty();
  return v;
}

PlannedScenario plan_scenario(const io::Scenario& scenario) {
  PlannedScenario p;
  sim::PlannedProgram planned = sim::plan_program(scenario, scenario.machine);
  p.program = std::move(planned.program);
  p.trajectory = planned.trajectory();
  p.corners = corner_windows(p.trajectory, p.program);
  for (const auto& c : p.corners)
    if (is_feed_move(p.program, c.corner.block_before) && is_feed_move(p.program, c.corner.block_after))
      p.tuning_corners.push_back(c);
  if (p.tuning_corners.empty()) p.tuning_corners = p.corners;
  p.total_ticks = sim::run_ticks(scenario, p.trajectory);
  if (p.tuning_corners.empty()) {
    // A program without corners (a straight slot): its errors are judged over the whole run.
    CornerWindow whole;
    whole.k_begin = 0;
    whole.k_end = p.total_ticks;
    whole.t_end_s = static_cast<double>(p.total_ticks) * p.trajectory.Ts_s();
    p.tuning_corners.push_back(whole);
  }
  return p;
}

SimulationWindow full_window(const PlannedScenario& planned) {
  return SimulationWindow{0, planned.total_ticks, planned.corners.empty() ? planned.tuning_corners : planned.corners};
}

SimulationWindow corner_window(const PlannedScenario& planned, double before_s, double after_s, double max_span_s) {
  if (planned.tuning_corners.empty()) return full_window(planned);
  const double Ts = planned.trajectory.Ts_s();
  SimulationWindow w;
  // The first tuning corner, and the next ones while they end within max_span_s of its start.
  const auto& first = planned.tuning_corners.front();
  for (const auto& c : planned.tuning_corners)
    if (w.corners.empty() || static_cast<double>(c.k_end - first.k_begin) * Ts <= max_span_s) w.corners.push_back(c);
  w.k_begin = std::max<std::int64_t>(0, w.corners.front().k_begin - static_cast<std::int64_t>(std::llround(before_s / Ts)));
  w.k_end = std::min(planned.total_ticks, w.corners.back().k_end + static_cast<std::int64_t>(std::llround(after_s / Ts)));
  return w;
}

namespace {

/// Puts the co-simulation in steady motion at tick k0 > 0 of the planned program.
void start_in_motion(sim::CoSimulation& cosim, const controller::Trajectory& trajectory, std::int64_t k0) {
  const auto r0 = trajectory.sample(k0);
  const auto r1 = trajectory.sample(k0 - 1);
  const auto r2 = trajectory.sample(std::max<std::int64_t>(0, k0 - 2));
  AxisArray<std::optional<sim::ReferenceAtStart>> ref{};
  for (Axis ax : cosim.axes()) {
    const std::size_t a = index(ax);
    ref[a] = sim::ReferenceAtStart{r0.x_mm[a], r1.x_mm[a], r2.x_mm[a], r0.v_mm_per_s[a]};
  }
  sim::start_in_steady_motion(cosim, ref, k0);
}

/// The figures of a window, one tick after the other: command peaks, saturation and
/// the errors after the stop over every tick, the tracking and contour errors inside
/// the window's corners.
class WindowFigures {
 public:
  WindowFigures(const std::vector<Axis>& axes, const SimulationWindow& window) : axes_(axes), window_(window) {
    m_.u_peak_block.fill(-1);
  }

  void add(const sim::Snapshot& s, std::int64_t k) {
    ++m_.ticks;
    for (Axis ax : axes_) {
      const auto& x = s.axes[index(ax)];
      if (std::abs(x.u_V) > m_.u_peak_V[index(ax)]) {
        m_.u_peak_V[index(ax)] = std::abs(x.u_V);
        m_.u_peak_t_s[index(ax)] = s.t_s;
        m_.u_peak_block[index(ax)] = s.block;
      }
      if (x.saturated) ++m_.saturated_ticks[index(ax)];
      if (s.reference_done)
        m_.max_error_after_stop_mm[index(ax)] = std::max(m_.max_error_after_stop_mm[index(ax)], std::abs(x.e_mm));
    }
    m_.max_contour_error_run_mm = std::max(m_.max_contour_error_run_mm, s.contour_error_mm);
    if (!in_corner(k)) return;
    ++n_corner_;
    for (Axis ax : axes_) {
      const double e = s.axes[index(ax)].e_mm;
      m_.max_tracking_error_mm[index(ax)] = std::max(m_.max_tracking_error_mm[index(ax)], std::abs(e));
      sum_e2_[index(ax)] += e * e;
    }
    m_.max_contour_error_mm = std::max(m_.max_contour_error_mm, s.contour_error_mm);
    sum_c2_ += s.contour_error_mm * s.contour_error_mm;
  }

  ScenarioMetrics finish(bool completed, std::string failure) {
    m_.completed = completed;
    m_.failure = std::move(failure);
    const double n = std::max<double>(1.0, static_cast<double>(n_corner_));
    for (Axis ax : axes_) m_.rms_tracking_error_mm[index(ax)] = std::sqrt(sum_e2_[index(ax)] / n);
    m_.rms_contour_error_mm = std::sqrt(sum_c2_ / n);
    return m_;
  }

 private:
  bool in_corner(std::int64_t k) {
    const auto& corners = window_.corners;
    while (next_ < corners.size() && corners[next_].k_end <= k) ++next_;
    bool in = false;
    for (std::size_t c = next_; c < corners.size() && corners[c].k_begin <= k; ++c)
      if (k < corners[c].k_end) in = true;
    return in;
  }

  const std::vector<Axis>& axes_;
  const SimulationWindow& window_;
  ScenarioMetrics m_;
  AxisArray<double> sum_e2_{};
  double sum_c2_{0.0};
  std::int64_t n_corner_{0};
  std::size_t next_{0};
};

}  // namespace

ScenarioMetrics simulate_window(const io::Scenario& scenario, const PlannedScenario& planned,
                                const sim::MachineDefinition& machine, const SimulationWindow& window,
                                CornerTrace* trace, std::int64_t trace_begin, std::int64_t trace_end) {
  const std::int64_t k0 = window.k_begin;
  AxisArray<double> x0 = scenario.start_mm;
  if (k0 > 0) x0 = planned.trajectory.sample(k0).x_mm;
  sim::CoSimulation cosim = sim::build_cosimulation(
      scenario,
      {.machine = &machine, .reference = std::make_shared<sim::ProgramReference>(planned.trajectory), .start_mm = x0});
  const auto& axes = cosim.axes();
  if (k0 > 0) start_in_motion(cosim, planned.trajectory, k0);
  if (trace) *trace = CornerTrace{};
  WindowFigures figures(axes, window);
  try {
    for (std::int64_t k = k0; k < window.k_end; ++k) {
      const sim::Snapshot& s = cosim.step();
      figures.add(s, k);
      if (trace && k >= trace_begin && k < trace_end) {
        trace->t_s.push_back(s.t_s);
        for (Axis ax : axes) trace->e_mm[index(ax)].push_back(s.axes[index(ax)].e_mm);
        trace->contour_mm.push_back(s.contour_error_mm);
      }
    }
  } catch (const ModelError& e) {
    return figures.finish(false, e.what());
  }
  return figures.finish(true, "");
}

namespace {

/// Per-axis search variables, one per gain the law searches: ln(gain / base) for a
/// feedback gain (a gain with base 0 stays 0), gain / model value for a feedforward gain.
struct AxisScales {
  Axis axis{Axis::kX};
  LinearPlant plant;
  double Ts_s;
  controller::PositionLoopParams start;
  const controller::Law* law{nullptr};
  std::vector<const LawGain*> vars;  ///< feedback gains first
  std::vector<double> base;
  std::size_t feedback_vars{0};

  AxisScales(Axis a, const LinearPlant& p, double Ts, const controller::PositionLoopParams& g)
      : axis(a), plant(p), Ts_s(Ts), start(g), law(&controller::law_of(g.law)) {
    for (const LawGain& lg : law->gains()) {
      if (!lg.searched) continue;
      vars.push_back(&lg);
      if (lg.feedforward) {
        base.push_back(lg.model(plant));
      } else {
        const double v = lg.get(start);
        base.push_back(v > 0.0 ? v : (lg.base_when_zero ? lg.base_when_zero(start) : 0.0));
        ++feedback_vars;
      }
    }
  }
  std::size_t size() const { return vars.size(); }
  /// The search's starting variables: the start's feedback gains, the model feedforward.
  std::vector<double> origin() const {
    std::vector<double> q(size(), 0.0);
    for (std::size_t i = feedback_vars; i < size(); ++i) q[i] = 1.0;
    return q;
  }
  double lower(std::size_t i, double log_range) const {
    return vars[i]->feedforward ? 0.0 : (base[i] > 0.0 ? -log_range : 0.0);
  }
  double upper(std::size_t i, double log_range, double ff_range) const {
    return vars[i]->feedforward ? ff_range : (base[i] > 0.0 ? log_range : 0.0);
  }
  controller::PositionLoopParams gains(const double* q) const {
    controller::PositionLoopParams g = start;
    for (std::size_t i = 0; i < size(); ++i)
      vars[i]->ref(g) = vars[i]->feedforward ? base[i] * q[i] : (base[i] > 0.0 ? base[i] * std::exp(q[i]) : 0.0);
    return g;
  }
  /// `start` with every feedforward gain of the law at its model value.
  controller::PositionLoopParams model_feedforward() const {
    controller::PositionLoopParams g = start;
    for (const LawGain& lg : law->gains())
      if (lg.feedforward) lg.ref(g) = lg.model(plant);
    return g;
  }
  /// `g` with its searched feedforward gains scaled by alpha.
  controller::PositionLoopParams scaled_feedforward(controller::PositionLoopParams g, double alpha) const {
    for (std::size_t i = feedback_vars; i < size(); ++i) vars[i]->ref(g) *= alpha;
    return g;
  }
};

/// Peak |command| of axis `a` over a run in its law's unit (u in V, or the torque); a
/// tick at the limit counts as the limit (the cascade limits the torque command before
/// the current loop's lag, whose output may stay just below it).
double command_peak(const ScenarioMetrics& m, const sim::MachineDefinition& machine, Axis a) {
  const auto& def = machine.axes[index(a)];
  const controller::Law& law = controller::law_of(def.loop.law);
  const LinearPlant p = linear_plant(def.drive);
  const double peak = m.u_peak_V[index(a)] * p.Ka_A_per_V * p.Kt_Nm_per_A / law.torque_per_command(p);
  return m.saturated_ticks[index(a)] > 0 ? std::max(peak, law.command_limit(def.loop)) : peak;
}
double command_limit(const sim::MachineDefinition& machine, Axis a, const TuneConstraints& c) {
  const auto& loop = machine.axes[index(a)].loop;
  return c.u_fraction_max * controller::law_of(loop.law).command_limit(loop);
}
/// "|u| 9.844 V > 9.500 V" or "|torque| 30.200 torque unit > 29.402 torque unit".
std::string command_text(const sim::MachineDefinition& machine, Axis a, double value, double limit) {
  const controller::Law& law = controller::law_of(machine.axes[index(a)].loop.law);
  return fmt::format("|{}| {:.3f} {} > {:.3f} {}", law.command_name(), value, law.command_unit(), limit,
                     law.command_unit());
}

struct StageA {
  const AxisScales* scales;
  const TuneConstraints* constraints;
  std::string where;
};

double stage_a_objective(unsigned n, const double* q, double*, void*) {
  double s = 0.0;
  for (unsigned i = 0; i < n; ++i) s += q[i] * q[i];
  return s;
}

double stage_a_constraint(unsigned n, const double* q, double*, void* data) {
  const auto* d = static_cast<const StageA*>(data);
  std::vector<double> full(d->scales->size(), 0.0);
  std::copy(q, q + n, full.begin());
  // Aim a little inside the constraints so that COBYLA's last point is feasible.
  TuneConstraints tight = *d->constraints;
  tight.phase_margin_min_deg += 0.5;
  tight.gain_margin_min_dB += 0.2;
  tight.sensitivity_peak_max -= 0.02;
  tight.step_overshoot_max -= 0.005;
  try {
    const ConstraintValues v = linear_constraints(d->scales->plant, d->scales->gains(full.data()), d->scales->Ts_s, tight,
                                                 d->where);
    return linear_violation(v, tight);
  } catch (const ConfigError&) {
    return 100.0;
  }
}

struct StageB {
  const io::Scenario* scenario;
  const PlannedScenario* planned;
  const SimulationWindow* window;
  const TuneOptions* options;
  std::vector<AxisScales> scales;
  std::vector<std::size_t> offsets;  ///< where each axis's variables start in q
  sim::MachineDefinition machine;
  double norm_contour{1.0}, norm_rms{1.0}, norm_max{1.0};
  int evaluations{0};
  double best_objective{std::numeric_limits<double>::infinity()};
  std::vector<double> best_q;
  ScenarioMetrics best_metrics;
};

double objective_of(const ScenarioMetrics& m, const std::vector<AxisScales>& scales, const StageB& d) {
  double rms = 0.0, mx = 0.0;
  for (const auto& s : scales) {
    rms += m.rms_tracking_error_mm[index(s.axis)];
    mx += m.max_tracking_error_mm[index(s.axis)];
  }
  return m.max_contour_error_mm / d.norm_contour + d.options->rms_weight * rms / d.norm_rms +
         d.options->max_tracking_weight * mx / d.norm_max;
}

/// Simulation constraint violation: peak |command| beyond the limit, or a runaway.
double simulation_violation(const ScenarioMetrics& m, const std::vector<AxisScales>& scales,
                            const sim::MachineDefinition& machine, const TuneConstraints& c) {
  if (!m.completed) return 10.0;
  double s = 0.0;
  for (const auto& sc : scales) {
    const double limit = command_limit(machine, sc.axis, c);
    s += std::max(0.0, (command_peak(m, machine, sc.axis) - limit) / limit);
  }
  return s;
}

double stage_b_objective(unsigned n, const double* q, double*, void* data) {
  auto* d = static_cast<StageB*>(data);
  const TuneConstraints& c = d->options->constraints;
  double lin = 0.0;
  sim::MachineDefinition machine = d->machine;
  for (std::size_t i = 0; i < d->scales.size(); ++i) {
    const auto& s = d->scales[i];
    const controller::PositionLoopParams g = s.gains(q + d->offsets[i]);
    try {
      lin += linear_violation(linear_constraints(s.plant, g, s.Ts_s, c, std::string(axis_name(s.axis))), c);
    } catch (const ConfigError&) {
      lin += 100.0;
    }
    machine.axes[index(s.axis)].loop = g;
  }
  if (lin > 0.0) return 1e3 * (1.0 + lin);
  ++d->evaluations;
  const ScenarioMetrics m = simulate_window(*d->scenario, *d->planned, machine, *d->window);
  const double simv = simulation_violation(m, d->scales, machine, c);
  if (simv > 0.0) return 1e2 * (1.0 + simv);
  const double f = objective_of(m, d->scales, *d);
  if (f < d->best_objective) {
    d->best_objective = f;
    d->best_q.assign(q, q + n);
    d->best_metrics = m;
  }
  return f;
}

}  // namespace

namespace {

std::string motion_text(const PlannedScenario& planned, int block) {
  if (block < 0 || block >= static_cast<int>(planned.program.blocks.size())) return "while settling after the program";
  const auto& b = planned.program.blocks[static_cast<std::size_t>(block)];
  const char* kind = b.kind == controller::MotionKind::kRapid    ? "a rapid (G0)"
                     : b.kind == controller::MotionKind::kLinear ? "a feed move (G1)"
                     : b.kind == controller::MotionKind::kDwell  ? "a dwell (G4)"
                                                                 : "an arc";
  return fmt::format("in {} at line {}", kind, b.line);
}

/// Before/after figures of one axis; the |u| constraint from the full-scenario runs.
AxisTuneResult axis_result(const AxisScales& s, const controller::PositionLoopParams& after,
                           const sim::MachineDefinition& machine, const ScenarioMetrics& full_before,
                           const ScenarioMetrics& full_after, const TuneConstraints& c) {
  AxisTuneResult ar;
  ar.axis = s.axis;
  ar.before = s.start;
  ar.after = after;
  ar.model_feedforward = s.model_feedforward();
  const std::string name(axis_name(s.axis));
  ar.analysis_before = analyse_loop(DiscreteLoopModel(s.plant, ar.before, s.Ts_s, name));
  ar.analysis_after = analyse_loop(DiscreteLoopModel(s.plant, ar.after, s.Ts_s, name));
  ar.constraints_before = linear_constraints(s.plant, ar.before, s.Ts_s, c, name);
  ar.constraints_after = linear_constraints(s.plant, ar.after, s.Ts_s, c, name);
  for (auto* pair : {&ar.constraints_before, &ar.constraints_after}) {
    const ScenarioMetrics& fm = pair == &ar.constraints_before ? full_before : full_after;
    pair->command_peak = command_peak(fm, machine, s.axis);
    pair->simulation_ok = fm.completed && pair->command_peak <= pair->command_limit;
    if (pair->violation.empty() && !pair->simulation_ok)
      pair->violation = fm.completed ? fmt::format("{}: peak {} in the full scenario", name,
                                                   command_text(machine, s.axis, pair->command_peak,
                                                                pair->command_limit))
                                     : fmt::format("{}: {}", name, fm.failure);
  }
  return ar;
}

/// The largest alpha in [0, 1] (to 1/32) for which axis `s.axis` with gains `g`, its searched
/// feedforward scaled by alpha, keeps its peak command within `limit` on the window (the
/// other axes as in `machine`); -1 when even alpha = 0 does not, or when the law searches
/// no feedforward (the cascade keeps the machine's). At most 6 simulations.
double reachable_feedforward(const io::Scenario& scenario, const PlannedScenario& planned,
                             sim::MachineDefinition machine, const AxisScales& s,
                             const controller::PositionLoopParams& g, const SimulationWindow& window, double limit) {
  if (s.feedback_vars == s.size()) return -1.0;
  auto ok = [&](double alpha) {
    machine.axes[index(s.axis)].loop = s.scaled_feedforward(g, alpha);
    const ScenarioMetrics m = simulate_window(scenario, planned, machine, window);
    return m.completed && command_peak(m, machine, s.axis) <= limit;
  };
  if (!ok(0.0)) return -1.0;
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 5; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ok(mid) ? lo : hi) = mid;
  }
  return lo;
}

}  // namespace

namespace {

/// Axes that keep the machine's gains, with the reason (in the order found).
using KeptAxes = std::vector<std::pair<AxisScales, std::string>>;

/// One tuning of a scenario's axes: stage A (nearest feedback gains meeting the
/// linear constraints, per axis), stage B (the coupled simulation through the
/// corners), then the judgement on the full scenario. Each step drops the axes
/// it cannot tune into `kept_` with the reason.
class Tuner {
 public:
  Tuner(const io::Scenario& scenario, const TuneOptions& options)
      : scenario_(scenario), options_(options), m0_(scenario.machine), c_(options.constraints) {}

  TuneResult run() {
    result_.machine_before = m0_;
    result_.machine_after = m0_;
    check_options();
    lr_ = std::log(options_.gain_range);
    for (const AxisScales& s : requested_axes()) stage_a(s);
    if (scales_.empty()) return keep_all(ScenarioMetrics{});  // nothing is simulated
    planned_.emplace(plan_scenario(scenario_));
    full_ = full_window(*planned_);
    result_.full_before = simulate_window(scenario_, *planned_, m0_, full_);
    if (result_.full_before.completed) drop_axes_beyond_limit_on_full();
    if (scales_.empty()) return keep_all(result_.full_before);
    window_ = corner_window(*planned_, options_.window_before_s, options_.window_after_s, options_.max_window_span_s);
    start_within_limit();
    if (scales_.empty()) return keep_all(result_.full_before);
    StageB data = stage_b_data();
    search(data);
    if (data.best_q.empty()) return no_feasible_point();
    take_best(data);
    report_tuned(judge_on_full());
    return result_;
  }

 private:
  void check_options() const {
    const TuneOptions& o = options_;
    if (o.axes.empty()) throw ConfigError("tune: no axis to tune");
    if (!(o.gain_range > 1.0) || !(o.feedforward_range > 0.0) || o.max_evaluations < 1 || !(o.max_window_span_s > 0.0))
      throw ConfigError(fmt::format("tune: gain_range {} must be > 1, feedforward_range {} > 0, max_evaluations {} "
                                    ">= 1, --max-window {} s > 0",
                                    o.gain_range, o.feedforward_range, o.max_evaluations, o.max_window_span_s));
  }

  std::vector<AxisScales> requested_axes() const {
    std::vector<AxisScales> requested;
    for (Axis a : options_.axes) {
      const auto& def = m0_.axes[index(a)];
      if (!def.present)
        throw ConfigError(fmt::format("tune: axis {} is not present in machine {}", axis_name(a), m0_.name));
      const LinearPlant plant = linear_plant(def.drive);
      plant.validate(fmt::format("{}: axis {}", m0_.source.empty() ? m0_.name : m0_.source, axis_name(a)));
      requested.emplace_back(a, plant, m0_.Ts_s, def.loop);
    }
    return requested;
  }

  /// Stage A of one axis: its nearest feedback gains that meet the linear
  /// constraints become its starting point, or it keeps its gains.
  void stage_a(const AxisScales& s) {
    StageA data{&s, &c_, std::string(axis_name(s.axis))};
    const unsigned nf = static_cast<unsigned>(s.feedback_vars);
    nlopt::opt opt(nlopt::LN_COBYLA, nf);
    std::vector<double> lo(nf), hi(nf);
    for (std::size_t i = 0; i < nf; ++i) {
      lo[i] = s.lower(i, lr_);
      hi[i] = s.upper(i, lr_, options_.feedforward_range);
    }
    opt.set_lower_bounds(lo);
    opt.set_upper_bounds(hi);
    opt.set_min_objective(stage_a_objective, &data);
    opt.add_inequality_constraint(stage_a_constraint, &data, 0.0);
    opt.set_maxeval(600);
    opt.set_xtol_abs(1e-4);
    opt.set_initial_step(0.3);
    std::vector<double> x(nf, 0.0);
    double fval = 0.0;
    // Gains that already meet the constraints are their own nearest point (COBYLA would
    // end within its tolerance of them, not on them).
    if (stage_a_constraint(nf, x.data(), nullptr, &data) > 0.0) {
      try {
        opt.optimize(x, fval);
      } catch (const std::exception&) {
        // COBYLA's stopping by round-off is not a failure: the point is checked below.
      }
    }
    std::vector<double> full = s.origin();
    std::copy(x.begin(), x.end(), full.begin());
    const ConstraintValues v =
        linear_constraints(s.plant, s.gains(full.data()), s.Ts_s, c_, std::string(axis_name(s.axis)));
    if (v.linear_ok) {
      scales_.push_back(s);
      q0_.push_back(full);
      return;
    }
    std::string names;
    for (std::size_t i = 0; i < nf; ++i) names += fmt::format("{}{}", i > 0 ? ", " : "", s.vars[i]->name);
    kept_.emplace_back(s, fmt::format("no gains satisfy the constraints on axis {} within the search range ({} in "
                                      "[1/{:g}, {:g}] x start): best found {} ({}); start {}",
                                      axis_name(s.axis), names, options_.gain_range, options_.gain_range,
                                      gains_text(s.gains(full.data())), v.violation, gains_text(s.start)));
  }

  std::string kept_text() const {
    std::string t;
    for (const auto& [s, why] : kept_)
      t += fmt::format("{}axis {} keeps the machine's gains: {}", t.empty() ? "" : "; ", axis_name(s.axis), why);
    return t;
  }

  /// The kept axes' results, then every axis in axis order.
  void finish_kept(const ScenarioMetrics& fb, const ScenarioMetrics& fa) {
    for (const auto& [s, why] : kept_) {
      AxisTuneResult ar = axis_result(s, s.start, m0_, fb, fa, c_);
      ar.tuned = false;
      ar.note = why;
      result_.axes.push_back(ar);
    }
    std::stable_sort(result_.axes.begin(), result_.axes.end(),
                     [](const AxisTuneResult& x, const AxisTuneResult& y) { return index(x.axis) < index(y.axis); });
  }

  /// Every axis keeps its gains; `full` is the scenario with them.
  TuneResult keep_all(const ScenarioMetrics& full) {
    result_.feasible = false;
    result_.message = kept_text();
    finish_kept(full, full);
    result_.full_after = full;
    return result_;
  }

  /// Keeps the axes of scales_ (and their q0_) for which keep(i) is true.
  template <typename F>
  void filter_axes(F&& keep) {
    std::vector<AxisScales> reachable;
    std::vector<std::vector<double>> q_reachable;
    for (std::size_t i = 0; i < scales_.size(); ++i) {
      if (!keep(i)) continue;
      reachable.push_back(scales_[i]);
      q_reachable.push_back(q0_[i]);
    }
    scales_ = std::move(reachable);
    q0_ = std::move(q_reachable);
  }

  /// The machine's own gains on the full scenario: an axis whose peak |u| is already
  /// above the limit there cannot be judged against it (no new gains could pass where the
  /// program itself asks for that much, e.g. a rapid plunge): it keeps its gains.
  void drop_axes_beyond_limit_on_full() {
    const ScenarioMetrics& fb = result_.full_before;
    filter_axes([&](std::size_t i) {
      const Axis a = scales_[i].axis;
      const double limit = command_limit(m0_, a, c_);
      const double peak = command_peak(fb, m0_, a);
      if (!(peak > limit)) return true;
      kept_.emplace_back(
          scales_[i],
          fmt::format("its own gains already reach peak {} ({:g} x {}) on this scenario, at "
                      "t = {:.4f} s {} ({} ticks at the limit), so the scenario cannot show that new gains keep the "
                      "limit; axis {} is left as it is (tune it on a scenario without that move, or raise "
                      "--u-fraction)",
                      command_text(m0_, a, peak, limit), c_.u_fraction_max,
                      controller::law_of(m0_.axes[index(a)].loop.law).command_limit_name(), fb.u_peak_t_s[index(a)],
                      motion_text(*planned_, fb.u_peak_block[index(a)]), fb.saturated_ticks[index(a)], axis_name(a)));
      return false;
    });
  }

  /// The machine with every remaining axis at its stage-A point.
  sim::MachineDefinition machine_at_start() const {
    sim::MachineDefinition ms = m0_;
    for (std::size_t i = 0; i < scales_.size(); ++i) ms.axes[index(scales_[i].axis)].loop = scales_[i].gains(q0_[i].data());
    return ms;
  }

  /// Stage B's starting point (stage-A feedback, model feedforward) must keep the |u|
  /// limit on the window: an axis that breaks it starts with its feedforward scaled down
  /// to what keeps it (or, if even no feedforward does, keeps its own gains), so the
  /// search starts from reachable gains.
  void start_within_limit() {
    sim::MachineDefinition ms = machine_at_start();
    const ScenarioMetrics start = simulate_window(scenario_, *planned_, ms, window_);
    filter_axes([&](std::size_t i) {
      const AxisScales& s = scales_[i];
      const Axis a = s.axis;
      const double limit = command_limit(m0_, a, c_);
      std::vector<double>& q = q0_[i];
      const double peak = command_peak(start, ms, a);
      if (!start.completed || !(peak > limit)) return true;
      const bool has_ff = s.feedback_vars < s.size();
      const double alpha = reachable_feedforward(scenario_, *planned_, ms, s, s.gains(q.data()), window_, limit);
      const std::string where = fmt::format(
          "with {} the peak {} at t = {:.4f} s {}", has_ff ? "the model feedforward" : "the machine's feedforward",
          command_text(ms, a, peak, limit), start.u_peak_t_s[index(a)],
          motion_text(*planned_, start.u_peak_block[index(a)]));
      if (alpha < 0.0) {
        kept_.emplace_back(s, where + (has_ff ? ", and above it without feedforward too (feedback at the nearest "
                                                "gains meeting the margins): no starting point keeps the limit"
                                              : " at the nearest feedback gains meeting the margins: no starting "
                                                "point keeps the limit"));
        return false;
      }
      for (std::size_t j = s.feedback_vars; j < s.size(); ++j) q[j] *= alpha;
      limited_[index(a)] = fmt::format("{}; the search started from {:.3f} x the model feedforward", where, alpha);
      ms.axes[index(a)].loop = s.gains(q.data());
      return true;
    });
  }

  /// Stage B's data: the remaining axes, their variables one after the other, and the
  /// objective's norms from the machine's own gains on the window (or the start's).
  StageB stage_b_data() {
    StageB data;
    data.scenario = &scenario_;
    data.planned = &*planned_;
    data.window = &window_;
    data.options = &options_;
    data.scales = scales_;
    data.machine = m0_;
    for (std::size_t i = 0; i < scales_.size(); ++i) {
      data.offsets.push_back(x0_.size());
      x0_.insert(x0_.end(), q0_[i].begin(), q0_[i].end());
    }
    result_.window_before = simulate_window(scenario_, *planned_, m0_, window_);
    // An axis that does not move through the corners searched on (its error there is 0)
    // does not enter the objective: the search's moves of its gains mean nothing, and it
    // ends at its stage-A point.
    const ScenarioMetrics start = simulate_window(scenario_, *planned_, machine_at_start(), window_);
    for (const auto& s : scales_)
      idle_.push_back(start.completed && start.max_tracking_error_mm[index(s.axis)] == 0.0 &&
                      start.rms_tracking_error_mm[index(s.axis)] == 0.0);
    const ScenarioMetrics& ref = result_.window_before.completed ? result_.window_before : start;
    data.norm_contour = std::max(ref.max_contour_error_mm, 1e-6);
    double rms = 0.0, mx = 0.0;
    for (const auto& s : scales_) {
      rms += ref.rms_tracking_error_mm[index(s.axis)];
      mx += ref.max_tracking_error_mm[index(s.axis)];
    }
    data.norm_rms = std::max(rms, 1e-6);
    data.norm_max = std::max(mx, 1e-6);
    result_.objective_before =
        result_.window_before.completed ? objective_of(result_.window_before, scales_, data) : 0.0;
    return data;
  }

  /// Stage B: BOBYQA over every remaining axis's variables at once.
  void search(StageB& data) {
    const unsigned n = static_cast<unsigned>(x0_.size());
    std::vector<double> lb(n), ub(n), step(n);
    for (std::size_t i = 0; i < scales_.size(); ++i) {
      for (std::size_t j = 0; j < scales_[i].size(); ++j) {
        lb[data.offsets[i] + j] = scales_[i].lower(j, lr_);
        ub[data.offsets[i] + j] = scales_[i].upper(j, lr_, options_.feedforward_range);
        step[data.offsets[i] + j] = scales_[i].vars[j]->feedforward ? 0.1 : 0.15;
      }
    }
    nlopt::opt opt(nlopt::LN_BOBYQA, n);
    opt.set_lower_bounds(lb);
    opt.set_upper_bounds(ub);
    opt.set_min_objective(stage_b_objective, &data);
    opt.set_maxeval(options_.max_evaluations);
    opt.set_initial_step(step);
    opt.set_xtol_abs(1e-3);
    std::vector<double> x = x0_;
    double fval = 0.0;
    try {
      opt.optimize(x, fval);
    } catch (const std::exception&) {
      // A stop by round-off or by the evaluation budget keeps the best feasible point below.
    }
    result_.evaluations = data.evaluations;
  }

  /// No point the search evaluated met the simulation's constraints.
  TuneResult no_feasible_point() {
    result_.feasible = false;
    result_.message = "no evaluated gains met every constraint in the simulation (|u| below the limit, no runaway)";
    if (!kept_.empty()) result_.message += "; " + kept_text();
    result_.window_after = result_.window_before;
    result_.full_after = result_.full_before;
    for (const auto& s : scales_) {
      AxisTuneResult ar = axis_result(s, s.start, m0_, result_.full_before, result_.full_after, c_);
      ar.tuned = false;
      ar.note = result_.message;
      result_.axes.push_back(ar);
    }
    finish_kept(result_.full_before, result_.full_after);
    return result_;
  }

  /// The search's best point (idle axes at their stage-A point) as the tuned machine.
  void take_best(StageB& data) {
    for (std::size_t i = 0; i < scales_.size(); ++i)
      if (idle_[i])
        std::copy(q0_[i].begin(), q0_[i].end(), data.best_q.begin() + static_cast<std::ptrdiff_t>(data.offsets[i]));
    result_.window_after = data.best_metrics;
    result_.objective_after = data.best_objective;
    for (std::size_t i = 0; i < scales_.size(); ++i)
      result_.machine_after.axes[index(scales_[i].axis)].loop = scales_[i].gains(&data.best_q[data.offsets[i]]);
  }

  /// Judges the tuned machine on the full scenario. An axis whose tuned gains break a
  /// constraint there (the search saw only the corner window) has its feedforward scaled
  /// down when only the command limit is broken, else goes back to its own gains, and the
  /// scenario is run again with the remaining tuned axes. Returns the tuned axes.
  std::vector<AxisScales> judge_on_full() {
    result_.full_after = simulate_window(scenario_, *planned_, result_.machine_after, full_);
    std::vector<AxisScales> tuned;
    for (const auto& s : scales_) {
      const AxisTuneResult ar = axis_result(s, result_.machine_after.axes[index(s.axis)].loop, m0_,
                                            result_.full_before, result_.full_after, c_);
      if (ar.constraints_after.violation.empty() || !result_.full_after.completed ||
          (ar.constraints_after.linear_ok && scale_to_limit_on_full(s, ar))) {
        tuned.push_back(s);
        continue;
      }
      kept_.emplace_back(s, fmt::format("the gains tuned on the corner window break a constraint on the full scenario "
                                        "({}; peak |u| at t = {:.4f} s {}{}) where its own gains keep it, so axis {} "
                                        "keeps its own gains",
                                        ar.constraints_after.violation, result_.full_after.u_peak_t_s[index(s.axis)],
                                        motion_text(*planned_, result_.full_after.u_peak_block[index(s.axis)]),
                                        ar.constraints_after.linear_ok && s.feedback_vars < s.size()
                                            ? ", also with no feedforward"
                                            : "",
                                        axis_name(s.axis)));
      result_.machine_after.axes[index(s.axis)].loop = s.start;
    }
    bool changed = tuned.size() != scales_.size();
    for (const auto& l : limited_) changed = changed || l.find("on the full scenario") != std::string::npos;
    if (changed) result_.full_after = simulate_window(scenario_, *planned_, result_.machine_after, full_);
    return tuned;
  }

  /// Only the command limit is broken on the full scenario: scales axis s's feedforward
  /// down to what keeps it; false when even none does.
  bool scale_to_limit_on_full(const AxisScales& s, const AxisTuneResult& ar) {
    const double limit = ar.constraints_after.command_limit;
    auto& g = result_.machine_after.axes[index(s.axis)].loop;
    const double alpha = reachable_feedforward(scenario_, *planned_, result_.machine_after, s, g, full_, limit);
    if (!(alpha >= 0.0)) return false;
    g = s.scaled_feedforward(g, alpha);
    limited_[index(s.axis)] +=
        fmt::format("{}on the full scenario the gains tuned on the corner window reach peak {} "
                    "at t = {:.4f} s {}: the feedforward was scaled by {:.3f} to keep the limit",
                    limited_[index(s.axis)].empty() ? "" : "; ",
                    command_text(m0_, s.axis, ar.constraints_after.command_peak, limit),
                    result_.full_after.u_peak_t_s[index(s.axis)],
                    motion_text(*planned_, result_.full_after.u_peak_block[index(s.axis)]), alpha);
    return true;
  }

  /// The tuned axes' results and the run's message.
  void report_tuned(const std::vector<AxisScales>& tuned) {
    result_.feasible = !tuned.empty();
    std::size_t changed_axes = 0;
    for (const auto& s : tuned) {
      AxisTuneResult ar = axis_result(s, result_.machine_after.axes[index(s.axis)].loop, m0_, result_.full_before,
                                      result_.full_after, c_);
      ar.note = limited_[index(s.axis)];
      if (gains_unchanged(s, ar)) {
        ar.tuned = false;
        ar.note = unchanged_note(s.axis);
      } else {
        ++changed_axes;
      }
      if (!ar.constraints_after.violation.empty() && result_.feasible) {
        result_.feasible = false;
        result_.message = fmt::format("tuned gains break a constraint on the full scenario: {}",
                                      ar.constraints_after.violation);
      }
      result_.axes.push_back(ar);
    }
    finish_kept(result_.full_before, result_.full_after);
    if (result_.feasible) {
      result_.message = fmt::format(
          "tuned {} axis(es) in {} simulations: max contour error through the corners {:.3f} um -> {:.3f} um",
          changed_axes, result_.evaluations, 1e3 * result_.full_before.max_contour_error_mm,
          1e3 * result_.full_after.max_contour_error_mm);
      if (!kept_.empty()) result_.message += "; " + kept_text();
    } else if (result_.message.empty()) {
      result_.message = kept_text();
    }
  }

  static bool gains_unchanged(const AxisScales& s, const AxisTuneResult& ar) {
    bool same = true;
    for (const LawGain& lg : s.law->gains()) same = same && lg.get(ar.before) == lg.get(ar.after);
    return same;
  }

  /// The search's best point left this axis where it started (its start met every
  /// constraint and nothing it tried on this axis lowered the objective).
  std::string unchanged_note(Axis a) const {
    if (result_.window_before.max_tracking_error_mm[index(a)] == 0.0)
      return fmt::format("axis {} does not move through the corners searched on (its tracking error there "
                         "is 0), so the search cannot judge its gains; the machine's meet every constraint "
                         "and are kept",
                         axis_name(a));
    return "the machine's gains meet every constraint and no change of them lowered the objective; they are kept";
  }

  const io::Scenario& scenario_;
  const TuneOptions& options_;
  const sim::MachineDefinition& m0_;
  const TuneConstraints& c_;
  double lr_{0.0};  ///< ln(gain_range): the feedback variables' range
  TuneResult result_;
  KeptAxes kept_;
  std::vector<AxisScales> scales_;        ///< axes still being tuned
  std::vector<std::vector<double>> q0_;   ///< their starting variables
  std::vector<std::string> limited_ = std::vector<std::string>(kNumAxes);  ///< per axis: what limited the tuning
  std::optional<PlannedScenario> planned_;
  SimulationWindow full_;
  SimulationWindow window_;
  std::vector<double> x0_;  ///< all axes' starting variables, one after the other
  std::vector<bool> idle_;  ///< per axis of scales_: no error through the corners searched on
};

}  // namespace

TuneResult tune_gains(const io::Scenario& scenario, const TuneOptions& options) {
  return Tuner(scenario, options).run();
}

namespace {

/// The law's gains under their report names (`feedforward_only`: only its feedforward gains).
nlohmann::json gains_json(const controller::PositionLoopParams& g, bool feedforward_only = false) {
  nlohmann::json j = nlohmann::json::object();
  for (const LawGain& lg : controller::law_of(g.law).gains())
    if (lg.feedforward || !feedforward_only) j[std::string(lg.json_key)] = lg.get(g);
  return j;
}

double finite_or(double v, double alt) { return std::isfinite(v) ? v : alt; }

nlohmann::json analysis_json(const LoopAnalysis& a) {
  nlohmann::json poles = nlohmann::json::array();
  for (const auto& p : a.poles) poles.push_back({p.real(), p.imag()});
  // JSON has no infinity: a margin that does not exist is written as null.
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json j = {{"stable", a.stable},
          {"poles_z", poles},
          {"gain_margin_dB", num(a.gain_margin_dB)},
          {"phase_crossover_Hz", a.phase_crossover_Hz},
          {"phase_margin_deg", num(a.phase_margin_deg)},
          {"gain_crossover_Hz", a.gain_crossover_Hz},
          {"sensitivity_peak", a.sensitivity_peak},
          {"sensitivity_peak_dB", a.sensitivity_peak_dB},
          {"bandwidth_Hz", a.bandwidth_Hz},
          {"bandwidth_with_feedforward_Hz", a.bandwidth_with_feedforward_Hz},
          {"step_overshoot", num(a.step_overshoot)},
          {"step_settling_time_s", num(a.step_settling_time_s)},
          {"tracking_error_gain_1Hz", a.error_gain_1Hz},
          {"tracking_error_gain_10Hz", a.error_gain_10Hz}};
  if (a.velocity_loop) {
    j["velocity_loop_phase_margin_deg"] = num(a.velocity_loop_phase_margin_deg);
    j["velocity_loop_gain_crossover_Hz"] = a.velocity_loop_gain_crossover_Hz;
    j["velocity_loop_gain_margin_dB"] = num(a.velocity_loop_gain_margin_dB);
    j["velocity_loop_phase_crossover_Hz"] = a.velocity_loop_phase_crossover_Hz;
  }
  return j;
}

nlohmann::json constraints_json(const ConstraintValues& v) {
  // The FADAL law's command is u in V (u_peak_V, u_limit_V); the cascade's the torque in
  // the machine's torque unit (torque_peak, torque_limit).
  const std::string unit = v.command_unit == "V" ? "_V" : "";
  return {{"phase_margin_deg", finite_or(v.phase_margin_deg, 1e300)},
          {"gain_margin_dB", finite_or(v.gain_margin_dB, 1e300)},
          {"sensitivity_peak", v.sensitivity_peak},
          {"step_overshoot", finite_or(v.step_overshoot, 1e300)},
          {fmt::format("{}_peak{}", v.command_name, unit), v.command_peak},
          {fmt::format("{}_limit{}", v.command_name, unit), v.command_limit},
          {"satisfied", v.violation.empty()},
          {"violation", v.violation}};
}

nlohmann::json axis_metrics_json(const ScenarioMetrics& m, Axis a) {
  return {{"max_tracking_error_mm", m.max_tracking_error_mm[index(a)]},
          {"rms_tracking_error_mm", m.rms_tracking_error_mm[index(a)]},
          {"u_peak_V", m.u_peak_V[index(a)]},
          {"saturated_ticks", m.saturated_ticks[index(a)]},
          {"max_error_after_stop_mm", m.max_error_after_stop_mm[index(a)]}};
}

nlohmann::json metrics_json(const ScenarioMetrics& m, const std::vector<Axis>& axes) {
  nlohmann::json j = {{"completed", m.completed},
                      {"max_contour_error_corners_mm", m.max_contour_error_mm},
                      {"rms_contour_error_corners_mm", m.rms_contour_error_mm},
                      {"max_contour_error_run_mm", m.max_contour_error_run_mm},
                      {"ticks", m.ticks}};
  if (!m.completed) j["failure"] = m.failure;
  for (Axis a : axes) j["axes"][std::string(axis_name(a))] = axis_metrics_json(m, a);
  return j;
}

}  // namespace

nlohmann::json tune_report(const io::Scenario& scenario, const TuneOptions& options, const TuneResult& r,
                           const std::optional<io::Scenario>& check_scenario,
                           const std::optional<std::pair<ScenarioMetrics, ScenarioMetrics>>& check_metrics) {
  nlohmann::json j;
  j["scenario"] = scenario.name;
  j["machine"] = scenario.machine.name;
  j["feasible"] = r.feasible;
  j["message"] = r.message;
  const auto& c = options.constraints;
  j["constraints"] = {{"phase_margin_min_deg", c.phase_margin_min_deg},
                      {"gain_margin_min_dB", c.gain_margin_min_dB},
                      {"sensitivity_peak_max", c.sensitivity_peak_max},
                      {"step_overshoot_max", c.step_overshoot_max},
                      {"u_fraction_max", c.u_fraction_max}};
  nlohmann::json searched = nlohmann::json::object();
  for (const auto& a : r.axes) {
    nlohmann::json names = nlohmann::json::array();
    for (const LawGain& lg : controller::law_of(a.before.law).gains())
      if (lg.searched) names.push_back(lg.name);
    searched[std::string(axis_name(a.axis))] = names;
  }
  j["search"] = {{"method", "NLopt COBYLA (linear constraints) then BOBYQA (coupled simulation)"},
                 {"gains_searched", searched},
                 {"simulations", r.evaluations},
                 {"max_evaluations", options.max_evaluations},
                 {"window_before_s", options.window_before_s},
                 {"window_after_s", options.window_after_s},
                 {"max_window_span_s", options.max_window_span_s},
                 {"objective_before", r.objective_before},
                 {"objective_after", r.objective_after}};
  std::vector<Axis> axes;
  for (const auto& a : r.axes) axes.push_back(a.axis);
  for (const auto& a : r.axes) {
    nlohmann::json ja;
    ja["tuned"] = a.tuned;
    ja["note"] = a.note;
    ja["gains_before"] = gains_json(a.before);
    ja["gains_after"] = gains_json(a.after);
    ja["controller"] = controller::loop_law_name(a.before.law);
    ja["model_feedforward"] = gains_json(a.model_feedforward, true);
    ja["analysis_before"] = analysis_json(a.analysis_before);
    ja["analysis_after"] = analysis_json(a.analysis_after);
    ja["constraints_before"] = constraints_json(a.constraints_before);
    ja["constraints_after"] = constraints_json(a.constraints_after);
    ja["corners_before"] = axis_metrics_json(r.full_before, a.axis);
    ja["corners_after"] = axis_metrics_json(r.full_after, a.axis);
    j["axes"][std::string(axis_name(a.axis))] = ja;
  }
  j["scenario_before"] = metrics_json(r.full_before, axes);
  j["scenario_after"] = metrics_json(r.full_after, axes);
  j["tuning_window_before"] = metrics_json(r.window_before, axes);
  j["tuning_window_after"] = metrics_json(r.window_after, axes);
  const double b = r.full_before.max_contour_error_mm, a = r.full_after.max_contour_error_mm;
  j["max_contour_error_corners_ratio"] = b > 0.0 ? a / b : 0.0;
  if (check_scenario && check_metrics) {
    j["generalisation"] = {{"scenario", check_scenario->name},
                           {"before", metrics_json(check_metrics->first, axes)},
                           {"after", metrics_json(check_metrics->second, axes)}};
    const double cb = check_metrics->first.max_contour_error_mm, ca = check_metrics->second.max_contour_error_mm;
    j["generalisation"]["max_contour_error_corners_ratio"] = cb > 0.0 ? ca / cb : 0.0;
  }
  return j;
}

namespace {

/// bode.dat: per axis, the loop before and after tuning, one gnuplot index each
/// (f_Hz, |L|_dB, unwrapped arg L in deg, |S|_dB, |T|_dB, |E/R|_dB).
std::string bode_data(const TuneResult& r) {
  std::string text = "# f_Hz |L|_dB argL_deg |S|_dB |T|_dB |E/R|_dB\n";
  for (const auto& a : r.axes) {
    for (const auto* g : {&a.before, &a.after}) {
      const DiscreteLoopModel m(linear_plant(r.machine_before.axes[index(a.axis)].drive), *g,
                                r.machine_before.Ts_s);
      double unwrap = 0.0, prev = 0.0;
      bool first = true;
      for (const auto& p : frequency_response(m, 0.1, 600)) {
        double ph = std::arg(p.L) * kDegPerRad;
        if (!first) {
          while (ph + unwrap - prev > 180.0) unwrap -= 360.0;
          while (ph + unwrap - prev < -180.0) unwrap += 360.0;
        }
        first = false;
        prev = ph + unwrap;
        text += fmt::format("{:.6g} {:.6g} {:.6g} {:.6g} {:.6g} {:.6g}\n", p.f_Hz, 20.0 * std::log10(std::abs(p.L)),
                            prev, 20.0 * std::log10(std::abs(p.S)), 20.0 * std::log10(std::abs(p.T)),
                            20.0 * std::log10(std::max(std::abs(p.E_over_R), 1e-300)));
      }
      text += "\n\n";
    }
  }
  return text;
}

/// corner_error.dat: the tracking and contour errors through the first tuning corner
/// (with 0.02 s on either side) with the gains before and after, in um.
std::string corner_error_data(const io::Scenario& scenario, const PlannedScenario& planned, const TuneResult& r) {
  const auto& cw = planned.tuning_corners.front();
  const double Ts = planned.trajectory.Ts_s();
  const std::int64_t pad = static_cast<std::int64_t>(std::llround(0.02 / Ts));
  const std::int64_t t0 = std::max<std::int64_t>(0, cw.k_begin - pad), t1 = cw.k_end + pad;
  SimulationWindow w{std::max<std::int64_t>(0, t0 - static_cast<std::int64_t>(std::llround(0.1 / Ts))),
                     std::min(planned.total_ticks, t1), {cw}};
  CornerTrace before, after;
  simulate_window(scenario, planned, r.machine_before, w, &before, t0, t1);
  simulate_window(scenario, planned, r.machine_after, w, &after, t0, t1);
  std::string text = "# t_s";
  for (const auto& a : r.axes) text += fmt::format(" {0}_err_before_um {0}_err_after_um", axis_name(a.axis));
  text += " contour_before_um contour_after_um\n";
  const std::size_t n = std::min(before.t_s.size(), after.t_s.size());
  for (std::size_t k = 0; k < n; ++k) {
    text += fmt::format("{:.6f}", before.t_s[k]);
    for (const auto& a : r.axes)
      text += fmt::format(" {:.6g} {:.6g}", 1e3 * before.e_mm[index(a.axis)][k], 1e3 * after.e_mm[index(a.axis)][k]);
    text += fmt::format(" {:.6g} {:.6g}\n", 1e3 * before.contour_mm[k], 1e3 * after.contour_mm[k]);
  }
  return text;
}

}  // namespace

std::vector<std::filesystem::path> plot_tune(io::ResultSet& results, const io::Scenario& scenario,
                                             const TuneResult& r) {
  TunePlots plots;
  plots.machine_name = scenario.machine.name;
  for (const auto& a : r.axes) plots.axes.push_back(a.axis);
  io::write_file_atomic(results.path(plots.bode_name), bode_data(r));
  // Tracking error through the first tuning corner, before and after.
  const PlannedScenario planned = plan_scenario(scenario);
  if (!planned.tuning_corners.empty()) {
    io::write_file_atomic(results.path(plots.corner_name), corner_error_data(scenario, planned, r));
    plots.corner_title = planned.corners.empty()
                             ? std::string("Tracking error over the whole scenario (it has no corner)")
                             : fmt::format("Tracking error through the corner at line {}",
                                           planned.tuning_corners.front().line_after);
  }
  return plot_tuning(results, plots);
}

}  // namespace twin::analysis
