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
#include "twin/sim/cosimulation.hpp"
#include "twin/sim/reference.hpp"

namespace twin::analysis {

namespace {

bool is_feed_move(const controller::Program& program, int block) {
  if (block < 0 || block >= static_cast<int>(program.blocks.size())) return false;
  const auto kind = program.blocks[static_cast<std::size_t>(block)].kind;
  return kind == controller::MotionKind::kLinear || kind == controller::MotionKind::kArcCw ||
         kind == controller::MotionKind::kArcCcw;
}

std::string gains_text(const controller::PositionLoopParams& g) { return linear_law(g.law).gains_text(g); }

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
                                    const TuneConstraints& c, const std::string& where) {
  ConstraintValues v;
  const DiscreteLoopModel model(plant, gains, where);
  const LoopAnalysis a = analyse_loop(model, 0.01, 1500);
  v.stable = a.stable;
  v.phase_margin_deg = a.phase_margin_deg;
  v.gain_margin_dB = a.gain_margin_dB;
  v.sensitivity_peak = a.sensitivity_peak;
  v.step_overshoot = a.step_overshoot;
  v.command_name = model.law().command_name();
  v.command_unit = model.law().command_unit();
  v.command_limit = c.u_fraction_max * model.law().command_limit(gains);
  if (!a.stable) {
    v.violation = fmt::format("{}: closed loop unstable (largest pole |z| = {:.6f})", where, a.max_pole_magnitude);
  } else if (a.phase_margin_deg < c.phase_margin_min_deg) {
    v.violation = fmt::format("{}: phase margin {:.2f} deg < {:.2f} deg", where, a.phase_margin_deg,
                              c.phase_margin_min_deg);
  } else if (a.gain_margin_dB < c.gain_margin_min_dB) {
    v.violation = fmt::format("{}: gain margin {:.2f} dB < {:.2f} dB", where, a.gain_margin_dB, c.gain_margin_min_dB);
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
  p.program = io::parse_program(scenario);
  p.trajectory = controller::plan_trajectory(p.program, scenario.machine.motion_limits(), scenario.machine.Ts_s);
  p.corners = corner_windows(p.trajectory, p.program);
  for (const auto& c : p.corners)
    if (is_feed_move(p.program, c.corner.block_before) && is_feed_move(p.program, c.corner.block_after))
      p.tuning_corners.push_back(c);
  if (p.tuning_corners.empty()) p.tuning_corners = p.corners;
  p.total_ticks =
      p.trajectory.num_ticks() + static_cast<std::int64_t>(std::ceil(scenario.settle_s / scenario.machine.Ts_s));
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

ScenarioMetrics simulate_window(const io::Scenario& scenario, const PlannedScenario& planned,
                                const sim::MachineDefinition& machine, const SimulationWindow& window,
                                CornerTrace* trace, std::int64_t trace_begin, std::int64_t trace_end) {
  ScenarioMetrics m;
  m.u_peak_block.fill(-1);
  auto reference = std::make_shared<sim::ProgramReference>(planned.trajectory);
  const double Ts = machine.Ts_s;
  const std::int64_t k0 = window.k_begin;
  AxisArray<double> x0 = scenario.start_mm;
  if (k0 > 0) x0 = planned.trajectory.sample(k0).x_mm;
  sim::CoSimulation cosim(machine, reference, scenario.make_process ? scenario.make_process() : nullptr, x0);
  const auto& axes = cosim.axes();
  if (k0 > 0) {
    // Steady motion at tick k0: the drives at the reference speed, the integrator
    // holding what the feedforward does not give of B w + Tc. The FADAL law holds it
    // with no error; the cascade's P position loop lags by the error whose Kv e gives
    // the speed the velocity feedforward does not: e = (rg w + rg ev - kff v) / Kv, the
    // velocity error ev = 0 with an integral, T / Kvp without one.
    sim::CoSimState st = cosim.get_state();
    const auto r0 = planned.trajectory.sample(k0);
    const auto r1 = planned.trajectory.sample(k0 - 1);
    const auto r2 = planned.trajectory.sample(std::max<std::int64_t>(0, k0 - 2));
    for (std::size_t i = 0; i < axes.size(); ++i) {
      const std::size_t a = index(axes[i]);
      const auto& d = machine.axes[a].drive;
      const auto& g = machine.axes[a].loop;
      const double v = (r1.x_mm[a] - r2.x_mm[a]) / Ts;
      const double w = r0.v_mm_per_s[a] / d.rg_mm_per_rad;
      auto& ds = st.drives[i];
      ds.x_mm = r0.x_mm[a];
      ds.w_rad_per_s = w;
      ds.stuck = w == 0.0;
      ds.x_load_mm = ds.x_mm;
      ds.w_load_rad_per_s = w;
      ds.x_table_mm = ds.x_mm;
      ds.load_stuck = ds.stuck;
      auto& ls = st.loops[i];
      ls = controller::PositionLoopState{};
      const double Tc = w > 0.0 ? d.Tc_pos_Nm : (w < 0.0 ? -d.Tc_neg_Nm : 0.0);
      const double T_needed = d.B_kg_m2_per_s * w + Tc;
      if (g.law == controller::LoopLaw::kCascade) {
        const controller::CascadeGains& c = g.cascade;
        const double ev = c.Tn_s > 0.0 ? 0.0 : T_needed / c.Kvp_torque_s_per_rad;
        const double e = (d.rg_mm_per_rad * (w + ev) - c.kff * v) / c.Kv_per_s;
        ds.x_mm -= e;
        ds.x_load_mm = ds.x_table_mm = ds.x_mm;
        ls.Iv_rad = c.Tn_s > 0.0 ? c.Tn_s * T_needed / c.Kvp_torque_s_per_rad : 0.0;
        ls.T_filtered = T_needed;
        ls.x_meas_prev_mm = ds.x_mm - d.rg_mm_per_rad * w * Ts;
        ls.e_prev_mm = e;
      } else {
        const double u_needed = T_needed / (d.Ka_A_per_V * d.Kt_Nm_per_A);
        ls.I_mm_s = g.Ki_V_per_s_mm > 0.0 ? (u_needed - g.K2_V_s_per_mm * v) / g.Ki_V_per_s_mm : 0.0;
        ls.e_prev_mm = 0.0;
      }
      ls.x_ref_prev_mm = r1.x_mm[a];
      ls.v_ref_prev_mm_per_s = v;
      ls.last_k = k0 - 1;
    }
    st.k = k0;
    st.last.k = k0 - 1;
    cosim.set_state(st);
  }
  if (trace) *trace = CornerTrace{};
  AxisArray<double> sum_e2{};
  double sum_c2 = 0.0;
  std::int64_t n_corner = 0;
  std::size_t next = 0;
  try {
    for (std::int64_t k = k0; k < window.k_end; ++k) {
      const sim::Snapshot& s = cosim.step();
      ++m.ticks;
      for (Axis ax : axes) {
        const auto& x = s.axes[index(ax)];
        if (std::abs(x.u_V) > m.u_peak_V[index(ax)]) {
          m.u_peak_V[index(ax)] = std::abs(x.u_V);
          m.u_peak_t_s[index(ax)] = s.t_s;
          m.u_peak_block[index(ax)] = s.block;
        }
        if (x.saturated) ++m.saturated_ticks[index(ax)];
        if (s.reference_done)
          m.max_error_after_stop_mm[index(ax)] = std::max(m.max_error_after_stop_mm[index(ax)], std::abs(x.e_mm));
      }
      m.max_contour_error_run_mm = std::max(m.max_contour_error_run_mm, s.contour_error_mm);
      while (next < window.corners.size() && window.corners[next].k_end <= k) ++next;
      bool in_corner = false;
      for (std::size_t c = next; c < window.corners.size() && window.corners[c].k_begin <= k; ++c)
        if (k < window.corners[c].k_end) in_corner = true;
      if (in_corner) {
        ++n_corner;
        for (Axis ax : axes) {
          const double e = s.axes[index(ax)].e_mm;
          m.max_tracking_error_mm[index(ax)] = std::max(m.max_tracking_error_mm[index(ax)], std::abs(e));
          sum_e2[index(ax)] += e * e;
        }
        m.max_contour_error_mm = std::max(m.max_contour_error_mm, s.contour_error_mm);
        sum_c2 += s.contour_error_mm * s.contour_error_mm;
      }
      if (trace && k >= trace_begin && k < trace_end) {
        trace->t_s.push_back(s.t_s);
        for (Axis ax : axes) trace->e_mm[index(ax)].push_back(s.axes[index(ax)].e_mm);
        trace->contour_mm.push_back(s.contour_error_mm);
      }
    }
    m.completed = true;
  } catch (const ModelError& e) {
    m.failure = e.what();
  }
  const double n = std::max<double>(1.0, static_cast<double>(n_corner));
  for (Axis ax : axes) m.rms_tracking_error_mm[index(ax)] = std::sqrt(sum_e2[index(ax)] / n);
  m.rms_contour_error_mm = std::sqrt(sum_c2 / n);
  return m;
}

namespace {

/// Per-axis search variables, one per gain the law searches: ln(gain / base) for a
/// feedback gain (a gain with base 0 stays 0), gain / model value for a feedforward gain.
struct AxisScales {
  Axis axis{Axis::kX};
  LinearPlant plant;
  controller::PositionLoopParams start;
  const LinearLaw* law{nullptr};
  std::vector<const LawGain*> vars;  ///< feedback gains first
  std::vector<double> base;
  std::size_t feedback_vars{0};

  AxisScales(Axis a, const LinearPlant& p, const controller::PositionLoopParams& g)
      : axis(a), plant(p), start(g), law(&linear_law(g.law)) {
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
  const LinearLaw& law = linear_law(def.loop.law);
  const LinearPlant p = linear_plant(def.drive);
  const double peak = m.u_peak_V[index(a)] * p.Ka_A_per_V * p.Kt_Nm_per_A / law.torque_per_command(p);
  return m.saturated_ticks[index(a)] > 0 ? std::max(peak, law.command_limit(def.loop)) : peak;
}
double command_limit(const sim::MachineDefinition& machine, Axis a, const TuneConstraints& c) {
  const auto& loop = machine.axes[index(a)].loop;
  return c.u_fraction_max * linear_law(loop.law).command_limit(loop);
}
/// "|u| 9.844 V > 9.500 V" or "|torque| 30.200 torque unit > 29.402 torque unit".
std::string command_text(const sim::MachineDefinition& machine, Axis a, double value, double limit) {
  const LinearLaw& law = linear_law(machine.axes[index(a)].loop.law);
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
    const ConstraintValues v = linear_constraints(d->scales->plant, d->scales->gains(full.data()), tight, d->where);
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
      lin += linear_violation(linear_constraints(s.plant, g, c, std::string(axis_name(s.axis))), c);
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
  ar.analysis_before = analyse_loop(DiscreteLoopModel(s.plant, ar.before, name));
  ar.analysis_after = analyse_loop(DiscreteLoopModel(s.plant, ar.after, name));
  ar.constraints_before = linear_constraints(s.plant, ar.before, c, name);
  ar.constraints_after = linear_constraints(s.plant, ar.after, c, name);
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

TuneResult tune_gains(const io::Scenario& scenario, const TuneOptions& options) {
  TuneResult result;
  const sim::MachineDefinition& m0 = scenario.machine;
  result.machine_before = m0;
  result.machine_after = m0;
  if (options.axes.empty()) throw ConfigError("tune: no axis to tune");
  if (!(options.gain_range > 1.0) || !(options.feedforward_range > 0.0) || options.max_evaluations < 1 ||
      !(options.max_window_span_s > 0.0))
    throw ConfigError(fmt::format("tune: gain_range {} must be > 1, feedforward_range {} > 0, max_evaluations {} >= 1, "
                                  "--max-window {} s > 0",
                                  options.gain_range, options.feedforward_range, options.max_evaluations,
                                  options.max_window_span_s));
  const TuneConstraints& c = options.constraints;
  std::vector<AxisScales> requested;
  for (Axis a : options.axes) {
    const auto& def = m0.axes[index(a)];
    if (!def.present)
      throw ConfigError(fmt::format("tune: axis {} is not present in machine {}", axis_name(a), m0.name));
    const LinearPlant plant = linear_plant(def.drive);
    plant.validate(fmt::format("{}: axis {}", m0.source.empty() ? m0.name : m0.source, axis_name(a)));
    requested.emplace_back(a, plant, def.loop);
  }
  const double lr = std::log(options.gain_range);
  // Axes that keep the machine's gains, with the reason (in the order asked).
  std::vector<std::pair<AxisScales, std::string>> kept;

  // Stage A: nearest feedback gains that meet the linear constraints, per axis.
  std::vector<AxisScales> scales;
  std::vector<std::vector<double>> q0;  // per axis
  for (const auto& s : requested) {
    StageA data{&s, &c, std::string(axis_name(s.axis))};
    const unsigned nf = static_cast<unsigned>(s.feedback_vars);
    nlopt::opt opt(nlopt::LN_COBYLA, nf);
    std::vector<double> lo(nf), hi(nf);
    for (std::size_t i = 0; i < nf; ++i) {
      lo[i] = s.lower(i, lr);
      hi[i] = s.upper(i, lr, options.feedforward_range);
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
    const ConstraintValues v = linear_constraints(s.plant, s.gains(full.data()), c, std::string(axis_name(s.axis)));
    if (!v.linear_ok) {
      std::string names;
      for (std::size_t i = 0; i < nf; ++i) names += fmt::format("{}{}", i > 0 ? ", " : "", s.vars[i]->name);
      kept.emplace_back(s, fmt::format("no gains satisfy the constraints on axis {} within the search range ({} in "
                                       "[1/{:g}, {:g}] x start): best found {} ({}); start {}",
                                       axis_name(s.axis), names, options.gain_range, options.gain_range,
                                       gains_text(s.gains(full.data())), v.violation, gains_text(s.start)));
      continue;
    }
    scales.push_back(s);
    q0.push_back(full);
  }

  auto finish_kept = [&](const ScenarioMetrics& fb, const ScenarioMetrics& fa) {
    for (const auto& [s, why] : kept) {
      AxisTuneResult ar = axis_result(s, s.start, m0, fb, fa, c);
      ar.tuned = false;
      ar.note = why;
      result.axes.push_back(ar);
    }
    std::stable_sort(result.axes.begin(), result.axes.end(),
                     [](const AxisTuneResult& x, const AxisTuneResult& y) { return index(x.axis) < index(y.axis); });
  };
  auto kept_text = [&] {
    std::string t;
    for (const auto& [s, why] : kept)
      t += fmt::format("{}axis {} keeps the machine's gains: {}", t.empty() ? "" : "; ", axis_name(s.axis), why);
    return t;
  };
  if (scales.empty()) {
    // No axis can meet the linear constraints: nothing is simulated.
    result.feasible = false;
    result.message = kept_text();
    finish_kept(ScenarioMetrics{}, ScenarioMetrics{});
    return result;
  }

  // The machine's own gains on the full scenario: an axis whose peak |u| is already
  // above the limit there cannot be judged against it (no new gains could pass where the
  // program itself asks for that much, e.g. a rapid plunge): it keeps its gains.
  const PlannedScenario planned = plan_scenario(scenario);
  const SimulationWindow full = full_window(planned);
  result.full_before = simulate_window(scenario, planned, m0, full);
  if (result.full_before.completed) {
    std::vector<AxisScales> reachable;
    std::vector<std::vector<double>> q_reachable;
    for (std::size_t i = 0; i < scales.size(); ++i) {
      const Axis a = scales[i].axis;
      const double limit = command_limit(m0, a, c);
      const double peak = command_peak(result.full_before, m0, a);
      if (peak > limit) {
        kept.emplace_back(
            scales[i],
            fmt::format("its own gains already reach peak {} ({:g} x {}) on this scenario, at "
                        "t = {:.4f} s {} ({} ticks at the limit), so the scenario cannot show that new gains keep the "
                        "limit; axis {} is left as it is (tune it on a scenario without that move, or raise "
                        "--u-fraction)",
                        command_text(m0, a, peak, limit), c.u_fraction_max,
                        linear_law(m0.axes[index(a)].loop.law).command_limit_name(),
                        result.full_before.u_peak_t_s[index(a)],
                        motion_text(planned, result.full_before.u_peak_block[index(a)]),
                        result.full_before.saturated_ticks[index(a)], axis_name(a)));
        continue;
      }
      reachable.push_back(scales[i]);
      q_reachable.push_back(q0[i]);
    }
    scales = std::move(reachable);
    q0 = std::move(q_reachable);
  }
  if (scales.empty()) {
    result.feasible = false;
    result.message = kept_text();
    finish_kept(result.full_before, result.full_before);
    result.full_after = result.full_before;
    return result;
  }

  // Stage B: the coupled simulation through the corners. Its starting point (stage-A
  // feedback, model feedforward) must keep the |u| limit on the window: an axis that breaks
  // it starts with its feedforward scaled down to what keeps it (or, if even no feedforward
  // does, keeps its own gains), so the search starts from reachable gains.
  const SimulationWindow window =
      corner_window(planned, options.window_before_s, options.window_after_s, options.max_window_span_s);
  std::vector<std::string> limited(kNumAxes);  // per axis: what limited the tuning
  {
    sim::MachineDefinition ms = m0;
    for (std::size_t i = 0; i < scales.size(); ++i) ms.axes[index(scales[i].axis)].loop = scales[i].gains(q0[i].data());
    const ScenarioMetrics start = simulate_window(scenario, planned, ms, window);
    std::vector<AxisScales> reachable;
    std::vector<std::vector<double>> q_reachable;
    for (std::size_t i = 0; i < scales.size(); ++i) {
      const AxisScales& s = scales[i];
      const Axis a = s.axis;
      const double limit = command_limit(m0, a, c);
      std::vector<double> q = q0[i];
      const double peak = command_peak(start, ms, a);
      if (start.completed && peak > limit) {
        const bool has_ff = s.feedback_vars < s.size();
        const double alpha = reachable_feedforward(scenario, planned, ms, s, s.gains(q.data()), window, limit);
        const std::string where =
            fmt::format("with {} the peak {} at t = {:.4f} s {}",
                        has_ff ? "the model feedforward" : "the machine's feedforward",
                        command_text(ms, a, peak, limit),
                        start.u_peak_t_s[index(a)], motion_text(planned, start.u_peak_block[index(a)]));
        if (alpha < 0.0) {
          kept.emplace_back(s, where + (has_ff ? ", and above it without feedforward too (feedback at the nearest "
                                                 "gains meeting the margins): no starting point keeps the limit"
                                               : " at the nearest feedback gains meeting the margins: no starting "
                                                 "point keeps the limit"));
          continue;
        }
        for (std::size_t j = s.feedback_vars; j < s.size(); ++j) q[j] *= alpha;
        limited[index(a)] = fmt::format("{}; the search started from {:.3f} x the model feedforward", where, alpha);
        ms.axes[index(a)].loop = s.gains(q.data());
      }
      reachable.push_back(s);
      q_reachable.push_back(q);
    }
    scales = std::move(reachable);
    q0 = std::move(q_reachable);
  }
  if (scales.empty()) {
    result.feasible = false;
    result.message = kept_text();
    finish_kept(result.full_before, result.full_before);
    result.full_after = result.full_before;
    return result;
  }
  StageB data;
  data.scenario = &scenario;
  data.planned = &planned;
  data.window = &window;
  data.options = &options;
  data.scales = scales;
  data.machine = m0;
  std::vector<double> x0;  // all axes' variables, one after the other
  for (std::size_t i = 0; i < scales.size(); ++i) {
    data.offsets.push_back(x0.size());
    x0.insert(x0.end(), q0[i].begin(), q0[i].end());
  }
  result.window_before = simulate_window(scenario, planned, m0, window);
  // An axis that does not move through the corners searched on (its error there is 0)
  // does not enter the objective: the search's moves of its gains mean nothing, and it
  // ends at its stage-A point.
  std::vector<bool> idle;
  {
    sim::MachineDefinition ms = m0;
    for (std::size_t i = 0; i < scales.size(); ++i) ms.axes[index(scales[i].axis)].loop = scales[i].gains(q0[i].data());
    const ScenarioMetrics start = simulate_window(scenario, planned, ms, window);
    for (const auto& s : scales)
      idle.push_back(start.completed && start.max_tracking_error_mm[index(s.axis)] == 0.0 &&
                     start.rms_tracking_error_mm[index(s.axis)] == 0.0);
    const ScenarioMetrics& ref = result.window_before.completed ? result.window_before : start;
    data.norm_contour = std::max(ref.max_contour_error_mm, 1e-6);
    double rms = 0.0, mx = 0.0;
    for (const auto& s : scales) {
      rms += ref.rms_tracking_error_mm[index(s.axis)];
      mx += ref.max_tracking_error_mm[index(s.axis)];
    }
    data.norm_rms = std::max(rms, 1e-6);
    data.norm_max = std::max(mx, 1e-6);
    result.objective_before = result.window_before.completed ? objective_of(result.window_before, scales, data) : 0.0;
  }
  const unsigned n = static_cast<unsigned>(x0.size());
  std::vector<double> lb(n), ub(n), step(n);
  for (std::size_t i = 0; i < scales.size(); ++i) {
    for (std::size_t j = 0; j < scales[i].size(); ++j) {
      lb[data.offsets[i] + j] = scales[i].lower(j, lr);
      ub[data.offsets[i] + j] = scales[i].upper(j, lr, options.feedforward_range);
      step[data.offsets[i] + j] = scales[i].vars[j]->feedforward ? 0.1 : 0.15;
    }
  }
  {
    nlopt::opt opt(nlopt::LN_BOBYQA, n);
    opt.set_lower_bounds(lb);
    opt.set_upper_bounds(ub);
    opt.set_min_objective(stage_b_objective, &data);
    opt.set_maxeval(options.max_evaluations);
    opt.set_initial_step(step);
    opt.set_xtol_abs(1e-3);
    std::vector<double> x = x0;
    double fval = 0.0;
    try {
      opt.optimize(x, fval);
    } catch (const std::exception&) {
      // A stop by round-off or by the evaluation budget keeps the best feasible point below.
    }
  }
  result.evaluations = data.evaluations;
  if (data.best_q.empty()) {
    result.feasible = false;
    result.message = "no evaluated gains met every constraint in the simulation (|u| below the limit, no runaway)";
    if (!kept.empty()) result.message += "; " + kept_text();
    result.window_after = result.window_before;
    result.full_after = result.full_before;
    for (const auto& s : scales) {
      AxisTuneResult ar = axis_result(s, s.start, m0, result.full_before, result.full_after, c);
      ar.tuned = false;
      ar.note = result.message;
      result.axes.push_back(ar);
    }
    finish_kept(result.full_before, result.full_after);
    return result;
  }
  for (std::size_t i = 0; i < scales.size(); ++i)
    if (idle[i])
      std::copy(q0[i].begin(), q0[i].end(), data.best_q.begin() + static_cast<std::ptrdiff_t>(data.offsets[i]));
  result.window_after = data.best_metrics;
  result.objective_after = data.best_objective;
  for (std::size_t i = 0; i < scales.size(); ++i)
    result.machine_after.axes[index(scales[i].axis)].loop = scales[i].gains(&data.best_q[data.offsets[i]]);

  // Judge on the full scenario. An axis whose tuned gains break a constraint there
  // (the search saw only the corner window) goes back to its own gains, and the
  // scenario is run again with the remaining tuned axes.
  result.full_after = simulate_window(scenario, planned, result.machine_after, full);
  std::vector<AxisScales> tuned;
  for (const auto& s : scales) {
    const AxisTuneResult ar =
        axis_result(s, result.machine_after.axes[index(s.axis)].loop, m0, result.full_before, result.full_after, c);
    if (ar.constraints_after.violation.empty() || !result.full_after.completed) {
      tuned.push_back(s);
      continue;
    }
    if (ar.constraints_after.linear_ok) {
      // Only the command limit is broken: scale this axis's feedforward down to what keeps it.
      const double limit = ar.constraints_after.command_limit;
      const double alpha = reachable_feedforward(scenario, planned, result.machine_after, s,
                                                 result.machine_after.axes[index(s.axis)].loop, full, limit);
      if (alpha >= 0.0) {
        auto& g = result.machine_after.axes[index(s.axis)].loop;
        g = s.scaled_feedforward(g, alpha);
        limited[index(s.axis)] +=
            fmt::format("{}on the full scenario the gains tuned on the corner window reach peak {} "
                        "at t = {:.4f} s {}: the feedforward was scaled by {:.3f} to keep the limit",
                        limited[index(s.axis)].empty() ? "" : "; ",
                        command_text(m0, s.axis, ar.constraints_after.command_peak, limit),
                        result.full_after.u_peak_t_s[index(s.axis)],
                        motion_text(planned, result.full_after.u_peak_block[index(s.axis)]), alpha);
        tuned.push_back(s);
        continue;
      }
    }
    kept.emplace_back(s, fmt::format("the gains tuned on the corner window break a constraint on the full scenario "
                                     "({}; peak |u| at t = {:.4f} s {}{}) where its own gains keep it, so axis {} "
                                     "keeps its own gains",
                                     ar.constraints_after.violation, result.full_after.u_peak_t_s[index(s.axis)],
                                     motion_text(planned, result.full_after.u_peak_block[index(s.axis)]),
                                     ar.constraints_after.linear_ok && s.feedback_vars < s.size()
                                         ? ", also with no feedforward"
                                         : "",
                                     axis_name(s.axis)));
    result.machine_after.axes[index(s.axis)].loop = s.start;
  }
  bool changed = tuned.size() != scales.size();
  for (const auto& l : limited) changed = changed || l.find("on the full scenario") != std::string::npos;
  if (changed) result.full_after = simulate_window(scenario, planned, result.machine_after, full);
  result.feasible = !tuned.empty();
  std::size_t changed_axes = 0;
  for (const auto& s : tuned) {
    AxisTuneResult ar =
        axis_result(s, result.machine_after.axes[index(s.axis)].loop, m0, result.full_before, result.full_after, c);
    ar.note = limited[index(s.axis)];
    bool same = true;
    for (const LawGain& lg : s.law->gains()) same = same && lg.get(ar.before) == lg.get(ar.after);
    if (same) {
      // The search's best point left this axis where it started (its start met every
      // constraint and nothing it tried on this axis lowered the objective).
      ar.tuned = false;
      ar.note = result.window_before.max_tracking_error_mm[index(s.axis)] == 0.0
                    ? fmt::format("axis {} does not move through the corners searched on (its tracking error there "
                                  "is 0), so the search cannot judge its gains; the machine's meet every constraint "
                                  "and are kept",
                                  axis_name(s.axis))
                    : std::string("the machine's gains meet every constraint and no change of them lowered the "
                                  "objective; they are kept");
    } else {
      ++changed_axes;
    }
    if (!ar.constraints_after.violation.empty() && result.feasible) {
      result.feasible = false;
      result.message = fmt::format("tuned gains break a constraint on the full scenario: {}",
                                   ar.constraints_after.violation);
    }
    result.axes.push_back(ar);
  }
  finish_kept(result.full_before, result.full_after);
  if (result.feasible) {
    result.message = fmt::format(
        "tuned {} axis(es) in {} simulations: max contour error through the corners {:.3f} um -> {:.3f} um",
        changed_axes, result.evaluations, 1e3 * result.full_before.max_contour_error_mm,
        1e3 * result.full_after.max_contour_error_mm);
    if (!kept.empty()) result.message += "; " + kept_text();
  } else if (result.message.empty()) {
    result.message = kept_text();
  }
  return result;
}

namespace {

/// The law's gains under their report names (`feedforward_only`: only its feedforward gains).
nlohmann::json gains_json(const controller::PositionLoopParams& g, bool feedforward_only = false) {
  nlohmann::json j = nlohmann::json::object();
  for (const LawGain& lg : linear_law(g.law).gains())
    if (lg.feedforward || !feedforward_only) j[std::string(lg.json_key)] = lg.get(g);
  return j;
}

double finite_or(double v, double alt) { return std::isfinite(v) ? v : alt; }

nlohmann::json analysis_json(const LoopAnalysis& a) {
  nlohmann::json poles = nlohmann::json::array();
  for (const auto& p : a.poles) poles.push_back({p.real(), p.imag()});
  // JSON has no infinity: a margin that does not exist is written as null.
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"stable", a.stable},
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
    for (const LawGain& lg : linear_law(a.before.law).gains())
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

std::vector<std::filesystem::path> plot_tune(io::ResultSet& results, const io::Scenario& scenario,
                                             const TuneResult& r) {
  std::vector<std::string> outputs;
  // Bode data: one block per axis and gain set.
  const std::string bode_dat = "bode.dat";
  {
    std::string text = "# f_Hz |L|_dB argL_deg |S|_dB |T|_dB |E/R|_dB\n";
    for (const auto& a : r.axes) {
      for (const auto* g : {&a.before, &a.after}) {
        const DiscreteLoopModel m(linear_plant(r.machine_before.axes[index(a.axis)].drive), *g);
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
    io::write_file_atomic(results.path(bode_dat), text);
  }
  std::string script = "set terminal pngcairo size 1200,900 noenhanced\n";
  const std::string bode_png = "bode.png";
  script += fmt::format("set output {}\n", gnuplot_output(bode_png));
  script += "set multiplot layout 2,1\nset logscale x\nset grid\nset xlabel 'f [Hz]'\nset ylabel 'dB'\n";
  script += fmt::format("set title {}\n",
                        gnuplot_text(fmt::format("Open loop L (broken at the command), {}: before and after tuning",
                                                 scenario.machine.name)));
  std::string mag = "plot ", ph = "plot ";
  int idx = 0;
  for (const auto& a : r.axes) {
    for (const char* when : {"before", "after"}) {
      const std::string label = fmt::format("{} {}", axis_name(a.axis), when);
      if (idx > 0) {
        mag += ", ";
        ph += ", ";
      }
      mag += fmt::format("{} index {} using 1:2 with lines title {}, '' index {} using 1:4 with lines dt 2 "
                         "title {}",
                         gnuplot_file(bode_dat), idx, gnuplot_text("|L| " + label), idx, gnuplot_text("|S| " + label));
      ph += fmt::format("{} index {} using 1:3 with lines title {}", gnuplot_file(bode_dat), idx,
                        gnuplot_text("arg L " + label));
      ++idx;
    }
  }
  script += mag + "\nset ylabel 'deg'\nset title 'Phase of L'\n" + ph + "\nunset multiplot\n";
  outputs.push_back(bode_png);

  // Tracking error through the first tuning corner, before and after.
  const PlannedScenario planned = plan_scenario(scenario);
  if (!planned.tuning_corners.empty()) {
    const auto& cw = planned.tuning_corners.front();
    const double Ts = planned.trajectory.Ts_s();
    const std::int64_t pad = static_cast<std::int64_t>(std::llround(0.02 / Ts));
    const std::int64_t t0 = std::max<std::int64_t>(0, cw.k_begin - pad), t1 = cw.k_end + pad;
    SimulationWindow w{std::max<std::int64_t>(0, t0 - static_cast<std::int64_t>(std::llround(0.1 / Ts))), std::min(planned.total_ticks, t1),
                       {cw}};
    CornerTrace before, after;
    simulate_window(scenario, planned, r.machine_before, w, &before, t0, t1);
    simulate_window(scenario, planned, r.machine_after, w, &after, t0, t1);
    const std::string dat = "corner_error.dat";
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
    io::write_file_atomic(results.path(dat), text);
    const std::string png = "corner_error.png";
    script += fmt::format("set output {}\nset multiplot layout 2,1\nunset logscale x\nset xlabel 't [s]'\n",
                          gnuplot_output(png));
    script += fmt::format("set ylabel 'um'\nset title {}\nplot ",
                          gnuplot_text(planned.corners.empty()
                                           ? std::string("Tracking error over the whole scenario (it has no corner)")
                                           : fmt::format("Tracking error through the corner at line {}", cw.line_after)));
    int col = 2;
    bool first = true;
    for (const auto& a : r.axes) {
      if (!first) script += ", ";
      first = false;
      script += fmt::format("{} using 1:{} with lines title '{} before', '' using 1:{} with lines title '{} after'",
                            gnuplot_file(dat), col, axis_name(a.axis), col + 1, axis_name(a.axis));
      col += 2;
    }
    script += fmt::format("\nset title 'Contour error'\nplot {} using 1:{} with lines title 'before', '' using 1:{} "
                          "with lines title 'after'\nunset multiplot\n",
                          gnuplot_file(dat), col, col + 1);
    outputs.push_back(png);
  }
  script += "unset output\n";
  std::vector<std::filesystem::path> written;
  for (const auto& o : outputs) written.push_back(results.path(o));
  run_gnuplot(results.staging_dir(), script, outputs);
  return written;
}

}  // namespace twin::analysis
