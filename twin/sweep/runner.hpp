#pragma once
/// Runs the cases of a sweep, each as its own process of the twin executable
/// (`twin run ...` or `twin calibrate ...`): cases share nothing, so a case
/// that fails or crashes ends only itself, and its result row says so.
///
/// Locally, up to `jobs` cases run at once. Under MPI (built with MPI and
/// started by mpirun), rank 0 hands out one case at a time to each rank that
/// asks (dynamic load balancing), runs cases itself too, and gathers the rows;
/// the table is the same as the local one, row for row and byte for byte.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "twin/sweep/sweep_spec.hpp"

namespace twin::sweep {

/// One row of the results table: case, name, status ("ok" or "failed"),
/// error (the case's one-line reason, empty when ok), the case's parameters,
/// then its figures (summary.json of a run, report.json of a calibration,
/// flattened to dotted names).
using Row = nlohmann::ordered_json;

struct RunnerOptions {
  std::filesystem::path out_dir;
  std::filesystem::path twin_exe;  ///< the twin executable each case runs
  int jobs{1};                     ///< cases at once in this process (per rank under MPI)
  /// Called on rank 0 after each case with (done, failed, total); may be empty.
  std::function<void(std::size_t, std::size_t, std::size_t)> progress;
};

/// The row of case `c` once its process ended with wait status `status`.
Row case_row(const SweepSpec& spec, const SweepCase& c, const std::filesystem::path& out_dir, int status);

/// Runs every case on local processes; rows in case order.
std::vector<Row> run_local(const SweepSpec& spec, const RunnerOptions& options);

/// True when this build can run a sweep across MPI ranks.
bool mpi_built() noexcept;
/// True when the process was started by an MPI launcher (mpirun, srun).
bool launched_by_mpi() noexcept;

/// Runs the sweep across MPI ranks (MPI_Init and MPI_Finalize inside). On
/// rank 0 returns the rows in case order and sets *is_root; other ranks
/// return no rows. InternalError when built without MPI.
std::vector<Row> run_mpi(const SweepSpec& spec, const RunnerOptions& options, bool* is_root, int* ranks);
/// Ends every rank after an error on one (MPI_Abort), when under MPI.
void abort_mpi(int code) noexcept;

/// OUT/results.csv: one header, one line per row, columns in order of first
/// appearance over the rows; numbers in the shortest text that reads back to
/// the same double.
std::string results_csv(const std::vector<Row>& rows);

}  // namespace twin::sweep
