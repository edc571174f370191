#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/calibrate/calibrate.hpp"
#include "twin/calibrate/effect_registry.hpp"
#include "twin/force_calibrate/force_calibrate.hpp"
#include "twin/calibrate/machine_from_data.hpp"
#include "twin/report/plots.hpp"
#include "twin/calibrate/signal.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/io/machine_file.hpp"

namespace twin::cli {
namespace {

// The run's axes whose measured position is logged: the ones with residuals to plot.
std::vector<Axis> measured_axes(const analysis::MeasuredRun& run) {
  std::vector<Axis> axes;
  for (Axis a : run.axes)
    if (run.trace.find(std::string(axis_name(a)) + "_mm")) axes.push_back(a);
  return axes;
}

// residuals.csv: measured minus model, before and after, every few rows.
void write_residuals(const std::filesystem::path& path, const analysis::MeasuredRun& run,
                     const analysis::CalibrationResult& r, const std::vector<Axis>& axes) {
  std::vector<std::string> names{"t_s"};
  const double fs = 1.0 / run.sample_period_s;
  const double fc = std::min(200.0, 0.4 * fs);
  struct Cols {
    std::vector<double> eb, ea, ub, ua, x;
  };
  AxisArray<Cols> cols;
  for (Axis a : axes) {
    const std::string n(axis_name(a));
    names.insert(names.end(), {n + "_mm", n + "_err_res_before_mm", n + "_err_res_after_mm", n + "_u_res_before",
                               n + "_u_res_after"});
    const auto& x = run.trace.at(n + "_mm");
    const auto* u = run.trace.find(n + "_u_V");
    const auto* i = run.trace.find(n + "_i_A");
    const std::size_t rows = std::min(x.size(), r.replay_before.x_mm[index(a)].size());
    auto& c = cols[index(a)];
    c.x.assign(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(rows));
    c.eb.resize(rows);
    c.ea.resize(rows);
    for (std::size_t k = 0; k < rows; ++k) {
      c.eb[k] = r.replay_before.x_mm[index(a)][k] - x[k];
      c.ea[k] = r.replay_after.x_mm[index(a)][k] - x[k];
    }
    c.ub.assign(rows, 0.0);
    c.ua.assign(rows, 0.0);
    const std::vector<double>* m = u ? u : i;
    if (m) {
      const auto& mb = u ? r.replay_before.u_V[index(a)] : r.replay_before.i_A[index(a)];
      const auto& ma = u ? r.replay_after.u_V[index(a)] : r.replay_after.i_A[index(a)];
      const auto lm = analysis::lowpass(std::span<const double>(m->data(), rows), fc, fs);
      const auto lb = analysis::lowpass(std::span<const double>(mb.data(), rows), fc, fs);
      const auto la = analysis::lowpass(std::span<const double>(ma.data(), rows), fc, fs);
      for (std::size_t k = 0; k < rows; ++k) {
        c.ub[k] = lm[k] - lb[k];
        c.ua[k] = lm[k] - la[k];
      }
    }
  }
  io::TraceWriter w(path, names);
  const auto& t = run.trace.at("t_s");
  const std::size_t rows = r.replay_before.t_s.size();
  const std::size_t step = std::max<std::size_t>(1, rows / 20000);
  std::vector<double> row;
  for (std::size_t k = 0; k < rows; k += step) {
    row.clear();
    row.push_back(t[k]);
    for (Axis a : axes) {
      const auto& c = cols[index(a)];
      row.insert(row.end(), {c.x[k], c.eb[k], c.ea[k], c.ub[k], c.ua[k]});
    }
    w.write_row(row);
  }
  w.commit();
}

// The figures are drawn by analysis::plot_calibration from residuals.csv.
std::vector<std::filesystem::path> make_plots(io::ResultSet& results, const analysis::MeasuredRun& run,
                                              const analysis::CalibrationResult& r) {
  const std::vector<Axis> axes = measured_axes(run);
  if (axes.empty()) throw ConfigError("no axis logs its measured position <a>_mm: no residual to plot");
  write_residuals(results.path("residuals.csv"), run, r, axes);
  std::optional<analysis::CalibrationEvidence> evidence;
  if (!r.added.empty()) {
    const auto& c = r.added.front().candidate;
    const auto it = std::find(axes.begin(), axes.end(), c.axis);
    if (it != axes.end())
      evidence = analysis::CalibrationEvidence{
          c.effect, c.axis, static_cast<std::size_t>(it - axes.begin()),
          analysis::registry_entry(c.kind).plot == analysis::PlotAlong::kPosition};
  }
  return analysis::plot_calibration(results, "residuals.csv", axes, evidence);
}


// Measured against model per axis (torque channel and following error), the
// fitted and held-out parts marked; and the evidence of the friction model:
// the channel against the commanded speed, measured and model.
std::vector<std::filesystem::path> make_data_plots(io::ResultSet& results, const analysis::MeasuredRun& run,
                                                   const analysis::DataCalibration& r) {
  const auto& rr = r.replay_after;
  std::vector<analysis::AxisFromData> axes;
  for (const auto& ax : r.axis)
    if (ax.identified && !rr.x_mm[index(ax.axis)].empty()) axes.push_back(ax);
  if (axes.empty()) throw ConfigError("no axis was identified: nothing to plot");
  std::vector<std::string> names{"t_s"};
  for (const auto& ax : axes) {
    const std::string n(axis_name(ax.axis));
    names.insert(names.end(), {n + "_T_meas", n + "_T_model", n + "_e_meas_mm", n + "_e_model_mm", n + "_v_cmd"});
  }
  {
    io::TraceWriter w(results.path("overlay.csv"), names);
    const auto& t = run.trace.at("t_s");
    std::vector<double> row;
    for (std::size_t k = 0; k < t.size(); ++k) {
      row.assign(1, t[k]);
      for (const auto& ax : axes) {
        const std::size_t i = index(ax.axis);
        const std::string n(axis_name(ax.axis));
        const auto& ref = run.trace.at(n + "_ref_mm");
        const auto* x = run.trace.find(n + "_mm");
        const auto& meas = run.trace.at(ax.channel.column);
        const auto& model = ax.channel.unit == "A" ? rr.i_A[i] : (ax.channel.unit == "V" ? rr.u_V[i] : rr.Tm[i]);
        const double v = k > 0 ? (ref[k] - ref[k - 1]) / run.sample_period_s : 0.0;
        row.insert(row.end(), {meas[k], model[k], x ? ref[k] - (*x)[k] : 0.0, ref[k] - rr.x_mm[i][k], v});
      }
      w.write_row(row);
    }
    w.commit();
  }
  const auto& t = run.trace.at("t_s");
  analysis::DataCalibrationPlots plots;
  plots.t_split_s = t[static_cast<std::size_t>(r.fit_fraction * static_cast<double>(t.size()))];
  for (const auto& ax : axes)
    plots.axes.push_back({std::string(axis_name(ax.axis)), ax.channel.column,
                          ax.channel.unit == "raw" ? "log's unit" : ax.channel.unit});
  return analysis::plot_data_calibration(results, plots);
}

struct CalibrateCommand {
  std::vector<std::string> runs;
  std::vector<std::string> validate;
  std::string out;
  std::string machine;
  std::vector<std::string> sets;
  bool no_plots{false};
};

// A machine the twin does not know: calibrated from the data alone.
void calibrate_unknown_machine(const CalibrateCommand& opt, const std::vector<analysis::MeasuredRun>& fit_runs,
                               const std::vector<analysis::MeasuredRun>& validate_runs) {
  std::vector<std::string> nominal_notes;
  sim::MachineDefinition nominal = analysis::machine_for_run(fit_runs.front(), "", &nominal_notes);
  analysis::DataCalibration r = analysis::calibrate_from_data(fit_runs, validate_runs, nominal);
  r.notes.insert(r.notes.begin(),
                 "the runs name no machine the twin ships: the machine is identified from the data alone (cascade "
                 "law, drives in the log's torque unit); the nominal machine the errors are compared with is the "
                 "shipped " + std::string(io::kDefaultMachineName) + " standing in");
  const std::filesystem::path out(opt.out);
  io::ResultSet results(out, "calibrate");  // the files appear in OUT together, manifest.json last
  analysis::write_data_trace(results.path("trace_before.csv"), fit_runs.front(), r.replay_before);
  analysis::write_data_trace(results.path("trace.csv"), fit_runs.front(), r.replay_after);
  std::string runs_text;
  for (const auto& s : opt.runs) runs_text += (runs_text.empty() ? "" : " ") + s;
  io::write_file_atomic(results.path("machine.yaml"),
                        io::machine_to_yaml(r.final_machine, fmt::format("identified by twin calibrate from {}: "
                                                                         "cascade loop and drives in the log's "
                                                                         "torque unit (Kt = Ka = 1, rg = 1 mm/rad)",
                                                                         runs_text)));
  if (!opt.no_plots) {
    try {
      make_data_plots(results, fit_runs.front(), r);
    } catch (const Error& e) {
      r.notes.push_back(fmt::format("plots not drawn: {}", e.what()));
    }
  }
  io::write_file_atomic(results.path("report.json"), analysis::data_calibration_report_json(r).dump(2) + "\n");
  io::write_file_atomic(results.path("report.md"), analysis::data_calibration_report_markdown(r, runs_text));
  results.commit();
  for (const auto& n : r.notes) std::fprintf(stderr, "twin calibrate: note: %s\n", n.c_str());
  std::printf("calibrated %s from the data (%zu runs, %d replays); wrote %s\n", runs_text.c_str(), fit_runs.size(),
              r.replays, out.c_str());
}

// The errors of `m` on the whole of run `v` (report.json's validation_runs entries).
nlohmann::json validation_errors(const analysis::MeasuredRun& v, const sim::MachineDefinition& m) {
  nlohmann::json e = nlohmann::json::object();
  try {
    const analysis::ReplayResult rr = analysis::replay_run(v, m);
    for (Axis a : v.axes) {
      if (!m.axes[index(a)].present) continue;
      const analysis::AxisErrors ae = analysis::axis_errors(v, rr, a, 0);
      const std::string n(axis_name(a));
      e[n + "_err_mm"] = ae.err_not_computed.empty() ? nlohmann::json(ae.err_mm) : nlohmann::json(nullptr);
      if (ae.has_u || ae.has_current)
        e[n + (ae.has_u ? "_u_V" : "_i_A")] =
            ae.u_not_computed.empty() ? nlohmann::json(ae.u) : nlohmann::json(nullptr);
    }
  } catch (const Error& err) {
    e["not_computed"] = fmt::format("the replay failed: {}", err.what());
  }
  return e;
}

// Runs of another program on the same machine, never fitted: their errors
// with the machine the run names (nominal) and with the calibrated one.
nlohmann::json validation_runs_json(const std::vector<analysis::MeasuredRun>& validate_runs,
                                    const std::string& machine_name, const sim::MachineDefinition& calibrated) {
  nlohmann::json list = nlohmann::json::array();
  for (const auto& v : validate_runs) {
    std::vector<std::string> vnotes;
    const sim::MachineDefinition nominal = analysis::machine_for_run(v, machine_name, &vnotes);
    nlohmann::json entry;
    entry["run"] = v.dir.string();
    entry["error_nominal"] = validation_errors(v, nominal);
    entry["error_calibrated"] = validation_errors(v, calibrated);
    list.push_back(entry);
  }
  return list;
}

// A machine the twin ships: its drives calibrated on the first run, the
// others reported as validation runs.
void calibrate_known_machine(const CalibrateCommand& opt, const std::vector<analysis::MeasuredRun>& fit_runs,
                             std::vector<analysis::MeasuredRun> validate_runs) {
  const analysis::MeasuredRun& run = fit_runs.front();
  std::vector<std::string> notes;
  sim::MachineDefinition machine = analysis::machine_for_run(run, opt.machine, &notes);
  for (std::size_t i = 1; i < fit_runs.size(); ++i) {
    notes.push_back(fmt::format("{}: the drive calibration of a known machine fits one run; this one is reported as "
                                "a validation run",
                                fit_runs[i].dir.string()));
    validate_runs.push_back(fit_runs[i]);
  }
  apply_sets(machine, opt.sets);
  analysis::CalibrationResult r = analysis::calibrate(run, machine);
  r.notes.insert(r.notes.begin(), notes.begin(), notes.end());
  const std::filesystem::path out(opt.out);
  io::ResultSet results(out, "calibrate");  // the files appear in OUT together, manifest.json last
  analysis::write_replay_trace(results.path("trace_before.csv"), r.replay_before);
  analysis::write_replay_trace(results.path("trace.csv"), r.replay_after);
  io::write_file_atomic(results.path("machine.yaml"),
                        io::machine_to_yaml(r.final_machine, fmt::format("calibrated by twin calibrate from {}: "
                                                                         "identified J, B, Tc and added effects",
                                                                         opt.runs.front())));
  nlohmann::json report = analysis::calibration_report_json(r);
  if (!validate_runs.empty())
    report["validation_runs"] = validation_runs_json(validate_runs, opt.machine, r.final_machine);
  io::write_file_atomic(results.path("report.json"), report.dump(2) + "\n");
  if (!opt.no_plots) {
    try {
      make_plots(results, run, r);
    } catch (const Error& e) {
      r.notes.push_back(fmt::format("plots not drawn: {}", e.what()));
    }
  }
  io::write_file_atomic(results.path("report.md"), analysis::calibration_report_markdown(r, opt.runs.front()));
  results.commit();
  for (const auto& n : r.notes) std::fprintf(stderr, "twin calibrate: note: %s\n", n.c_str());
  std::string added;
  for (const auto& a : r.added)
    added += fmt::format("{}{} on {}", added.empty() ? "" : ", ", a.candidate.effect, axis_name(a.candidate.axis));
  std::printf("calibrated %s (%zu samples, %d replays): effects added: %s; wrote %s\n", opt.runs.front().c_str(),
              r.replay_before.t_s.size(), r.replays, added.empty() ? "none" : added.c_str(), out.c_str());
}

void run_calibrate(const CalibrateCommand& opt) {
  for (const auto& r : opt.runs) refuse_output_over_input("calibrate", opt.out, r, opt.machine);
  for (const auto& r : opt.validate) refuse_output_over_input("calibrate", opt.out, r, opt.machine);
  if (opt.runs.size() == 1 && analysis::force::is_force_data(opt.runs.front())) {
    // A force run or series: meta.json has a `cut`.
    analysis::force::run_force_calibration(opt.runs.front(), opt.out, opt.no_plots);
    return;
  }
  std::vector<analysis::MeasuredRun> fit_runs, validate_runs;
  for (const auto& r : opt.runs) fit_runs.push_back(analysis::load_run(r));
  for (const auto& r : opt.validate) validate_runs.push_back(analysis::load_run(r));
  const bool known = !opt.machine.empty() ||
                     std::all_of(fit_runs.begin(), fit_runs.end(),
                                 [](const auto& r) { return analysis::names_shipped_machine(r); });
  if (known)
    calibrate_known_machine(opt, fit_runs, std::move(validate_runs));
  else
    calibrate_unknown_machine(opt, fit_runs, validate_runs);
}

}  // namespace

void register_calibrate(CLI::App& app) {
  auto opt = std::make_shared<CalibrateCommand>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Identify J, B, Tc per axis from a measured run, trace the residual to missing effects, add those that "
      "improve the held-out error; writes OUT/report.json, report.md, machine.yaml, trace.csv, trace_before.csv, plots");
  cmd->add_option("runs", opt->runs, "measured run folder(s) (trace.csv + meta.json) to fit on")->required();
  cmd->add_option("--validate", opt->validate,
                  "runs of another program on the same machine, not used for fitting: their errors with the nominal "
                  "and the calibrated machine are reported")
      ->take_all();
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the run's meta.machine");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.J=0.008")->take_all();
  cmd->add_flag("--no-plots", opt->no_plots, "skip the gnuplot figures");
  cmd->callback([opt]() { run_calibrate(*opt); });
}

}  // namespace twin::cli
