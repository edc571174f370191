#include "twin/cli/common.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <limits>

#include <fmt/format.h>

#include "controller/interpolator.hpp"
#include "twin/report/run_report.hpp"
#include <iterator>
#include <system_error>

#include <fmt/format.h>

#include "twin/core/error.hpp"

namespace twin::cli {
namespace {
/// Bytes per field of a simulated trace.csv, measured on the shipped
/// scenarios (docs/verification.md): 5.7 to 8.5; 10 keeps the estimate on
/// the safe side.
constexpr double kTraceBytesPerField = 10.0;
}  // namespace

void apply_sets(sim::MachineDefinition& machine, const std::vector<std::string>& sets) {
  for (const auto& s : sets) sim::apply_set(machine, s);
  if (!sets.empty()) machine.source += " (with --set)";
  machine.validate();
}

void add_budget_options(CLI::App& cmd, RunBudget& budget) {
  cmd.add_option("--max-duration-s", budget.max_duration_s,
                 "refuse, before simulating, a run longer than this simulated time in s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--max-trace-mb", budget.max_trace_mb,
                 "refuse, before simulating, a run whose trace.csv would exceed this size in MB")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
}

RunSize plan_run_size(const io::Scenario& scenario) {
  const double Ts = scenario.machine.Ts_s;
  const sim::PlannedProgram planned = sim::plan_program(scenario, scenario.machine);
  const controller::Trajectory& traj = planned.trajectory();
  RunSize size;
  const double settle_ticks = std::ceil(scenario.settle_s / Ts);
  const double rows = static_cast<double>(traj.num_ticks()) + settle_ticks;
  size.duration_s = rows * Ts;
  const double columns = static_cast<double>(
      analysis::run_trace_columns(scenario.machine.present_axes(), io::vibrating_tool(scenario)).size());
  size.trace_mb = rows * columns * kTraceBytesPerField / 1e6;
  size.rows = rows < 9e18 ? static_cast<std::int64_t>(rows) : std::numeric_limits<std::int64_t>::max();
  return size;
}

void check_run_budget(const io::Scenario& scenario, const RunSize& size, const RunBudget& budget) {
  if (size.duration_s <= budget.max_duration_s && size.trace_mb <= budget.max_trace_mb) return;
  throw ConfigError(fmt::format(
      "{}: the run would simulate {:.6g} s ({} ticks of {} s) and write a trace of about {:.6g} MB; the limits are "
      "{:g} s (--max-duration-s) and {:g} MB (--max-trace-mb): raise them to run it",
      scenario.path.string(), size.duration_s, size.rows, scenario.machine.Ts_s, size.trace_mb,
      budget.max_duration_s, budget.max_trace_mb));
}

SolverError explain_solver_failure(const SolverError& e, const sim::MachineDefinition& machine,
                                   const std::vector<std::string>& sets) {
  // The drive's own fastest rate is B/J (viscous damping over inertia); a
  // rate many times 1/Ts makes the explicit integrator fail.
  double worst = -1.0;
  std::string axis_text;
  for (Axis a : machine.present_axes()) {
    const auto& d = machine.axes[index(a)].drive;
    const double per_tick = d.B_kg_m2_per_s / d.J_kg_m2 * machine.Ts_s;
    if (!(per_tick > worst)) continue;
    worst = per_tick;
    axis_text = fmt::format("axis {}: J = {:g} kg m^2, B = {:g} kg m^2/s give B/J = {:.3g} 1/s, {:.3g} per tick of "
                            "Ts = {:g} s",
                            axis_name(a), d.J_kg_m2, d.B_kg_m2_per_s, d.B_kg_m2_per_s / d.J_kg_m2, per_tick,
                            machine.Ts_s);
  }
  std::string set_text;
  for (const auto& s : sets) set_text += (set_text.empty() ? "" : ", ") + s;
  return SolverError(fmt::format("{} ({}{}; check that axis's J and B)", e.what(),
                                 axis_text.empty() ? std::string("no axis") : axis_text,
                                 set_text.empty() ? std::string() : "; --set " + set_text));
}

TerminalProgress::TerminalProgress(std::string label)
    : label_(std::move(label)), enabled_(::isatty(STDERR_FILENO) == 1), start_(std::chrono::steady_clock::now()) {}

TerminalProgress::~TerminalProgress() {
  if (shown_) std::fprintf(stderr, "\r\033[K");
}

void TerminalProgress::update(std::int64_t done, std::int64_t total) {
  if (!enabled_ || total < kMinTicks) return;
  const std::int64_t percent = done * 100 / total;
  if (percent == last_percent_) return;
  last_percent_ = percent;
  const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double frac = static_cast<double>(done) / static_cast<double>(total);
  std::string eta;
  if (frac > 0.0) eta = fmt::format(", about {:.0f} s left", elapsed_s * (1.0 - frac) / frac);
  std::fprintf(stderr, "\r\033[K%s: %lld%% (%lld of %lld ticks)%s", label_.c_str(), static_cast<long long>(percent),
               static_cast<long long>(done), static_cast<long long>(total), eta.c_str());
  std::fflush(stderr);
  shown_ = true;
}

namespace {

// The absolute path with links, "." and ".." resolved as far as it exists.
std::filesystem::path resolved(const std::filesystem::path& p) {
  std::error_code ec;
  std::filesystem::path r = std::filesystem::weakly_canonical(std::filesystem::absolute(p, ec), ec);
  if (ec) r = std::filesystem::absolute(p, ec).lexically_normal();
  return r;
}

// Whether `inner` is `outer` or a path below it (both resolved).
bool is_within(const std::filesystem::path& inner, const std::filesystem::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty() && std::next(o) == outer.end()) break;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

void refuse_output_over_input(std::string_view command, const std::filesystem::path& out,
                              const std::filesystem::path& run_dir, const std::string& machine_option) {
  const auto out_r = resolved(out);
  const auto run_r = resolved(run_dir);
  if (is_within(out_r, run_r))
    throw ConfigError(fmt::format("{}: output folder {} {} the measured run {}: its files would be overwritten or "
                                  "hidden; choose an OUT outside the run folder",
                                  command, out.string(), out_r == run_r ? "is" : "is inside", run_dir.string()));
  std::vector<std::filesystem::path> inputs;
  for (const char* name : {"trace.csv", "trace.csv.gz", "meta.json"}) inputs.push_back(run_dir / name);
  std::error_code ec;
  if (!machine_option.empty() && std::filesystem::is_regular_file(machine_option, ec)) inputs.emplace_back(machine_option);
  for (const auto& in : inputs) {
    if (!std::filesystem::exists(in, ec)) continue;
    const auto in_r = resolved(in);
    if (in_r.parent_path() == out_r)
      throw ConfigError(fmt::format("{}: output folder {} holds the input {} ({}): it would be overwritten; choose "
                                    "another OUT",
                                    command, out.string(), in.string(), in_r.string()));
  }
}

void refuse_output_holding_inputs(std::string_view command, const std::filesystem::path& out,
                                  const std::vector<std::filesystem::path>& inputs) {
  const auto out_r = resolved(out);
  std::error_code ec;
  for (const auto& in : inputs) {
    if (in.empty() || !std::filesystem::exists(in, ec)) continue;
    const auto in_r = resolved(in);
    if (in_r.parent_path() == out_r)
      throw ConfigError(fmt::format("{}: output folder {} holds the input {} ({}): it would be overwritten or mixed "
                                    "with the results; choose another OUT",
                                    command, out.string(), in.string(), in_r.string()));
  }
}

}  // namespace twin::cli
