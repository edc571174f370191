#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "twin/report/plots.hpp"
#include "twin/cli/commands.hpp"
#include "twin/core/error.hpp"
#include "twin/io/atomic_file.hpp"
#include "twin/sweep/runner.hpp"
#include "twin/sweep/sweep_spec.hpp"

namespace twin::cli {

namespace {

std::filesystem::path own_executable() {
  std::error_code ec;
  const auto p = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (ec) throw IoError(fmt::format("cannot find the twin executable (/proc/self/exe): {}", ec.message()));
  return p;
}

// A progress line on stderr, redrawn in place, when stderr is a terminal.
class SweepProgress {
 public:
  SweepProgress() : enabled_(::isatty(2) == 1), start_(std::chrono::steady_clock::now()) {}
  ~SweepProgress() {
    if (shown_) std::fprintf(stderr, "\r\033[K");
  }
  SweepProgress(const SweepProgress&) = delete;
  SweepProgress& operator=(const SweepProgress&) = delete;
  void update(std::size_t done, std::size_t failed, std::size_t total) {
    if (!enabled_) return;
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    const double eta = done > 0 ? s / static_cast<double>(done) * static_cast<double>(total - done) : 0.0;
    std::fprintf(stderr, "\r\033[Ktwin sweep: %zu/%zu cases done, %zu failed, %.0f s, about %.0f s to go", done, total,
                 failed, s, eta);
    std::fflush(stderr);
    shown_ = true;
  }

 private:
  bool enabled_;
  bool shown_{false};
  std::chrono::steady_clock::time_point start_;
};

// The figures worth a look per case: the first of these the rows have.
std::vector<std::string> plotted_columns(const std::vector<sweep::Row>& rows, const std::string& command) {
  std::vector<std::string> wanted;
  if (command == "calibrate") {
    for (const auto& r : rows)
      for (auto it = r.begin(); it != r.end(); ++it)
        if (it.key().rfind("error_after.", 0) == 0 && it.value().is_number() &&
            std::find(wanted.begin(), wanted.end(), it.key()) == wanted.end())
          wanted.push_back(it.key());
  } else {
    wanted = {"cycle_time_s", "max_contour_error_mm"};
  }
  std::vector<std::string> out;
  for (const auto& w : wanted) {
    for (const auto& r : rows)
      if (r.contains(w) && r[w].is_number()) {
        out.push_back(w);
        break;
      }
    if (out.size() == 2) break;
  }
  return out;
}

void plot_summary(io::ResultSet& results, const std::vector<sweep::Row>& rows, const std::string& command) {
  analysis::plot_sweep(results, {.columns = plotted_columns(rows, command)});
}

}  // namespace

void register_sweep(CLI::App& app) {
  struct Options {
    std::string sweep;
    std::string out;
    int jobs{0};
    bool no_plots{false};
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "sweep", "Run the independent cases of SWEEP.yaml (a grid or list of scenarios, machines and --set values, or "
               "measured runs to calibrate) on all local cores, or across machines under mpirun; writes "
               "OUT/results.csv, OUT/results.json, OUT/summary.png, and each case in OUT/cases/<name>");
  cmd->add_option("sweep", opt->sweep, "SWEEP.yaml (docs/sweep.md)")->required();
  cmd->add_option("-o,--out", opt->out, "output folder (created if missing)")->required();
  cmd->add_option("-j,--jobs", opt->jobs,
                  "cases at once on this machine (default: every core; under mpirun: 1 per rank)")
      ->check(CLI::Range(1, 4096));
  cmd->add_flag("--no-plots", opt->no_plots, "do not draw summary.png");
  cmd->callback([opt]() {
    const sweep::SweepSpec spec = sweep::load_sweep(opt->sweep);
    sweep::RunnerOptions ro;
    ro.out_dir = opt->out;
    ro.twin_exe = own_executable();
    const bool mpi = sweep::mpi_built() && sweep::launched_by_mpi();
    ro.jobs = opt->jobs > 0 ? opt->jobs : mpi ? 1 : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    bool root = true;
    int ranks = 1;
    std::vector<sweep::Row> rows;
    {
      SweepProgress progress;
      io::ensure_directory(ro.out_dir);
      ro.progress = [&progress](std::size_t d, std::size_t f, std::size_t t) { progress.update(d, f, t); };
      rows = mpi ? sweep::run_mpi(spec, ro, &root, &ranks) : sweep::run_local(spec, ro);
    }
    if (!root) return;
    std::size_t failed = 0;
    for (const auto& r : rows) failed += r["status"] == "failed";
    io::ResultSet results(ro.out_dir, "sweep");
    io::write_file_atomic(results.path("results.csv"), sweep::results_csv(rows));
    nlohmann::ordered_json j;
    j["sweep"] = spec.source.string();
    j["command"] = spec.command;
    j["cases"] = rows.size();
    j["failed"] = failed;
    j["rows"] = rows;
    io::write_file_atomic(results.path("results.json"), j.dump(2) + "\n");
    if (!opt->no_plots) {
      try {
        plot_summary(results, rows, spec.command);
      } catch (const Error&) {
        results.commit();  // the tables stand without the plot
        throw;
      }
    }
    results.commit();
    std::printf("%s\n", fmt::format("{} cases ({} failed) on {} rank(s) x {} job(s): wrote {}, {}{}", rows.size(),
                                    failed, ranks, ro.jobs, results.final_path("results.csv").string(),
                                    results.final_path("results.json").string(),
                                    opt->no_plots ? "" : ", " + results.final_path("summary.png").string())
                            .c_str());
    if (failed > 0)
      throw ModelError(fmt::format("{} of {} cases failed (status and error per case in {})", failed, rows.size(),
                                   results.final_path("results.csv").string()));
  });
}

}  // namespace twin::cli
