#pragma once
/// Options shared by several subcommands.
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>

#include "twin/core/error.hpp"
#include "twin/io/scenario_file.hpp"
#include "twin/sim/machine.hpp"

namespace twin::cli {

/// Applies every `--set` assignment and validates the machine.
void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets);

/// What a run may cost before it starts: simulated time and trace size.
struct RunBudget {
  double max_duration_s{600.0};
  double max_trace_mb{1000.0};
};
/// Adds --max-duration-s and --max-trace-mb (validated > 0) to a subcommand.
void add_budget_options(CLI::App& cmd, RunBudget& budget);

/// The size of a run as planned, before any simulation.
struct RunSize {
  double duration_s{0.0};      ///< planned motion plus settle time
  std::int64_t rows{0};        ///< trace rows (one per tick)
  double trace_mb{0.0};        ///< estimated trace.csv size, MB (10^6 bytes)
};
/// Plans the scenario's program (parse, travel, trajectory) and estimates the run.
RunSize plan_run_size(const io::Scenario& scenario);
/// ConfigError naming the scenario, both figures and both limits (and the
/// flags that raise them) when the run would exceed the budget.
void check_run_budget(const io::Scenario& scenario, const RunSize& size, const RunBudget& budget);

/// A solver failure with what is known about the machine: the axis whose
/// drive has the fastest dynamics relative to the tick, the parameters that
/// set it (J, B) and the --set assignments in force.
SolverError explain_solver_failure(const SolverError& e, const sim::MachineDefinition& machine,
                                   const std::vector<std::string>& sets);

/// A progress line on stderr for runs of at least kMinTicks ticks, redrawn
/// in place at every whole percent, when stderr is a terminal; silent
/// otherwise (pipes, files).
class TerminalProgress {
 public:
  static constexpr std::int64_t kMinTicks = 100000;
  explicit TerminalProgress(std::string label);
  ~TerminalProgress();
  TerminalProgress(const TerminalProgress&) = delete;
  TerminalProgress& operator=(const TerminalProgress&) = delete;
  void update(std::int64_t done, std::int64_t total);

 private:
  std::string label_;
  bool enabled_{false};
  bool shown_{false};
  std::int64_t last_percent_{-1};
  std::chrono::steady_clock::time_point start_;
};
/// Refuses (ConfigError, one line, before anything is written) an output folder
/// that would write over a command's input: OUT is the measured run folder RUN
/// or a folder inside it (OUT/trace.csv would replace RUN/trace.csv or hide
/// RUN/trace.csv.gz), or OUT holds a file the command reads (a file of RUN
/// reached through a link, or the --machine file). Paths are compared after
/// resolving links, `..` and `.`.
void refuse_output_over_input(std::string_view command, const std::filesystem::path& out,
                              const std::filesystem::path& run_dir, const std::string& machine_option);
/// Refuses (ConfigError, one line, before anything is written) an output
/// folder that holds one of `inputs` (paths compared after resolving links,
/// `..` and `.`; inputs that do not exist are skipped): the command's files
/// would replace it or be mixed with it.
void refuse_output_holding_inputs(std::string_view command, const std::filesystem::path& out,
                                  const std::vector<std::filesystem::path>& inputs);

}  // namespace twin::cli
