#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/analysis/calibrate.hpp"
#include "twin/analysis/force_calibrate.hpp"
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

// run_gnuplot renames <name>.tmp.png to <name> once gnuplot succeeded.
std::string tmp_png(const std::filesystem::path& p) {
  auto t = p;
  t += ".tmp.png";
  return analysis::gnuplot_quote(t);
}

std::vector<std::filesystem::path> make_plots(const std::filesystem::path& out, const analysis::MeasuredRun& run,
                                              const analysis::CalibrationResult& r) {
  const std::vector<Axis> axes = measured_axes(run);
  if (axes.empty()) throw ConfigError("no axis logs its measured position <a>_mm: no residual to plot");
  const auto data = out / "residuals.csv";
  write_residuals(data, run, r, axes);
  const std::string d = analysis::gnuplot_quote(data);
  std::string script = "set datafile separator ','\nset key autotitle columnhead\nset grid\n";
  std::vector<std::filesystem::path> outputs;
  const std::size_t na = axes.size();
  for (const char* which : {"before", "after"}) {
    const auto png = out / fmt::format("residual_{}.png", which);
    outputs.push_back(png);
    script += fmt::format("set terminal pngcairo size 1200,{} noenhanced\nset output {}\nset multiplot layout {},2\n",
                          300 * na, tmp_png(png), na);
    for (std::size_t j = 0; j < na; ++j) {
      const std::size_t c0 = 2 + 5 * j;  // gnuplot columns are 1-based: t_s is 1
      const std::string an(axis_name(axes[j]));
      const std::size_t ce = c0 + (std::string(which) == "before" ? 1 : 2);
      const std::size_t cu = c0 + (std::string(which) == "before" ? 3 : 4);
      script += fmt::format("set title '{} tracking error, measured minus model ({})'\nset xlabel 't s'\n"
                            "set ylabel 'mm'\nplot {} using 1:{} with lines notitle\n",
                            an, which, d, ce);
      script += fmt::format("set title '{} low-passed u, measured minus model ({})'\nset ylabel 'V (or A)'\n"
                            "plot {} using 1:{} with lines notitle\n",
                            an, which, d, cu);
    }
    script += "unset multiplot\n";
  }
  if (!r.added.empty() && std::find(axes.begin(), axes.end(), r.added.front().candidate.axis) != axes.end()) {
    const auto& c = r.added.front().candidate;
    std::size_t j = 0;
    for (; j < na; ++j)
      if (axes[j] == c.axis) break;
    const std::size_t c0 = 2 + 5 * j;
    const auto png = out / "evidence.png";
    outputs.push_back(png);
    const bool in_x = c.effect == "cogging" || c.effect == "screw_pitch_error" ||
                      c.effect == "position_dependent_friction";
    script += fmt::format("set terminal pngcairo size 1200,500 noenhanced\nset output {}\nset multiplot layout 1,2\n",
                          tmp_png(png));
    script += fmt::format("set title '{} on {}: low-passed u residual of the model without it'\n"
                          "set xlabel '{}'\nset ylabel 'V (or A)'\nplot {} using {}:{} with dots notitle\n",
                          c.effect, axis_name(c.axis), in_x ? "x mm" : "t s", d, in_x ? c0 : 1, c0 + 3);
    script += fmt::format("set title 'tracking-error residual, without (red) and with (blue) it'\nset xlabel '{}'\n"
                          "set ylabel 'mm'\nplot {} using {}:{} with dots lc rgb 'red' notitle, '' using {}:{} with "
                          "dots lc rgb 'blue' notitle\nunset multiplot\n",
                          in_x ? "x mm" : "t s", d, in_x ? c0 : 1, c0 + 1, in_x ? c0 : 1, c0 + 2);
  }
  analysis::run_gnuplot(out, script, outputs);
  return outputs;
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
    if (analysis::force::is_force_data(opt->run)) {  // a force run or series: meta.json has a `cut`
      analysis::force::run_force_calibration(opt->run, opt->out, opt->no_plots);
      return;
    }
    const analysis::MeasuredRun run = analysis::load_run(opt->run);
    std::vector<std::string> notes;
    sim::MachineDefinition machine = analysis::machine_for_run(run, opt->machine, &notes);
    apply_sets(machine, opt->sets);
    analysis::CalibrationResult r = analysis::calibrate(run, machine);
    r.notes.insert(r.notes.begin(), notes.begin(), notes.end());
    const std::filesystem::path out(opt->out);
    io::ensure_directory(out);
    analysis::write_replay_trace(out / "trace_before.csv", r.replay_before);
    analysis::write_replay_trace(out / "trace.csv", r.replay_after);
    io::write_file_atomic(out / "machine.yaml",
                          io::machine_to_yaml(r.final_machine, fmt::format("calibrated by twin calibrate from {}: "
                                                                           "identified J, B, Tc and added effects",
                                                                           opt->run)));
    io::write_file_atomic(out / "report.json", analysis::calibration_report_json(r).dump(2) + "\n");
    if (!opt->no_plots) {
      try {
        make_plots(out, run, r);
      } catch (const Error& e) {
        r.notes.push_back(fmt::format("plots not drawn: {}", e.what()));
      }
    }
    io::write_file_atomic(out / "report.md", analysis::calibration_report_markdown(r, opt->run));
    for (const auto& n : r.notes) std::fprintf(stderr, "twin calibrate: note: %s\n", n.c_str());
    std::string added;
    for (const auto& a : r.added)
      added += fmt::format("{}{} on {}", added.empty() ? "" : ", ", a.candidate.effect, axis_name(a.candidate.axis));
    std::printf("calibrated %s (%zu samples, %d replays): effects added: %s; wrote %s\n", opt->run.c_str(),
                r.replay_before.t_s.size(), r.replays, added.empty() ? "none" : added.c_str(), out.c_str());
  });
}

}  // namespace twin::cli
