#include <algorithm>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/analysis/calibrate.hpp"
#include "twin/analysis/plots.hpp"
#include "twin/analysis/signal.hpp"
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
          c.effect == "cogging" || c.effect == "screw_pitch_error" || c.effect == "position_dependent_friction"};
  }
  return analysis::plot_calibration(results, "residuals.csv", axes, evidence);
}

}  // namespace

void register_calibrate(CLI::App& app) {
  struct Options {
    std::string run;
    std::string out;
    std::string machine;
    std::vector<std::string> sets;
    bool no_plots{false};
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Identify J, B, Tc per axis from a measured run, trace the residual to missing effects, add those that "
      "improve the held-out error; writes OUT/report.json, report.md, machine.yaml, trace.csv, trace_before.csv, plots");
  cmd->add_option("run", opt->run, "measured run folder (trace.csv + meta.json)")->required();
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the run's meta.machine");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.J=0.008")->take_all();
  cmd->add_flag("--no-plots", opt->no_plots, "skip the gnuplot figures");
  cmd->callback([opt]() {
    refuse_output_over_input("calibrate", opt->out, opt->run, opt->machine);
    const analysis::MeasuredRun run = analysis::load_run(opt->run);
    std::vector<std::string> notes;
    sim::MachineDefinition machine = analysis::machine_for_run(run, opt->machine, &notes);
    apply_sets(machine, opt->sets);
    analysis::CalibrationResult r = analysis::calibrate(run, machine);
    r.notes.insert(r.notes.begin(), notes.begin(), notes.end());
    const std::filesystem::path out(opt->out);
    io::ResultSet results(out, "calibrate");  // the files appear in OUT together, manifest.json last
    analysis::write_replay_trace(results.path("trace_before.csv"), r.replay_before);
    analysis::write_replay_trace(results.path("trace.csv"), r.replay_after);
    io::write_file_atomic(results.path("machine.yaml"),
                          io::machine_to_yaml(r.final_machine, fmt::format("calibrated by twin calibrate from {}: "
                                                                           "identified J, B, Tc and added effects",
                                                                           opt->run)));
    io::write_file_atomic(results.path("report.json"), analysis::calibration_report_json(r).dump(2) + "\n");
    if (!opt->no_plots) {
      try {
        make_plots(results, run, r);
      } catch (const Error& e) {
        r.notes.push_back(fmt::format("plots not drawn: {}", e.what()));
      }
    }
    io::write_file_atomic(results.path("report.md"), analysis::calibration_report_markdown(r, opt->run));
    results.commit();
    for (const auto& n : r.notes) std::fprintf(stderr, "twin calibrate: note: %s\n", n.c_str());
    std::string added;
    for (const auto& a : r.added)
      added += fmt::format("{}{} on {}", added.empty() ? "" : ", ", a.candidate.effect, axis_name(a.candidate.axis));
    std::printf("calibrated %s (%zu samples, %d replays): effects added: %s; wrote %s\n", opt->run.c_str(),
                r.replay_before.t_s.size(), r.replays, added.empty() ? "none" : added.c_str(), out.c_str());
  });
}

}  // namespace twin::cli
