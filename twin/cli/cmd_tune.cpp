#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/tune/linear_analysis.hpp"
#include "twin/tune/tune.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"
#include "twin/io/scenario_file.hpp"

namespace twin::cli {

namespace {

std::vector<Axis> parse_axes(const std::string& text, const sim::MachineDefinition& machine) {
  if (text == "all") return machine.present_axes();
  std::vector<Axis> axes;
  std::size_t pos = 0;
  while (pos <= text.size()) {
    const std::size_t comma = text.find(',', pos);
    const std::string item = text.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    const auto a = parse_axis(item);
    if (!a) throw ConfigError(fmt::format("--axis '{}': '{}' is not x, y, z or all", text, item));
    if (!machine.axes[index(*a)].present)
      throw ConfigError(fmt::format("--axis {}: machine {} has no axis {}", text, machine.name, item));
    axes.push_back(*a);
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return axes;
}

void print_line(const std::string& s) { std::printf("%s\n", s.c_str()); }

/// The files a loaded scenario was read from: the scenario, its program and
/// its machine (`machine_file`: the machine's source before any --set).
void add_inputs(std::vector<std::filesystem::path>& inputs, const io::Scenario& s, const std::string& machine_file) {
  inputs.push_back(s.path);
  inputs.push_back(s.program_path);
  inputs.emplace_back(machine_file);
}

struct TuneCliOptions {
  std::string scenario;
  std::string out;
  std::string machine;
  std::string axes{"x,y"};
  std::string check{"contour_square"};
  std::vector<std::string> sets;
  bool analyse{false};
  bool no_plots{false};
  analysis::TuneOptions tune;
};

void add_tune_options(CLI::App* cmd, TuneCliOptions& opt) {
  cmd->add_option("scenario", opt.scenario, "scenario.yaml, its folder, or a shipped scenario name");
  cmd->add_option("-o,--out", opt.out, "output folder (created if missing); required unless --analyse");
  cmd->add_option("--axis", opt.axes, "axes to tune: x, y, z, all, or a list like x,y (default x,y)");
  cmd->add_flag("--analyse,--analyze", opt.analyse,
                "print poles, margins, sensitivity peak, bandwidth and step figures for the current gains and stop");
  cmd->add_option("--machine", opt.machine, "machine definition (name or YAML file) replacing the scenario's");
  cmd->add_option("--set", opt.sets, "override a parameter: <axis>.<name>=<value>, e.g. x.Kp=600 (x.Kv=80 on a cascade)")->take_all();
  cmd->add_option("--check", opt.check,
                  "second scenario, not used for tuning, on which before/after are reported ('none' to skip)");
  cmd->add_option("--max-evals", opt.tune.max_evaluations, "coupled simulations in the search (default 160)");
  cmd->add_option("--max-window", opt.tune.max_window_span_s,
                  "corners searched on: the first and those ending within this many seconds of it (default 2); all "
                  "are judged on the full scenario");
  cmd->add_option("--pm", opt.tune.constraints.phase_margin_min_deg, "minimum phase margin, deg (default 40)");
  cmd->add_option("--gm", opt.tune.constraints.gain_margin_min_dB, "minimum gain margin, dB (default 6)");
  cmd->add_option("--ms", opt.tune.constraints.sensitivity_peak_max, "maximum sensitivity peak |S| (default 2)");
  cmd->add_option("--overshoot", opt.tune.constraints.step_overshoot_max,
                  "maximum feedback step overshoot, fraction (default 0.35)");
  cmd->add_option("--u-fraction", opt.tune.constraints.u_fraction_max,
                  "peak command allowed in the scenario as a fraction of its limit: |u| of u_max (FADAL law), "
                  "|torque| of T_max (cascade) (default 0.95)");
  cmd->add_flag("--no-plots", opt.no_plots, "do not draw the PNG plots");
}

/// --analyse: poles, margins and the rest for the current gains of each axis.
void print_analysis(const io::Scenario& scenario, const std::vector<Axis>& axes) {
  for (Axis a : axes) {
    const auto& def = scenario.machine.axes[index(a)];
    const analysis::LinearPlant plant = analysis::linear_plant(def.drive);
    const analysis::DiscreteLoopModel model(plant, def.loop, scenario.machine.Ts_s,
                                            fmt::format("axis {}", axis_name(a)));
    std::printf("%s", analysis::format_analysis(fmt::format("axis {} of {} (Ts {:g} s):", axis_name(a),
                                                            scenario.machine.name, scenario.machine.Ts_s),
                                                model, analysis::analyse_loop(model))
                          .c_str());
    std::string ff;
    for (const analysis::LawGain& g : model.law().gains())
      if (g.feedforward) ff += fmt::format("{}{} = {:.6g} {}", ff.empty() ? "" : ", ", g.name, g.model(plant), g.unit);
    print_line("  model feedforward (cancels the linear plant): " + ff);
  }
}

using MetricsPair = std::pair<analysis::ScenarioMetrics, analysis::ScenarioMetrics>;

/// The check scenario over its whole run with the gains before and after tuning.
MetricsPair check_before_after(const io::Scenario& cs, const analysis::TuneResult& result) {
  const analysis::PlannedScenario planned = analysis::plan_scenario(cs);
  sim::MachineDefinition before = cs.machine, after = cs.machine;
  for (const auto& a : result.axes) {
    before.axes[index(a.axis)].loop = a.before;
    after.axes[index(a.axis)].loop = a.after;
  }
  const auto w = analysis::full_window(planned);
  return std::make_pair(analysis::simulate_window(cs, planned, before, w),
                        analysis::simulate_window(cs, planned, after, w));
}

/// "axis x: Kp 1 -> 2, ...; PM ..." for a tuned axis, "axis x: gains kept (...)" for another.
void print_axis_result(const analysis::AxisTuneResult& a) {
  const controller::Law& law = controller::law_of(a.before.law);
  std::string gains;
  for (const analysis::LawGain& g : law.gains()) {
    gains += gains.empty() ? "" : ", ";
    gains += a.tuned ? fmt::format("{} {:.4g} -> {:.4g}", g.name, g.get(a.before), g.get(a.after))
                     : fmt::format("{} {:.4g}", g.name, g.get(a.before));
  }
  if (!a.tuned) {
    print_line(fmt::format("axis {}: gains kept ({}): {}", axis_name(a.axis), gains, a.note));
    return;
  }
  print_line(fmt::format("axis {}: {}; PM {:.1f} -> {:.1f} deg, GM {:.1f} -> {:.1f} dB, Ms {:.2f} "
                         "-> {:.2f}, bandwidth {:.1f} -> {:.1f} Hz",
                         axis_name(a.axis), gains, a.analysis_before.phase_margin_deg,
                         a.analysis_after.phase_margin_deg, a.analysis_before.gain_margin_dB,
                         a.analysis_after.gain_margin_dB, a.analysis_before.sensitivity_peak,
                         a.analysis_after.sensitivity_peak, a.analysis_before.bandwidth_Hz,
                         a.analysis_after.bandwidth_Hz));
  if (!a.note.empty()) print_line(fmt::format("axis {}: {}", axis_name(a.axis), a.note));
}

/// report.json, machine.yaml when the tuning succeeded, and the plots; returns the
/// files written.
std::vector<std::filesystem::path> write_tune_results(io::ResultSet& results, const TuneCliOptions& opt,
                                                      const io::Scenario& scenario, const analysis::TuneResult& result,
                                                      const std::optional<io::Scenario>& check,
                                                      const std::optional<MetricsPair>& check_metrics) {
  const nlohmann::json report = analysis::tune_report(scenario, opt.tune, result, check, check_metrics);
  io::write_file_atomic(results.path("report.json"), report.dump(2) + "\n");
  if (result.feasible) {
    const std::string header =
        fmt::format("{} with position-loop gains tuned by `twin tune` on scenario {} (axes {}); see report.json",
                    scenario.machine.name, scenario.name, opt.axes);
    io::write_file_atomic(results.path("machine.yaml"), io::machine_to_yaml(result.machine_after, header));
  }
  if (!opt.no_plots && !result.axes.empty()) {
    try {
      static_cast<void>(analysis::plot_tune(results, scenario, result));
    } catch (const Error&) {
      results.commit();  // the report and the machine stand without the plots
      throw;
    }
  }
  return results.commit();
}

void run_tune(TuneCliOptions& opt) {
  const auto path = opt.scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt.scenario);
  io::Scenario scenario = io::load_scenario(path, opt.machine);
  const std::string machine_file = scenario.machine.source;
  apply_sets(scenario.machine, opt.sets);
  const std::vector<Axis> axes = parse_axes(opt.axes, scenario.machine);
  if (opt.analyse) return print_analysis(scenario, axes);
  if (opt.out.empty()) throw ConfigError("tune: -o OUT is required (or use --analyse)");
  opt.tune.axes = axes;
  const std::filesystem::path out(opt.out);
  std::optional<io::Scenario> check_scenario;
  std::vector<std::filesystem::path> inputs;
  add_inputs(inputs, scenario, machine_file);
  if (opt.check != "none" && !opt.check.empty()) {
    check_scenario = io::load_scenario(io::resolve_scenario_path(opt.check), opt.machine);
    add_inputs(inputs, *check_scenario, check_scenario->machine.source);
    apply_sets(check_scenario->machine, opt.sets);
  }
  // Before anything is written: OUT/machine.yaml given as --machine (or a
  // scenario in OUT) would be replaced by the results.
  refuse_output_holding_inputs("tune", out, inputs);
  io::ResultSet results(out, "tune");  // the files appear in OUT together, manifest.json last
  print_line(fmt::format("tuning axes {} on {} ({} simulations at most) ...", opt.axes, scenario.name,
                         opt.tune.max_evaluations));
  const analysis::TuneResult result = analysis::tune_gains(scenario, opt.tune);
  std::optional<io::Scenario> check;
  std::optional<MetricsPair> check_metrics;
  if (check_scenario && !result.axes.empty()) {
    check_metrics = check_before_after(*check_scenario, result);
    check = std::move(check_scenario);
  }
  const std::vector<std::filesystem::path> written =
      write_tune_results(results, opt, scenario, result, check, check_metrics);
  for (const auto& a : result.axes) print_axis_result(a);
  if (check_metrics)
    print_line(fmt::format("check scenario {}: max contour error through the corners {:.3f} um -> {:.3f} um",
                           check->name, 1e3 * check_metrics->first.max_contour_error_mm,
                           1e3 * check_metrics->second.max_contour_error_mm));
  std::string files;
  for (const auto& p : written) files += (files.empty() ? "" : ", ") + p.string();
  print_line("wrote " + files);
  if (!result.feasible) throw ModelError(fmt::format("tune: {}", result.message));
  print_line(result.message);
}

}  // namespace

void register_tune(CLI::App& app) {
  auto opt = std::make_shared<TuneCliOptions>();
  CLI::App* cmd = app.add_subcommand(
      "tune", "Linear analysis of the position loops and tuning of their gains (FADAL law: Kp, Ki, Kd, K1, K2; "
              "cascade: Kv, Kvp, Tn) on a scenario's corners (default: the FADAL 2216 pocket corner); writes "
              "OUT/machine.yaml, OUT/report.json and plots");
  add_tune_options(cmd, *opt);
  cmd->callback([opt]() { run_tune(*opt); });
}

}  // namespace twin::cli
