#include <cstdint>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/report/run_report.hpp"
#include "twin/cli/commands.hpp"
#include "twin/cli/common.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/io/trace_csv.hpp"

namespace twin::cli {

void register_run(CLI::App& app) {
  struct Options {
    std::string scenario;
    std::string out;
    std::string machine;
    std::vector<std::string> sets;
    bool no_plots{false};
    std::int64_t log_every{1};
    std::string trace_format{"csv"};
    RunBudget budget;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "run", "Run a scenario (default: the FADAL 2216 pocket corner) and write OUT/trace.csv, OUT/summary.json and plots");
  cmd->add_option("scenario", opt->scenario, "scenario.yaml, its folder, or a shipped scenario name");
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("--machine", opt->machine, "machine definition (name or YAML file) replacing the scenario's");
  cmd->add_option("--set", opt->sets, "override a parameter: <axis>.<name>=<value>, e.g. x.Kp=600")->take_all();
  cmd->add_flag("--no-plots", opt->no_plots, "do not draw the PNG plots");
  cmd->add_option("--log-every", opt->log_every,
                  "write every N-th tick to the trace (the summary still takes in every tick)")
      ->check(CLI::Range(std::int64_t{1}, std::numeric_limits<std::int64_t>::max()));
  cmd->add_option("--trace-format", opt->trace_format, "trace file: csv (trace.csv) or csv.gz (trace.csv.gz)")
      ->check(CLI::IsMember({"csv", "csv.gz"}));
  add_budget_options(*cmd, opt->budget);
  cmd->callback([opt]() {
    const auto path = opt->scenario.empty() ? io::default_scenario_path() : io::resolve_scenario_path(opt->scenario);
    io::Scenario scenario = io::load_scenario(path, opt->machine);
    apply_sets(scenario.machine, opt->sets);
    const io::TraceFormat format = io::parse_trace_format(opt->trace_format);
    RunSize size = plan_run_size(scenario);
    // The estimate is of a full-rate plain trace: decimation divides it, and
    // gzip keeps about kGzipShare of it (docs/performance.md).
    constexpr double kGzipShare = 0.30;
    size.rows = (size.rows + opt->log_every - 1) / opt->log_every;
    size.trace_mb /= static_cast<double>(opt->log_every);
    if (format == io::TraceFormat::kCsvGz) size.trace_mb *= kGzipShare;
    check_run_budget(scenario, size, opt->budget);
    analysis::RunOptions ro;
    ro.out_dir = opt->out;
    ro.plots = !opt->no_plots;
    ro.log_every = opt->log_every;
    ro.trace_format = format;
    analysis::RunOutputs out;
    {
      TerminalProgress progress("twin run " + scenario.name);  // erased at the end of this block
      ro.progress = [&progress](std::int64_t done, std::int64_t total) { progress.update(done, total); };
      try {
        out = analysis::run_scenario(scenario, ro);
      } catch (const SolverError& e) {
        throw explain_solver_failure(e, scenario.machine, opt->sets);
      }
    }
    const auto& s = out.summary;
    std::printf("%s\n", fmt::format("{}: cycle time {:.4f} s (at programmed feed {:.4f} s, lost at corners {:.4f} s), "
                                    "max contour error {:.2f} um",
                                    scenario.name, s["cycle_time_s"].get<double>(),
                                    s["time_at_programmed_feed_s"].get<double>(),
                                    s["time_lost_at_corners_s"].get<double>(),
                                    s["max_contour_error_mm"].get<double>() * 1000.0)
                            .c_str());
    std::printf("wrote %s, %s", out.trace_path.c_str(), out.summary_path.c_str());
    for (const auto& p : out.plots) std::printf(", %s", p.c_str());
    std::printf("\n");
  });
}

}  // namespace twin::cli
