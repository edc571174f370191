#pragma once
/// SWEEP.yaml of `twin sweep`: a grid and/or a list of independent cases,
/// each one `twin run` (a scenario, a machine, --set values) or one
/// `twin calibrate` of a measured run (a fleet). docs/sweep.md gives the format.
#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace twin::sweep {

/// One independent case: the arguments of one twin command.
struct SweepCase {
  std::size_t index{0};
  std::string name;                  ///< unique, [A-Za-z0-9_.-]: OUT/cases/<name>, OUT/logs/<name>.log
  std::string command{"run"};        ///< "run" or "calibrate"
  std::string scenario;              ///< run: path or shipped name; empty: the built-in default
  std::string run_dir;               ///< calibrate: the measured run folder
  std::string machine;               ///< --machine (empty: the scenario's or the run's)
  std::vector<std::string> sets;     ///< --set assignments <axis>.<name>=<value>
  /// What distinguishes the case, as written in SWEEP.yaml: columns of the results table.
  std::vector<std::pair<std::string, std::string>> params;
};

struct SweepSpec {
  std::filesystem::path source;
  std::string command{"run"};
  std::string trace_format{"csv.gz"};  ///< run: trace of each case
  std::int64_t log_every{1};           ///< run: --log-every of each case
  std::vector<SweepCase> cases;
};

/// Reads SWEEP.yaml; ConfigError "file:line: key: ..." (one line) for
/// anything it cannot use: unknown keys, a grid that is not lists, a case
/// name given twice, no case at all, more than kMaxCases cases.
SweepSpec load_sweep(const std::filesystem::path& path);
inline constexpr std::size_t kMaxCases = 100000;

/// The command line (after the twin executable) that runs `c` with its
/// results in `case_dir`.
std::vector<std::string> case_arguments(const SweepSpec& spec, const SweepCase& c,
                                        const std::filesystem::path& case_dir);

}  // namespace twin::sweep
